//! The GPU back end: `shaders/integrate.wgsl` through wgpu, state resident on the device.
//!
//! - [`GpuContext`]: adapter (Vulkan or GL), device and queue.
//! - [`GpuSolver`]: pipelines (one per entry point, specialised to the scene), buffers uploaded
//!   at gather, substeps encoded into one submit, and a staging buffer read only on request.
//!
//! The springs go to the device in colour order, so a Gauss–Seidel colour is a contiguous range
//! and the Jacobi passes index the same array. Cloth grids kept whole (symplectic and explicit
//! Euler, `harmonic`) go as their links only: `grid_pass` finds each particle's neighbours from
//! its grid position, as the CPU grid pass does, with no memory per spring. Under `harmonic`
//! the links hold the closed form for one mass, and each spring the CPU pass corrects
//! (`grid::Fix`) goes as two extra device springs, its own closed form and the nominal force
//! taken back. Coefficients (`p`, `q`) come
//! from the CPU ([`crate::integrate::harmonic`]), once per `h`: one definition of the spring
//! math.

use std::sync::{Arc, Mutex, OnceLock};

use bytemuck::{Pod, Zeroable};
use glam::DVec3;
use wgpu::util::DeviceExt;

use crate::buffers::Packed;
use crate::error::GpuError;
use crate::integrate::harmonic::Linear;
use crate::integrate::{grid, Integrator, SGS_SWEEPS};

pub mod bench;
pub mod contacts;

/// The WGSL source of every kernel.
pub const SHADER: &str = include_str!("../../shaders/integrate.wgsl");
/// Invocations per workgroup (the shader's `WORKGROUP` override).
pub const WORKGROUP: u32 = 256;
/// Workgroups per dispatch dimension (WebGPU's minimum limit).
const MAX_GROUPS: u32 = 65_535;

/// `Params` in shaders/integrate.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Params {
    pub gravity: [f32; 3],
    pub h: f32,
    pub particles: u32,
    pub springs: u32,
    /// Always 1.0 (see `drift_by` in the shader).
    pub one: f32,
    pub _pad1: u32,
}

/// `Position`: `x = hi + lo`, a compensated pair.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Position {
    pub hi: [f32; 4],
    pub lo: [f32; 4],
}

impl Position {
    pub fn from_f64(x: DVec3) -> Self {
        let hi = x.as_vec3();
        let lo = (x - hi.as_dvec3()).as_vec3();
        Self {
            hi: [hi.x, hi.y, hi.z, 0.0],
            lo: [lo.x, lo.y, lo.z, 0.0],
        }
    }
    pub fn to_f64(self) -> DVec3 {
        let [hx, hy, hz, _] = self.hi.map(f64::from);
        let [lx, ly, lz, _] = self.lo.map(f64::from);
        DVec3::new(hx + lx, hy + ly, hz + lz)
    }
}

/// `Coef`: a spring's rest length, step coefficients and end a's mass share (b's is 1 − wa).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Coef {
    pub rest: f32,
    pub p: f32,
    pub q: f32,
    pub wa: f32,
}

/// `Entry`: one incident spring of a particle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Entry {
    pub spring: u32,
    pub coef: f32,
}

/// `Range`: one colour's springs, or one cloth grid's particles and links.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Range {
    pub start: u32,
    pub count: u32,
    /// A grid's columns (0 for a colour).
    pub cols: u32,
    /// A grid's first link, counted past the springs.
    pub links: u32,
    pub link_count: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// How the kernels step: which entry points run, in which order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// `spring_pass`, `grid_pass` per cloth grid kept whole, then `particle_pass` (harmonic,
    /// symplectic and explicit Euler).
    Jacobi,
    /// `add_gravity`, `sweeps` colour sweeps alternating direction, `drift`.
    GaussSeidel { sweeps: u32 },
}

impl Kernel {
    /// The GPU kernel of an integrator, if it has one.
    pub fn of(integrator: Integrator, exact_displacement: bool) -> Option<Kernel> {
        match integrator {
            Integrator::Harmonic if exact_displacement => None,
            Integrator::Harmonic | Integrator::SymplecticEuler | Integrator::ExplicitEuler => {
                Some(Kernel::Jacobi)
            }
            Integrator::HarmonicGs => Some(Kernel::GaussSeidel { sweeps: 1 }),
            Integrator::HarmonicSgs => Some(Kernel::GaussSeidel {
                sweeps: SGS_SWEEPS as u32,
            }),
            _ => None,
        }
    }

    /// Integrators with a GPU kernel.
    pub fn supported() -> impl Iterator<Item = Integrator> {
        Integrator::ALL
            .into_iter()
            .filter(|&i| Kernel::of(i, false).is_some())
    }
}

