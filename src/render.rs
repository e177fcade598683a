//! Drawing a simulation with wgpu: the cloth shaded from its normals with both sides lit
//! (or coloured by strain), ropes as particles and springs, the rapier bodies as meshes from
//! parry's shape tessellation, and a floor grid. [`Renderer`] draws into any texture view (a
//! window's surface in `examples/viewer.rs`); [`Offscreen`] draws into its own texture and
//! reads the pixels back, which is what `harmonic render` writes to PNG. Both work on a
//! software adapter (Mesa's lavapipe).

use std::path::Path;
use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};
use rapier3d::prelude::{ColliderHandle, ColliderSet, RigidBodySet};

use crate::error::GpuError;
use crate::gpu::GpuContext;
use crate::Simulation;

/// The WGSL source of the renderer's pipelines (`shaders/render.wgsl`).
pub const SHADER: &str = include_str!("../shaders/render.wgsl");

/// The offscreen colour format (no sRGB conversion: the shader's colours are written as is).
pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
const SAMPLES: u32 = 4;
/// The background, also the far colour of the floor grid's fade.
pub const SKY: [f64; 3] = [0.86, 0.89, 0.93];
/// Cloth and rope colour when not coloured by strain.
pub const CLOTH: [f32; 3] = [0.88, 0.42, 0.16];

/// What to draw besides the shaded cloth.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Style {
    /// Draw the cloth's triangle edges.
    pub wireframe: bool,
    /// Colour the cloth by strain (each particle's largest stretch `(l − l0)/l0` over its
    /// springs) instead of its plain colour: blue (unstretched) through green and yellow to
    /// red at `strain_scale` or more.
    pub strain: bool,
    /// The strain drawn fully red (0 means 10 %).
    pub strain_scale: f32,
}

/// An orbit camera: it looks at `target` from `distance` away, turned `yaw` about the vertical
/// and raised `pitch` (radians).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// The point looked at (m).
    pub target: Vec3,
    /// Turn about the vertical axis (radians); 0 looks from +z.
    pub yaw: f32,
    /// Elevation above the horizontal (radians).
    pub pitch: f32,
    /// From the eye to `target` (m).
    pub distance: f32,
    /// Vertical field of view (radians).
    pub fov_y: f32,
}

impl Camera {
    /// A three-quarter view from above that fits the box `lo..hi`.
    pub fn framing(lo: Vec3, hi: Vec3) -> Self {
        let fov_y = 40f32.to_radians();
        let radius = (0.5 * (hi - lo).length()).max(0.05);
        Self {
            target: 0.5 * (lo + hi),
            yaw: 0.65,
            pitch: 0.38,
            distance: 0.95 * radius / (0.5 * fov_y).tan(),
            fov_y,
        }
    }

    /// [`Self::framing`] of `sim`'s [`bounds`] grown by `margin` of their size on each side.
    pub fn of(sim: &Simulation, margin: f32) -> Self {
        let (lo, hi) = bounds(sim);
        let pad = margin * (hi - lo);
        Self::framing(lo - pad, hi + pad)
    }

    /// The eye's position: `distance` from `target`, at `yaw` and `pitch`.
    pub fn eye(&self) -> Vec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        self.target + self.distance * Vec3::new(cp * sy, sp, cp * cy)
    }

    /// Projection times view for a viewport of `aspect` = width / height (depth 0..1).
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        let near = (0.01 * self.distance).max(1e-3);
        use glam::camera::rh::{proj::directx, view::look_at_mat4};
        let proj = directx::perspective(self.fov_y, aspect, near, 100.0 * self.distance);
        proj * look_at_mat4(self.eye(), self.target, Vec3::Y)
    }

    /// The ray through a viewport point (`ndc` in −1..1, y up): origin and unit direction.
    pub fn ray(&self, ndc: glam::Vec2, aspect: f32) -> (Vec3, Vec3) {
        let inv = self.view_proj(aspect).inverse();
        let near = inv.project_point3(Vec3::new(ndc.x, ndc.y, 0.0));
        let far = inv.project_point3(Vec3::new(ndc.x, ndc.y, 1.0));
        (near, (far - near).normalize_or(Vec3::NEG_Z))
    }
}

