//! The renderer: pipelines, and the frame's geometry drawn into a texture view.

use std::sync::Arc;

use glam::Vec3;
use rapier3d::prelude::{ColliderSet, RigidBodySet};

use super::geometry::*;
use super::*;
use crate::error::GpuError;
use crate::gpu::GpuContext;

/// Draws simulations into texture views of one format.
pub struct Renderer {
    pub(super) ctx: Arc<GpuContext>,
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
        let scale = if style.strain_scale.is_finite() && style.strain_scale > 0.0 {
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