/// What the shader is specialised to (its override constants), chosen from the scene at gather.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Specialisation {
    /// Some spring has `q ≠ 0` (damped, or any harmonic spring): the spring pass reads velocities.
    pub rate: bool,
    /// Some particle is pinned: the pin test stays in.
    pub pins: bool,
    /// 0: velocity first; 1: position first (explicit Euler).
    pub update: u32,
    /// Cloth grids are kept whole: `particle_pass` adds what `grid_pass` summed.
    pub grids: bool,
}

impl Specialisation {
    /// What a scene needs at step `h` (`lin`: its springs' coefficients for `h`).
    pub fn of(packed: &Packed, lin: &[Linear], h: f64, integrator: Integrator) -> Self {
        let live = |k: &&u32| packed.springs[**k as usize].mu.is_finite();
        Self {
            rate: packed
                .colouring
                .springs
                .iter()
                .filter(live)
                .any(|&k| lin[k as usize].q != 0.0)
                || packed.grids.iter().flat_map(|g| &g.links).any(|l| {
                    // The closed form responds to δ̇ even undamped (q = cos ωh − 1).
                    integrator == Integrator::Harmonic || grid::link_coefficients(l, h).q != 0.0
                }),
            pins: packed.inv_mass.contains(&0.0),
            update: u32::from(integrator == Integrator::ExplicitEuler),
            grids: !packed.grids.is_empty(),
        }
    }

    /// Every term in, whatever the scene: the unspecialised kernel, for comparison.
    pub fn general(self) -> Self {
        Self {
            rate: true,
            pins: true,
            ..self
        }
    }

    fn constants(&self) -> [(&'static str, f64); 5] {
        [
            ("WORKGROUP", WORKGROUP as f64),
            ("RATE", f64::from(u8::from(self.rate))),
            ("PINS", f64::from(u8::from(self.pins))),
            ("UPDATE", self.update as f64),
            ("GRIDS", f64::from(u8::from(self.grids))),
        ]
    }
}

/// True for adapters that run on the CPU (lavapipe, llvmpipe, SwiftShader).
pub fn is_software(info: &wgpu::AdapterInfo) -> bool {
    let name = info.name.to_lowercase();
    info.device_type == wgpu::DeviceType::Cpu
        || ["llvmpipe", "lavapipe", "softpipe", "swiftshader"]
            .iter()
            .any(|s| name.contains(s))
}

/// An adapter, its device and queue.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    /// Errors wgpu reported outside an error scope (instead of its default panic).
    uncaptured: Arc<Mutex<Vec<String>>>,
}

impl GpuContext {
    /// The best adapter: discrete, integrated, virtual, then software (only when
    /// `allow_software`); Vulkan, else GL.
    pub fn new(allow_software: bool) -> Result<Self, GpuError> {
        // Vulkan first; GL (which probes EGL and window systems) only when Vulkan has nothing.
        let mut adapters = Vec::new();
        for backends in [wgpu::Backends::VULKAN, wgpu::Backends::GL] {
            let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
                backends,
                ..wgpu::InstanceDescriptor::new_without_display_handle()
            });
            adapters.extend(pollster::block_on(instance.enumerate_adapters(backends)));
            if adapters
                .iter()
                .any(|a| allow_software || !is_software(&a.get_info()))
            {
                break;
            }
        }
        let rank = |info: &wgpu::AdapterInfo| {
            let kind = match info.device_type {
                _ if is_software(info) => 4,
                wgpu::DeviceType::DiscreteGpu => 0,
                wgpu::DeviceType::IntegratedGpu => 1,
                wgpu::DeviceType::VirtualGpu => 2,
                _ => 3,
            };
            (kind, u8::from(info.backend != wgpu::Backend::Vulkan))
        };
        let found: Vec<String> = adapters.iter().map(|a| describe(&a.get_info())).collect();
        let adapter = adapters
            .into_iter()
            .filter(|a| allow_software || !is_software(&a.get_info()))
            .min_by_key(|a| rank(&a.get_info()));
        let Some(adapter) = adapter else {
            return Err(if found.is_empty() {
                GpuError::NoAdapter
            } else {
                GpuError::OnlySoftware {
                    found: found.join("; "),
                }
            });
        };
        let info = adapter.get_info();
        let limits = adapter.limits();
        if limits.max_storage_buffers_per_shader_stage < 7 {
            return Err(GpuError::Device {
                adapter: describe(&info),
                what: format!(
                    "needs 7 storage buffers per shader stage, the adapter has {}",
                    limits.max_storage_buffers_per_shader_stage
                ),
            });
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("harmonic"),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device {
            adapter: describe(&info),
            what: e.to_string(),
        })?;
        Ok(Self::from_device(device, queue, info, limits))
    }

    /// A context on a device the caller made: a windowed application's, from an adapter
    /// compatible with its surface (`examples/viewer.rs`).
    pub fn from_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        info: wgpu::AdapterInfo,
        limits: wgpu::Limits,
    ) -> Self {
        let uncaptured = Arc::new(Mutex::new(Vec::new()));
        let sink = uncaptured.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(e.to_string());
            }
        }));
        Self {
            device,
            queue,
            info,
            limits,
            uncaptured,
        }
    }

    /// One context per process and kind (hardware only, or software allowed), made on first use:
    /// every simulation shares its device.
    pub fn shared(allow_software: bool) -> Result<Arc<GpuContext>, GpuError> {
        static HARDWARE: OnceLock<Result<Arc<GpuContext>, GpuError>> = OnceLock::new();
        static ANY: OnceLock<Result<Arc<GpuContext>, GpuError>> = OnceLock::new();
        let cell = if allow_software { &ANY } else { &HARDWARE };
        cell.get_or_init(|| GpuContext::new(allow_software).map(Arc::new))
            .clone()
    }

    /// "name (backend, device type)".
    pub fn describe(&self) -> String {
        describe(&self.info)
    }

    pub fn is_software(&self) -> bool {
        is_software(&self.info)
    }

    /// Runs `f` inside a validation and an out-of-memory error scope.
    pub(crate) fn scoped<T>(&self, what: &str, f: impl FnOnce() -> T) -> Result<T, GpuError> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out = f();
        let e1 = pollster::block_on(validation.pop());
        let e2 = pollster::block_on(oom.pop());
        let stray = self
            .uncaptured
            .lock()
            .map(|mut v| v.drain(..).collect::<Vec<_>>())
            .unwrap_or_default();
        match e1
            .or(e2)
            .map(|e| e.to_string())
            .or(stray.into_iter().next())
        {
            Some(e) => Err(GpuError::Device {
                adapter: self.describe(),
                what: format!("{what}: {e}"),
            }),
            None => Ok(out),
        }
    }
}

fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

/// The compute pipelines of one specialisation.
struct Pipelines {
    spec: Specialisation,
    spring_pass: wgpu::ComputePipeline,
    grid_pass: wgpu::ComputePipeline,
    particle_pass: wgpu::ComputePipeline,
    add_gravity: wgpu::ComputePipeline,
    sweep_colour: wgpu::ComputePipeline,
    drift: wgpu::ComputePipeline,
}

/// Device buffers of one topology.
struct Buffers {
    params: wgpu::Buffer,
    pos: wgpu::Buffer,
    vel: wgpu::Buffer,
    coefs: wgpu::Buffer,
    sdv: wgpu::Buffer,
    staging: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// Colour ranges (start, count), in sweep order.
    colours: Vec<(u32, u32)>,
    /// Each cloth grid's particles (first, count); their `Range`s follow the colours' in the
    /// uniform.
    grids: Vec<(u32, u32)>,
    /// Dynamic-offset stride of the colour uniform.
    colour_stride: u32,
    particles: u32,
    springs_len: u32,
}

/// The GPU step over one scene.
pub struct GpuSolver {
    ctx: Arc<GpuContext>,
    module: wgpu::ShaderModule,
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    pipelines: Option<Pipelines>,
    buffers: Option<Buffers>,
    kernel: Kernel,
    /// Whether to specialise the shader to the scene (off only to measure what it buys).
    pub specialise: bool,
    /// The host copy of the spring coefficients, in device order, for step changes.
    host_coefs: Vec<Coef>,
    /// The grids step under the closed form (`grid::GridLaw::Harmonic`), not Euler.
    harmonic_grids: bool,
    /// Host scratch for state uploads.
    host_pos: Vec<Position>,
    host_vel: Vec<[f32; 4]>,
    h: f32,
    /// The contact stage on the device, when the scene's colliders allow it.
    contacts: Option<contacts::DeviceContacts>,
}