/// The box a picture of `sim` should hold: its particles and its bodies, leaving out fixed
/// colliders much larger than the rest (a ground slab would make everything else small).
pub fn bounds(sim: &Simulation) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for x in sim.positions() {
        lo = lo.min(x.as_vec3());
        hi = hi.max(x.as_vec3());
    }
    if let Some(p) = sim.props() {
        let size = if lo.x.is_finite() {
            (hi - lo).length()
        } else {
            0.0
        };
        for (_, co) in p.colliders().iter() {
            let aabb = co.compute_aabb();
            let big = (aabb.maxs - aabb.mins).length() > 3.0 * size.max(0.1);
            let fixed = co
                .parent()
                .and_then(|h| p.bodies().get(h))
                .is_none_or(|b| b.is_fixed());
            if big && fixed {
                continue;
            }
            lo = lo.min(aabb.mins);
            hi = hi.max(aabb.maxs);
        }
    }
    if !lo.x.is_finite() || !hi.x.is_finite() {
        return (Vec3::splat(-1.0), Vec3::splat(1.0));
    }
    (lo, hi)
}

/// The colour of a strain `s` on a scale where `scale` is fully red.
pub fn strain_colour(s: f32, scale: f32) -> [f32; 3] {
    let stops = [
        [0.20, 0.35, 0.90],
        [0.15, 0.75, 0.35],
        [0.95, 0.85, 0.15],
        [0.90, 0.15, 0.10],
    ];
    let t = (s / scale.max(1e-9)).clamp(0.0, 1.0) * 3.0;
    let k = (t as usize).min(2);
    let f = t - k as f32;
    let (a, b) = (stops[k], stops[k + 1]);
    [0, 1, 2].map(|c| a[c] + f * (b[c] - a[c]))
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Vertex {
    position: [f32; 3],
    normal: [f32; 3],
    colour: [f32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct ViewUniform {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    floor: [f32; 4],
    grid: [f32; 4],
}

/// A body's surface in its own frame, from parry's tessellation.
struct BodyMesh {
    collider: ColliderHandle,
    vertices: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
}

fn body_mesh(shape: &dyn rapier3d::parry::shape::Shape) -> Option<(Vec<Vec3>, Vec<[u32; 3]>)> {
    if let Some(s) = shape.as_ball() {
        return Some(s.to_trimesh(20, 40));
    }
    if let Some(s) = shape.as_cuboid() {
        return Some(s.to_trimesh());
    }
    if let Some(s) = shape.as_capsule() {
        return Some(s.to_trimesh(20, 12));
    }
    if let Some(s) = shape.as_cylinder() {
        return Some(s.to_trimesh(40));
    }
    if let Some(s) = shape.as_cone() {
        return Some(s.to_trimesh(40));
    }
    if let Some(s) = shape.as_convex_polyhedron() {
        return Some(s.to_trimesh());
    }
    if let Some(s) = shape.as_trimesh() {
        return Some((s.vertices().to_vec(), s.indices().to_vec()));
    }
    if let Some(s) = shape.as_heightfield() {
        return Some(s.to_trimesh());
    }
    None
}

/// A vertex or index buffer that grows as needed.
struct Growing {
    buffer: Option<wgpu::Buffer>,
    usage: wgpu::BufferUsages,
    label: &'static str,
}

impl Growing {
    fn new(usage: wgpu::BufferUsages, label: &'static str) -> Self {
        Self {
            buffer: None,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            label,
        }
    }

    fn write(&mut self, ctx: &GpuContext, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        let size = bytes.len() as u64;
        if self.buffer.as_ref().is_none_or(|b| b.size() < size) {
            self.buffer = Some(ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(self.label),
                size: size.next_power_of_two().max(256),
                usage: self.usage,
                mapped_at_creation: false,
            }));
        }
        if let Some(b) = &self.buffer {
            ctx.queue.write_buffer(b, 0, bytes);
        }
    }
}

struct Attachments {
    size: (u32, u32),
    colour: wgpu::TextureView,
    depth: wgpu::TextureView,
}

/// Draws simulations into texture views of one format.
pub struct Renderer {
    ctx: Arc<GpuContext>,
    format: wgpu::TextureFormat,
    mesh: wgpu::RenderPipeline,
    lines: wgpu::RenderPipeline,
    floor: wgpu::RenderPipeline,
    view: wgpu::Buffer,
    bind: wgpu::BindGroup,
    attachments: Option<Attachments>,
    bodies: Vec<BodyMesh>,
    // CPU-side geometry of the frame, kept to draw without allocating once warm.
    tri_vertices: Vec<Vertex>,
    tri_indices: Vec<u32>,
    line_vertices: Vec<Vertex>,
    strain: Vec<f32>,
    tri_vb: Growing,
    tri_ib: Growing,
    line_vb: Growing,
}

/// One flat-shaded triangle (its face normal at each corner), on vertices of its own.
fn push_flat(indices: &mut Vec<u32>, vertices: &mut Vec<Vertex>, tri: [Vec3; 3], colour: [f32; 3]) {
    let [a, b, c] = tri;
    let normal = (b - a).cross(c - a).normalize_or_zero().to_array();
    for q in tri {
        indices.push(vertices.len() as u32);
        vertices.push(Vertex {
            position: q.to_array(),
            normal,
            colour,
        });
    }
}

impl Renderer {
    /// A renderer on `ctx`'s device drawing into views of `format`.
    pub fn new(ctx: Arc<GpuContext>, format: wgpu::TextureFormat) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let (mesh, lines, floor, view, bind) = ctx.scoped("render pipelines", || {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("render.wgsl"),
                source: wgpu::ShaderSource::Wgsl(SHADER.into()),
            });
            let view = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("view"),
                size: std::mem::size_of::<ViewUniform>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("view"),
                entries: &[wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }],
            });
            let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("view"),
                layout: &layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: view.as_entire_binding(),
                }],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("render"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let attributes =
                wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x3];
            let buffers = [Some(wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<Vertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &attributes,
            })];
            let pipeline = |label: &str,
                            vs: &str,
                            fs: &str,
                            buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
                            topology: wgpu::PrimitiveTopology,
                            bias: i32| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some(label),
                    layout: Some(&pipeline_layout),
                    vertex: wgpu::VertexState {
                        module: &module,
                        entry_point: Some(vs),
                        compilation_options: Default::default(),
                        buffers,
                    },
                    primitive: wgpu::PrimitiveState {
                        topology,
                        cull_mode: None,
                        ..Default::default()
                    },
                    depth_stencil: Some(wgpu::DepthStencilState {
                        format: DEPTH,
                        depth_write_enabled: Some(true),
                        depth_compare: Some(wgpu::CompareFunction::LessEqual),
                        stencil: Default::default(),
                        // Surfaces sit a little behind their own wireframe.
                        bias: wgpu::DepthBiasState {
                            constant: bias,
                            slope_scale: if bias > 0 { 1.0 } else { 0.0 },
                            clamp: 0.0,
                        },
                    }),
                    multisample: wgpu::MultisampleState {
                        count: SAMPLES,
                        ..Default::default()
                    },
                    fragment: Some(wgpu::FragmentState {
                        module: &module,
                        entry_point: Some(fs),
                        compilation_options: Default::default(),
                        targets: &[Some(wgpu::ColorTargetState {
                            format,
                            blend: None,
                            write_mask: wgpu::ColorWrites::ALL,
                        })],
                    }),
                    multiview_mask: None,
                    cache: None,
                })
            };
            let mesh = pipeline(
                "mesh",
                "vs_mesh",
                "fs_mesh",
                &buffers,
                wgpu::PrimitiveTopology::TriangleList,
                2,
            );
            let lines = pipeline(
                "lines",
                "vs_mesh",
                "fs_line",
                &buffers,
                wgpu::PrimitiveTopology::LineList,
                0,
            );
            let floor = pipeline(
                "floor",
                "vs_floor",
                "fs_floor",
                &[],
                wgpu::PrimitiveTopology::TriangleList,
                0,
            );
            (mesh, lines, floor, view, bind)
        })?;
        Ok(Self {
            ctx,
            format,
            mesh,
            lines,
            floor,
            view,
            bind,
            attachments: None,
            bodies: Vec::new(),
            tri_vertices: Vec::new(),
            tri_indices: Vec::new(),
            line_vertices: Vec::new(),
            strain: Vec::new(),
            tri_vb: Growing::new(wgpu::BufferUsages::VERTEX, "triangles"),
            tri_ib: Growing::new(wgpu::BufferUsages::INDEX, "indices"),
            line_vb: Growing::new(wgpu::BufferUsages::VERTEX, "lines"),
        })
    }

    /// The GPU context it draws with.
    pub fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    /// The format of the texture views it draws into.
    pub fn format(&self) -> wgpu::TextureFormat {
        self.format
    }

    /// Draws `sim` at `alpha` between its last two steps (see [`Simulation::render`]) into
    /// `target` (`width` × `height`, this renderer's format). Bodies come from the scene's own
    /// rapier sets, or from `colliders` and `bodies` when given (a caller stepping its own).
    #[allow(clippy::too_many_arguments)]
    pub fn draw(
        &mut self,
        sim: &mut Simulation,
        alpha: f64,
        sets: Option<(&ColliderSet, &RigidBodySet)>,
        camera: &Camera,
        style: &Style,
        target: &wgpu::TextureView,
        (width, height): (u32, u32),
    ) -> Result<(), GpuError> {
        self.build(sim, alpha, sets, style);
        // The floor: under everything, at most at y = 0; its grid's spacing follows the camera
        // distance only, so it stays put while the scene moves.
        let (lo, _) = bounds(sim);
        let floor_y = lo.y.min(0.0) - 1e-3;
        let radius = camera.distance * (0.5 * camera.fov_y).tan();
        let spacing = 10f32.powf((radius / 2.0).log10().floor());
        let uniform = ViewUniform {
            view_proj: camera
                .view_proj(width as f32 / height.max(1) as f32)
                .to_cols_array_2d(),
            eye: camera.eye().extend(1.0).to_array(),
            floor: [camera.target.x, floor_y, camera.target.z, 4.0 * radius],
            grid: [spacing, 0.0, 0.0, 0.0],
        };
        let ctx = self.ctx.clone();
        ctx.scoped("draw", || {
            self.ensure_attachments(width, height);
            ctx.queue
                .write_buffer(&self.view, 0, bytemuck::bytes_of(&uniform));
            self.tri_vb
                .write(&ctx, bytemuck::cast_slice(&self.tri_vertices));
            self.tri_ib
                .write(&ctx, bytemuck::cast_slice(&self.tri_indices));
            self.line_vb
                .write(&ctx, bytemuck::cast_slice(&self.line_vertices));
            let Some(att) = &self.attachments else {
                return;
            };
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("draw"),
                });
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("draw"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &att.colour,
                        depth_slice: None,
                        resolve_target: Some(target),
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color {
                                r: SKY[0],
                                g: SKY[1],
                                b: SKY[2],
                                a: 1.0,
                            }),
                            store: wgpu::StoreOp::Discard,
                        },
                    })],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &att.depth,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Discard,
                        }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_bind_group(0, &self.bind, &[]);
                pass.set_pipeline(&self.floor);
                pass.draw(0..6, 0..1);
                if let (Some(vb), Some(ib)) = (&self.tri_vb.buffer, &self.tri_ib.buffer) {
                    if !self.tri_indices.is_empty() {
                        pass.set_pipeline(&self.mesh);
                        pass.set_vertex_buffer(0, vb.slice(..));
                        pass.set_index_buffer(ib.slice(..), wgpu::IndexFormat::Uint32);
                        pass.draw_indexed(0..self.tri_indices.len() as u32, 0, 0..1);
                    }
                }
                if let Some(vb) = &self.line_vb.buffer {
                    if !self.line_vertices.is_empty() {
                        pass.set_pipeline(&self.lines);
                        pass.set_vertex_buffer(0, vb.slice(..));
                        pass.draw(0..self.line_vertices.len() as u32, 0..1);
                    }
                }
            }
            ctx.queue.submit([encoder.finish()]);
        })
    }

    fn ensure_attachments(&mut self, width: u32, height: u32) {
        if self
            .attachments
            .as_ref()
            .is_some_and(|a| a.size == (width, height))
        {
            return;
        }
        let texture = |format, label| {
            self.ctx
                .device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d {
                        width,
                        height,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: SAMPLES,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        };
        self.attachments = Some(Attachments {
            size: (width, height),
            colour: texture(self.format, "colour (multisampled)"),
            depth: texture(DEPTH, "depth"),
        });
    }

    /// The frame's geometry on the CPU: cloth triangles (or rope particles and springs),
    /// body meshes posed, wireframe lines.
    fn build(
        &mut self,
        sim: &mut Simulation,
        alpha: f64,
        sets: Option<(&ColliderSet, &RigidBodySet)>,
        style: &Style,
    ) {
        self.tri_vertices.clear();
        self.tri_indices.clear();
        self.line_vertices.clear();
        // Per-particle strain: the largest over its springs.
        self.strain.clear();
        self.strain.resize(sim.positions().len(), 0.0);
        if style.strain {
            let packed = sim.packed();
            for s in packed.all_springs() {
                let (a, b) = (s.a as usize, s.b as usize);
                if s.rest <= 0.0 {
                    continue;
                }
                // Stretch only: folding compresses the bend springs, which is not strain.
                let e = ((packed.x[a].distance(packed.x[b]) - s.rest).max(0.0) / s.rest) as f32;
                self.strain[a] = self.strain[a].max(e);
                self.strain[b] = self.strain[b].max(e);
            }
        }
        let scale = if style.strain_scale > 0.0 {
            style.strain_scale
        } else {
            0.1
        };
        let rope_size = rope_marker(sim);
        let view = sim.render(alpha);
        let colour = |i: usize, strain: &[f32]| {
            if style.strain {
                strain_colour(strain[i], scale)
            } else {
                CLOTH
            }
        };
        let n = view.positions.len();
        if !view.triangles.is_empty() {
            for (i, (p, nrm)) in view.positions.iter().zip(view.normals).enumerate() {
                self.tri_vertices.push(Vertex {
                    position: p.to_array(),
                    normal: nrm.to_array(),
                    colour: colour(i, &self.strain),
                });
            }
            for t in view.triangles {
                if t.iter().all(|&i| (i as usize) < n) {
                    self.tri_indices.extend_from_slice(t);
                }
            }
            if style.wireframe {
                // Edges in a darker shade of the surface: a dense mesh still shows its colours.
                for t in view.triangles {
                    if t.iter().any(|&i| (i as usize) >= n) {
                        continue;
                    }
                    for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                        for i in [a, b] {
                            let c = colour(i as usize, &self.strain);
                            self.line_vertices.push(Vertex {
                                position: view.positions[i as usize].to_array(),
                                normal: [0.0; 3],
                                colour: c.map(|v| 0.55 * v),
                            });
                        }
                    }
                }
            }
        } else if let Some(size) = rope_size {
            // Ropes and loose particles: a small octahedron per particle, springs as lines.
            let dirs = [
                Vec3::X,
                Vec3::NEG_X,
                Vec3::Y,
                Vec3::NEG_Y,
                Vec3::Z,
                Vec3::NEG_Z,
            ];
            const FACES: [[usize; 3]; 8] = [
                [0, 2, 4],
                [2, 1, 4],
                [1, 3, 4],
                [3, 0, 4],
                [2, 0, 5],
                [1, 2, 5],
                [3, 1, 5],
                [0, 3, 5],
            ];
            for (i, p) in view.positions.iter().enumerate() {
                let c = colour(i, &self.strain);
                for f in FACES {
                    push_flat(
                        &mut self.tri_indices,
                        &mut self.tri_vertices,
                        f.map(|k| *p + size * dirs[k]),
                        c,
                    );
                }
            }
            let packed = sim.packed();
            for s in packed.all_springs() {
                for i in [s.a, s.b] {
                    let x = packed.x[i as usize].as_vec3();
                    self.line_vertices.push(Vertex {
                        position: x.to_array(),
                        normal: [0.0; 3],
                        colour: [0.35, 0.2, 0.1],
                    });
                }
            }
        }
        // Bodies.
        let (colliders, bodies) = match sets {
            Some(s) => s,
            None => match sim.props() {
                Some(p) => (p.colliders(), p.bodies()),
                None => return,
            },
        };
        if self.bodies.len() != colliders.len()
            || self.bodies.iter().any(|b| !colliders.contains(b.collider))
        {
            self.bodies.clear();
            for (h, co) in colliders.iter() {
                if let Some((vertices, triangles)) = body_mesh(co.shape()) {
                    self.bodies.push(BodyMesh {
                        collider: h,
                        vertices,
                        triangles,
                    });
                }
            }
        }
        for mesh in &self.bodies {
            let Some(co) = colliders.get(mesh.collider) else {
                continue;
            };
            let body = co.parent().and_then(|h| bodies.get(h));
            let colour = match body {
                Some(b) if b.is_dynamic() => [0.25, 0.5, 0.85],
                Some(b) if b.is_kinematic() => [0.35, 0.65, 0.4],
                _ => [0.6, 0.63, 0.7],
            };
            let pose = co.position();
            for t in &mesh.triangles {
                push_flat(
                    &mut self.tri_indices,
                    &mut self.tri_vertices,
                    t.map(|i| pose.transform_point(mesh.vertices[i as usize])),
                    colour,
                );
            }
        }
    }
}