impl GpuSolver {
    pub fn new(ctx: Arc<GpuContext>, kernel: Kernel) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let (module, layout, pipeline_layout) = ctx.scoped("shader module", || {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("integrate.wgsl"),
                source: wgpu::ShaderSource::Wgsl(SHADER.into()),
            });
            let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            };
            let uniform = |binding, dynamic| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: dynamic,
                    min_binding_size: None,
                },
                count: None,
            };
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("integrate"),
                entries: &[
                    uniform(0, false),
                    storage(1, false),
                    storage(2, false),
                    storage(3, true),
                    storage(4, true),
                    storage(5, false),
                    storage(6, true),
                    storage(7, true),
                    uniform(8, true),
                ],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("integrate"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            (module, layout, pipeline_layout)
        })?;
        Ok(Self {
            ctx,
            module,
            layout,
            pipeline_layout,
            pipelines: None,
            buffers: None,
            kernel,
            specialise: true,
            host_coefs: Vec::new(),
            harmonic_grids: false,
            host_pos: Vec::new(),
            host_vel: Vec::new(),
            h: f32::NAN,
            contacts: None,
        })
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    /// The specialisation the pipelines were built for (after an upload).
    pub fn specialisation(&self) -> Option<Specialisation> {
        self.pipelines.as_ref().map(|p| p.spec)
    }

    fn pipelines(&self, spec: Specialisation) -> Result<Pipelines, GpuError> {
        let constants = spec.constants();
        let make = |entry: &str| {
            self.ctx
                .device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: Some(&self.pipeline_layout),
                    module: &self.module,
                    entry_point: Some(entry),
                    compilation_options: wgpu::PipelineCompilationOptions {
                        constants: &constants,
                        zero_initialize_workgroup_memory: false,
                    },
                    cache: None,
                })
        };
        self.ctx.scoped("compute pipelines", || Pipelines {
            spec,
            spring_pass: make("spring_pass"),
            grid_pass: make("grid_pass"),
            particle_pass: make("particle_pass"),
            add_gravity: make("add_gravity"),
            sweep_colour: make("sweep_colour"),
            drift: make("drift"),
        })
    }

    /// Gather: uploads state and topology, with coefficients `lin` (per packed spring) for step
    /// `h`, and builds the pipelines if the scene needs another specialisation.
    pub fn upload(
        &mut self,
        packed: &Packed,
        lin: &[Linear],
        gravity: DVec3,
        h: f64,
        integrator: Integrator,
    ) -> Result<(), GpuError> {
        self.contacts = None;
        if !packed.grids.is_empty() && !integrator.runs_on_gpu_grids() {
            return Err(GpuError::Device {
                adapter: self.ctx.describe(),
                what: format!("{integrator} does not step cloth grids kept whole"),
            });
        }
        let mut spec = Specialisation::of(packed, lin, h, integrator);
        if !self.specialise {
            spec = spec.general();
        }
        if self.pipelines.as_ref().map(|p| p.spec) != Some(spec) {
            self.pipelines = Some(self.pipelines(spec)?);
        }
        let n = packed.particle_count();
        let order = &packed.colouring.springs;
        self.harmonic_grids = integrator == Integrator::Harmonic;
        let (fixes, grid_coefs) = grid_device(packed, h, self.harmonic_grids);
        // Device index of each packed spring (u32::MAX: both ends pinned, not on the device).
        let mut device_index = vec![u32::MAX; packed.springs.len()];
        for (j, &k) in order.iter().enumerate() {
            device_index[k as usize] = j as u32;
        }
        // Device springs: the packed ones in colour order, then each fix twice (its own
        // closed form, then the nominal force it takes back); then the grids' links.
        let springs_len = order.len() + 2 * fixes.len();
        // The springs' ends, then the grids' link offsets (as i32 bits).
        let ends: Vec<[u32; 2]> = order
            .iter()
            .map(|&k| {
                let s = &packed.springs[k as usize];
                [s.a, s.b]
            })
            .chain(fixes.iter().chain(&fixes).map(|f| [f.a as u32, f.b as u32]))
            .chain(
                packed
                    .grids
                    .iter()
                    .flat_map(|g| &g.links)
                    .map(|l| [l.offset.0 as u32, l.offset.1 as u32]),
            )
            .collect();
        self.host_coefs = order
            .iter()
            .map(|&k| {
                let (s, l) = (&packed.springs[k as usize], &lin[k as usize]);
                Coef {
                    rest: s.rest as f32,
                    p: l.p as f32,
                    q: l.q as f32,
                    wa: s.wa as f32,
                }
            })
            .collect();
        self.host_coefs.extend(grid_coefs);
        fill_state(packed, &mut self.host_pos, &mut self.host_vel);
        let (positions, velocities) = (&self.host_pos, &self.host_vel);
        let (offsets, entries) = incidence(packed, &device_index, &fixes, order.len());
        // Dynamic offsets must be multiples of the alignment, and a step must hold a Range.
        let stride = (std::mem::size_of::<Range>() as u32)
            .next_multiple_of(self.ctx.limits.min_uniform_buffer_offset_alignment.max(16));
        let mut colours: Vec<(u32, u32)> = (0..packed.colouring.colours())
            .map(|c| {
                let o = &packed.colouring.offsets;
                (o[c], o[c + 1] - o[c])
            })
            .collect();
        if colours.is_empty() {
            colours.push((0, 0));
        }
        let mut ranges: Vec<Range> = colours
            .iter()
            .map(|&(start, count)| Range {
                start,
                count,
                ..Range::default()
            })
            .collect();
        let (mut links, mut grids) = (0, Vec::with_capacity(packed.grids.len()));
        for g in &packed.grids {
            grids.push((g.base, g.cols * g.rows));
            ranges.push(Range {
                start: g.base,
                count: g.cols * g.rows,
                cols: g.cols,
                links,
                link_count: g.links.len() as u32,
                ..Range::default()
            });
            links += g.links.len() as u32;
        }
        let range_size = std::mem::size_of::<Range>();
        let mut colour_bytes = vec![0u8; ranges.len() * stride as usize];
        for (c, r) in ranges.iter().enumerate() {
            let at = c * stride as usize;
            colour_bytes[at..at + range_size].copy_from_slice(bytemuck::bytes_of(r));
        }
        // Per spring, then (with grids) per particle: what grid_pass summed, zero elsewhere.
        let sdv_len = springs_len + if packed.grids.is_empty() { 0 } else { n };
        let params = Params {
            gravity: gravity.as_vec3().to_array(),
            h: h as f32,
            particles: n as u32,
            springs: springs_len as u32,
            one: 1.0,
            ..Params::default()
        };
        let device = &self.ctx.device;
        let host_coefs = &self.host_coefs;
        let layout = &self.layout;
        let buffers = self.ctx.scoped("upload", || {
            use wgpu::BufferUsages as U;
            let init = |label, bytes: &[u8], usage| {
                // A binding may not be empty: a scene without springs still gets one element.
                let bytes = if bytes.is_empty() {
                    &[0u8; 32][..]
                } else {
                    bytes
                };
                device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: bytes,
                    usage,
                })
            };
            let rw = U::STORAGE | U::COPY_SRC | U::COPY_DST;
            let params = init(
                "params",
                bytemuck::bytes_of(&params),
                U::UNIFORM | U::COPY_DST,
            );
            let pos = init("pos", bytemuck::cast_slice(positions), rw);
            let vel = init("vel", bytemuck::cast_slice(velocities), rw);
            let ends = init("ends", bytemuck::cast_slice(&ends), U::STORAGE);
            let coefs = init(
                "coefs",
                bytemuck::cast_slice(host_coefs),
                U::STORAGE | U::COPY_DST,
            );
            let mut sdv_bytes = poison(springs_len * 16);
            sdv_bytes.resize(sdv_len * 16, 0);
            let sdv = init("sdv", &sdv_bytes, rw);
            let offsets = init("offsets", bytemuck::cast_slice(&offsets), U::STORAGE);
            let entries = init("entries", bytemuck::cast_slice(&entries), U::STORAGE);
            let colour = init("colours", &colour_bytes, U::UNIFORM);
            let state_bytes = (n * (std::mem::size_of::<Position>() + 16)).max(32) as u64;
            let staging = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("staging"),
                size: state_bytes,
                usage: U::MAP_READ | U::COPY_DST,
                mapped_at_creation: false,
            });
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("integrate"),
                layout,
                entries: &[
                    entry(0, &params),
                    entry(1, &pos),
                    entry(2, &vel),
                    entry(3, &ends),
                    entry(4, &coefs),
                    entry(5, &sdv),
                    entry(6, &offsets),
                    entry(7, &entries),
                    wgpu::BindGroupEntry {
                        binding: 8,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &colour,
                            offset: 0,
                            size: wgpu::BufferSize::new(range_size as u64),
                        }),
                    },
                ],
            });
            Buffers {
                params,
                pos,
                vel,
                coefs,
                sdv,
                staging,
                bind_group,
                colours,
                grids,
                colour_stride: stride,
                particles: n as u32,
                springs_len: springs_len as u32,
            }
        })?;
        self.buffers = Some(buffers);
        self.h = h as f32;
        Ok(())
    }

    /// A new step `h` with its coefficients: rewrites `h` and the springs' coefficients only.
    pub fn set_step(&mut self, packed: &Packed, lin: &[Linear], h: f64) -> Result<(), GpuError> {
        let Some(b) = &self.buffers else {
            return Ok(());
        };
        if self.h == h as f32 {
            return Ok(());
        }
        let springs = packed.colouring.springs.len();
        for (c, &k) in self.host_coefs.iter_mut().zip(&packed.colouring.springs) {
            c.p = lin[k as usize].p as f32;
            c.q = lin[k as usize].q as f32;
        }
        self.host_coefs.truncate(springs);
        self.host_coefs
            .extend(grid_device(packed, h, self.harmonic_grids).1);
        let q = &self.ctx.queue;
        q.write_buffer(&b.coefs, 0, bytemuck::cast_slice(&self.host_coefs));
        // h is the 4th f32 of Params.
        q.write_buffer(&b.params, 12, bytemuck::bytes_of(&(h as f32)));
        self.h = h as f32;
        Ok(())
    }

    /// Puts the contact stage on the device over the state uploaded last (call after each
    /// upload and step change); every substep then ends with the contact pass.
    pub fn enable_contacts(&mut self, setup: &contacts::ContactSetup<'_>) -> Result<(), GpuError> {
        let Some(b) = &self.buffers else {
            return Ok(());
        };
        self.contacts = Some(contacts::DeviceContacts::new(
            &self.ctx, &b.pos, &b.vel, setup,
        )?);
        Ok(())
    }

    /// The device contact stage, when enabled.
    pub fn contacts(&mut self) -> Option<&mut contacts::DeviceContacts> {
        self.contacts.as_mut()
    }

    /// Waits for the queued work; the contact partials of slots `first..first + count`.
    pub fn read_partials(
        &mut self,
        first: u32,
        count: u32,
    ) -> Result<&[contacts::Partial], GpuError> {
        match &mut self.contacts {
            Some(c) => c.read(&self.ctx, first, count),
            None => Ok(&[]),
        }
    }

    /// Encodes `substeps` substeps into one submit. Nothing is read back.
    pub fn run(&mut self, substeps: u32) -> Result<(), GpuError> {
        self.run_slots(0, substeps)
    }

    /// As [`Self::run`], the substeps using contact slots `first..first + substeps`.
    pub fn run_slots(&mut self, first: u32, substeps: u32) -> Result<(), GpuError> {
        let (Some(b), Some(p)) = (&self.buffers, &self.pipelines) else {
            return Ok(());
        };
        let contacts = self.contacts.as_ref();
        if let Some(c) = contacts {
            c.flush(&self.ctx.queue);
        }
        let kernel = self.kernel;
        let ctx = &self.ctx;
        ctx.scoped("step", || {
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("step"),
                });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("substeps"),
                    timestamp_writes: None,
                });
                for s in 0..substeps {
                    pass.set_bind_group(0, &b.bind_group, &[0]);
                    match kernel {
                        Kernel::Jacobi => {
                            pass.set_pipeline(&p.spring_pass);
                            dispatch(&mut pass, b.springs_len);
                            if !b.grids.is_empty() {
                                pass.set_pipeline(&p.grid_pass);
                                for (g, &(_, count)) in b.grids.iter().enumerate() {
                                    let at = (b.colours.len() + g) as u32 * b.colour_stride;
                                    pass.set_bind_group(0, &b.bind_group, &[at]);
                                    dispatch(&mut pass, count);
                                }
                                pass.set_bind_group(0, &b.bind_group, &[0]);
                            }
                            pass.set_pipeline(&p.particle_pass);
                            dispatch(&mut pass, b.particles);
                        }
                        Kernel::GaussSeidel { sweeps } => {
                            pass.set_pipeline(&p.add_gravity);
                            dispatch(&mut pass, b.particles);
                            pass.set_pipeline(&p.sweep_colour);
                            for sweep in 0..sweeps {
                                let n = b.colours.len();
                                for i in 0..n {
                                    let c = if sweep % 2 == 1 { n - 1 - i } else { i };
                                    let offset = c as u32 * b.colour_stride;
                                    pass.set_bind_group(0, &b.bind_group, &[offset]);
                                    dispatch(&mut pass, b.colours[c].1);
                                }
                            }
                            pass.set_bind_group(0, &b.bind_group, &[0]);
                            pass.set_pipeline(&p.drift);
                            dispatch(&mut pass, b.particles);
                        }
                    }
                    if let Some(c) = contacts {
                        c.encode(&mut pass, first + s);
                    }
                }
            }
            ctx.queue.submit([encoder.finish()]);
        })
    }

    /// Waits for the queued work and copies positions and velocities into `packed`
    /// (pinned particles included: the kernels never write them).
    pub fn read_back(&mut self, packed: &mut Packed) -> Result<(), GpuError> {
        let Some(b) = &self.buffers else {
            return Ok(());
        };
        let n = b.particles as usize;
        let pos_bytes = (n * std::mem::size_of::<Position>()) as u64;
        let vel_bytes = (n * 16) as u64;
        if n == 0 {
            return Ok(());
        }
        let total = pos_bytes + vel_bytes;
        read_staging(
            &self.ctx,
            "read back",
            &b.staging,
            total,
            |encoder| {
                encoder.copy_buffer_to_buffer(&b.pos, 0, &b.staging, 0, pos_bytes);
                encoder.copy_buffer_to_buffer(&b.vel, 0, &b.staging, pos_bytes, vel_bytes);
            },
            |bytes| {
                let pos: &[Position] = bytemuck::cast_slice(&bytes[..pos_bytes as usize]);
                let vel: &[[f32; 4]] = bytemuck::cast_slice(&bytes[pos_bytes as usize..]);
                for (x, p) in packed.x.iter_mut().zip(pos) {
                    *x = p.to_f64();
                }
                for (v, w) in packed.v.iter_mut().zip(vel) {
                    *v = DVec3::new(w[0].into(), w[1].into(), w[2].into());
                }
            },
        )
    }

    /// Uploads positions and velocities from `packed` (after the CPU changed them: contacts),
    /// through host scratch sized at gather.
    pub fn write_state(&mut self, packed: &Packed) {
        if let Some(b) = &self.buffers {
            fill_state(packed, &mut self.host_pos, &mut self.host_vel);
            let q = &self.ctx.queue;
            q.write_buffer(&b.pos, 0, bytemuck::cast_slice(&self.host_pos));
            q.write_buffer(&b.vel, 0, bytemuck::cast_slice(&self.host_vel));
        }
    }

    /// Blocks until the queued substeps have run.
    pub fn finish(&self) -> Result<(), GpuError> {
        self.ctx
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Readback(e.to_string()))
    }

    /// Overwrites the per-spring output buffer with NaN, so an element a pass fails to write
    /// shows up as a non-finite state (the parity tests call this before each run).
    pub fn poison(&mut self) {
        if let Some(b) = &self.buffers {
            let bytes = poison(b.springs_len as usize * 16);
            self.ctx.queue.write_buffer(&b.sdv, 0, &bytes);
            // And the grid particles' sums (the other particles' stay zero: no pass writes them).
            for &(first, count) in &b.grids {
                let at = (u64::from(b.springs_len) + u64::from(first)) * 16;
                let bytes = poison(count as usize * 16);
                self.ctx.queue.write_buffer(&b.sdv, at, &bytes);
            }
        }
    }

    /// Bytes the kernels move per substep at best (each element read or written once),
    /// for the memory-bound floor: see BENCHMARKS.md.
    pub fn bytes_per_substep(&self) -> u64 {
        let Some(b) = &self.buffers else { return 0 };
        let (n, m) = (b.particles as u64, b.springs_len as u64);
        let spec = self.specialisation();
        let rate = spec.is_none_or(|s| s.rate);
        let pos = std::mem::size_of::<Position>() as u64;
        match self.kernel {
            Kernel::Jacobi => {
                // Spring pass: spring, two positions (and velocities), one sdv write.
                // Particle pass: offsets, entries, sdv reads, position and velocity in and out.
                let spring_pass = m * (8 + 16 + 16) + n * (pos + if rate { 16 } else { 0 });
                let particle_pass = n * (4 + 2 * pos + 2 * 16) + 2 * m * (8 + 16);
                // Grid pass: each grid particle's position and velocity read (its neighbours'
                // from cache), its sum written, then read by the particle pass.
                let g: u64 = b.grids.iter().map(|&(_, c)| u64::from(c)).sum();
                let grid_pass = g * (pos + 16 + 16 + 16);
                spring_pass + grid_pass + particle_pass
            }
            Kernel::GaussSeidel { sweeps } => {
                let sweep = m * (8 + 16) + n * (pos + 2 * 16);
                n * 2 * 16 + sweeps as u64 * sweep + n * (2 * pos + 16)
            }
        }
    }
}