/// The half-size of the marker drawn at each particle of a scene without triangles: a quarter
/// of the mean spring length (a tenth of the box's size without springs). None when the
/// scene has too many particles to mark.
fn rope_marker(sim: &Simulation) -> Option<f32> {
    let packed = sim.packed();
    if packed.x.is_empty() || packed.x.len() > 20_000 {
        return None;
    }
    let n = packed.spring_count();
    if n > 0 {
        let mean = packed.all_springs().map(|s| s.rest).sum::<f64>() / n as f64;
        if mean > 0.0 {
            return Some((0.25 * mean) as f32);
        }
    }
    let (lo, hi) = bounds(sim);
    Some((0.02 * (hi - lo).length()).max(0.01))
}

/// RGBA8 pixels, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Four bytes per pixel (R, G, B, A), row by row from the top left.
    pub rgba: Vec<u8>,
}

impl Image {
    /// The RGBA of pixel `(x, y)`, `x` from the left and `y` from the top.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = 4 * (y as usize * self.width as usize + x as usize);
        [
            self.rgba[i],
            self.rgba[i + 1],
            self.rgba[i + 2],
            self.rgba[i + 3],
        ]
    }

    /// Pixels of the plain cloth colour family (red well above blue: no sky, floor or body
    /// colour is), whatever the shading.
    pub fn cloth_pixels(&self) -> usize {
        self.rgba
            .chunks_exact(4)
            .filter(|p| p[0] as i32 - p[2] as i32 > 60 && p[0] as i32 > p[1] as i32 + 20)
            .count()
    }

    /// Distinct colours (a blank picture has one or two).
    pub fn distinct_colours(&self) -> usize {
        let mut seen: Vec<u32> = self
            .rgba
            .chunks_exact(4)
            .map(|p| u32::from_le_bytes([p[0], p[1], p[2], p[3]]))
            .collect();
        seen.sort_unstable();
        seen.dedup();
        seen.len()
    }

    /// `frames` tiled `columns` wide (all the same size).
    pub fn sheet(frames: &[Image], columns: u32) -> Option<Image> {
        let first = frames.first()?;
        let (w, h) = (first.width, first.height);
        let columns = columns.clamp(1, frames.len() as u32);
        let rows = (frames.len() as u32).div_ceil(columns);
        let mut out = Image {
            width: w * columns,
            height: h * rows,
            rgba: vec![255; (w * columns * h * rows * 4) as usize],
        };
        for (k, f) in frames.iter().enumerate() {
            if (f.width, f.height) != (w, h) {
                return None;
            }
            let (cx, cy) = (k as u32 % columns, k as u32 / columns);
            for y in 0..h {
                let src = &f.rgba[(y * w * 4) as usize..((y + 1) * w * 4) as usize];
                let at = (((cy * h + y) * out.width + cx * w) * 4) as usize;
                out.rgba[at..at + src.len()].copy_from_slice(src);
            }
        }
        Some(out)
    }

    /// Writes the image to `path` as an 8-bit RGBA PNG; an error names the path.
    pub fn write_png(&self, path: &Path) -> Result<(), ImageError> {
        let at = |e: png::EncodingError| ImageError {
            path: path.to_path_buf(),
            source: e,
        };
        let file = std::fs::File::create(path).map_err(|e| at(e.into()))?;
        let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), self.width, self.height);
        encoder.set_color(png::ColorType::Rgba);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(at)?;
        writer.write_image_data(&self.rgba).map_err(at)
    }
}