/// Encodes `copy` into `staging`, submits it, waits, and hands the first `bytes` of `staging`
/// to `read`: every read-back from the device goes through here.
pub(crate) fn read_staging(
    ctx: &GpuContext,
    what: &str,
    staging: &wgpu::Buffer,
    bytes: u64,
    copy: impl FnOnce(&mut wgpu::CommandEncoder),
    read: impl FnOnce(&[u8]),
) -> Result<(), GpuError> {
    ctx.scoped(what, || {
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(what) });
        copy(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
    })?;
    let failed = |e: &dyn std::fmt::Display| GpuError::Readback(e.to_string());
    let (tx, rx) = std::sync::mpsc::channel();
    staging
        .slice(..bytes)
        .map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
    ctx.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| failed(&e))?;
    match rx.recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(failed(&e)),
        Err(e) => return Err(failed(&e)),
    }
    {
        let view = staging.get_mapped_range(..bytes).map_err(|e| failed(&e))?;
        read(&view);
    }
    staging.unmap();
    Ok(())
}

/// Binding `binding` to the whole of `buffer`.
fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// The device form of the state: compensated positions, and velocities whose `w` is the
/// inverse mass, 0 only for a pinned particle (the shader's pin mask; a free particle's is
/// kept within f32's normal range, so it never reads as pinned).
fn fill_state(packed: &Packed, pos: &mut Vec<Position>, vel: &mut Vec<[f32; 4]>) {
    pos.clear();
    pos.extend(packed.x.iter().map(|&x| Position::from_f64(x)));
    vel.clear();
    vel.extend(packed.v.iter().zip(&packed.inv_mass).map(|(v, &im)| {
        let v = v.as_vec3();
        let w = if im == 0.0 {
            0.0
        } else {
            (im as f32).clamp(f32::MIN_POSITIVE, f32::MAX)
        };
        [v.x, v.y, v.z, w]
    }));
}