/// An image could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct ImageError {
    /// The file that could not be written.
    pub path: std::path::PathBuf,
    /// Why: the file could not be created, or the PNG encoder failed.
    #[source]
    pub source: png::EncodingError,
}

/// A renderer with its own target texture, read back to the CPU after each draw.
pub struct Offscreen {
    renderer: Renderer,
    size: (u32, u32),
    target: wgpu::Texture,
    view: wgpu::TextureView,
    staging: wgpu::Buffer,
    row: u32,
}

impl Offscreen {
    /// Renders of `width` × `height` on the shared GPU context (software adapters allowed).
    pub fn new(width: u32, height: u32) -> Result<Self, GpuError> {
        let limit = 8192;
        if width == 0 || height == 0 || width > limit || height > limit {
            return Err(GpuError::Device {
                adapter: "offscreen".into(),
                what: format!("image size {width}x{height} is outside 1..={limit} per side"),
            });
        }
        let ctx = GpuContext::shared(true)?;
        let renderer = Renderer::new(ctx.clone(), FORMAT)?;
        let target = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("offscreen"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = target.create_view(&Default::default());
        let row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("offscreen read-back"),
            size: row as u64 * height as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Self {
            renderer,
            size: (width, height),
            target,
            view,
            staging,
            row,
        })
    }