/// What the grids add on the device for step `h`: the closed form's fixes (none under Euler),
/// and the coefficients after the packed springs': each fix's own closed form, each fix's
/// nominal force, then the grids' links (`grid_pass`'s).
fn grid_device(packed: &Packed, h: f64, harmonic: bool) -> (Vec<grid::Fix>, Vec<Coef>) {
    let (mut fixes, mut links) = (Vec::new(), Vec::new());
    for g in &packed.grids {
        let lin = if harmonic {
            let (lin, f) = grid::harmonic_grid(g, &packed.inv_mass, h);
            fixes.extend(f);
            lin
        } else {
            g.links
                .iter()
                .map(|l| grid::link_coefficients(l, h))
                .collect()
        };
        links.extend(g.links.iter().zip(lin).map(|(l, c)| Coef {
            rest: l.rest_length as f32,
            p: c.p as f32,
            q: c.q as f32,
            wa: 0.0,
        }));
    }
    let own = fixes.iter().map(|f| Coef {
        rest: f.rest as f32,
        p: f.own.p as f32,
        q: f.own.q as f32,
        wa: f.wa as f32,
    });
    let nominal = fixes.iter().map(|f| Coef {
        rest: f.rest as f32,
        p: f.nominal.p as f32,
        q: f.nominal.q as f32,
        wa: 0.0,
    });
    let coefs = own.chain(nominal).chain(links).collect();
    (fixes, coefs)
}