    /// The renderer that draws into its texture.
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// Draws `sim` as it stands and reads the picture back.
    pub fn capture(
        &mut self,
        sim: &mut Simulation,
        camera: &Camera,
        style: &Style,
    ) -> Result<Image, GpuError> {
        let size = self.size;
        self.renderer
            .draw(sim, 1.0, None, camera, style, &self.view, size)?;
        let (width, height) = size;
        let row = self.row;
        let mut rgba = vec![0u8; (width * height * 4) as usize];
        let ctx = self.renderer.ctx.clone();
        crate::gpu::read_staging(
            &ctx,
            "offscreen read-back",
            &self.staging,
            row as u64 * height as u64,
            |encoder| {
                encoder.copy_texture_to_buffer(
                    wgpu::TexelCopyTextureInfo {
                        texture: &self.target,
                        mip_level: 0,
                        origin: wgpu::Origin3d::ZERO,
                        aspect: wgpu::TextureAspect::All,
                    },
                    wgpu::TexelCopyBufferInfo {
                        buffer: &self.staging,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset: 0,
                            bytes_per_row: Some(row),
                            rows_per_image: Some(height),
                        },
                    },
                    wgpu::Extent3d {
                        width,
                        height,
                        depth_or_array_layers: 1,
                    },
                );
            },
            |bytes| {
                for y in 0..height as usize {
                    let src = &bytes[y * row as usize..][..width as usize * 4];
                    rgba[y * width as usize * 4..][..width as usize * 4].copy_from_slice(src);
                }
            },
        )?;
        Ok(Image {
            width,
            height,
            rgba,
        })
    }
}