/// The particles' lists of device springs (CSR): each packed spring's entry (`−wa` at end a,
/// `+wb` at b, of `φ n`), then the fixes' at free ends: `∓w` of their own `φ n` and `±1/m` of
/// the nominal force, which cancels what `grid_pass` applied (the CPU's `Fix::dv`).
fn incidence(
    packed: &Packed,
    device_index: &[u32],
    fixes: &[grid::Fix],
    first_fix: usize,
) -> (Vec<u32>, Vec<Entry>) {
    let inc = &packed.incidence;
    let n = packed.particle_count();
    let mut extra: Vec<Vec<Entry>> = vec![Vec::new(); if fixes.is_empty() { 0 } else { n }];
    for (j, f) in fixes.iter().enumerate() {
        let (own, nominal) = ((first_fix + j) as u32, (first_fix + fixes.len() + j) as u32);
        for (i, w, im, sign) in [(f.a, f.wa, f.ia, -1.0), (f.b, f.wb, f.ib, 1.0)] {
            if im != 0.0 {
                extra[i].push(Entry {
                    spring: own,
                    coef: (sign * w) as f32,
                });
                extra[i].push(Entry {
                    spring: nominal,
                    coef: (-sign * im) as f32,
                });
            }
        }
    }
    let mut offsets = Vec::with_capacity(n + 1);
    let mut entries = Vec::with_capacity(inc.spring.len() + 4 * fixes.len());
    for i in 0..n {
        offsets.push(entries.len() as u32);
        let (lo, hi) = match inc.offsets.get(i..i + 2) {
            Some(&[lo, hi]) => (lo as usize, hi as usize),
            _ => (0, 0),
        };
        entries.extend((lo..hi).map(|e| Entry {
            spring: device_index[inc.spring[e] as usize],
            coef: inc.coef[e] as f32,
        }));
        if let Some(x) = extra.get(i) {
            entries.extend_from_slice(x);
        }
    }
    offsets.push(entries.len() as u32);
    (offsets, entries)
}

/// `len` bytes of f32 NaN.
fn poison(len: usize) -> Vec<u8> {
    f32::NAN
        .to_le_bytes()
        .iter()
        .copied()
        .cycle()
        .take(len)
        .collect()
}

/// One invocation per element, over a 2-D grid of workgroups when one dimension is not enough.
fn dispatch(pass: &mut wgpu::ComputePass<'_>, count: u32) {
    if count == 0 {
        return;
    }
    let groups = count.div_ceil(WORKGROUP);
    let x = groups.min(MAX_GROUPS);
    pass.dispatch_workgroups(x, groups.div_ceil(x), 1);
}
