//! The kernels, their specialisation to a scene (override constants) and the compiled pipelines.

use super::*;

/// How the kernels step: which entry points run, in which order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// `spring_pass`, `grid_pass` per cloth grid kept whole, then `particle_pass` (harmonic,
    /// symplectic and explicit Euler).
    Jacobi,
    /// `add_gravity`, one sweep over the colours, `drift`.
    GaussSeidel,
}

impl Kernel {
    /// The GPU kernel of an integrator, if it has one.
    pub fn of(integrator: Integrator, exact_displacement: bool) -> Option<Kernel> {
        match integrator {
            Integrator::Harmonic if exact_displacement => None,
            Integrator::Harmonic | Integrator::SymplecticEuler | Integrator::ExplicitEuler => {
                Some(Kernel::Jacobi)
            }
            Integrator::HarmonicGs => Some(Kernel::GaussSeidel),
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
    /// A force stage is listed: the external acceleration is read per particle.
    pub forces: bool,
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
                || packed
                    .topology
                    .grids
                    .iter()
                    .flat_map(|g| &g.links)
                    .any(|l| {
                        // The closed form responds to δ̇ even undamped (q = cos ωh − 1).
                        integrator == Integrator::Harmonic || grid::link_coefficients(l, h).q != 0.0
                    }),
            pins: packed.inv_mass.contains(&0.0),
            update: u32::from(integrator == Integrator::ExplicitEuler),
            grids: !packed.topology.grids.is_empty(),
            forces: false,
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

    pub(super) fn constants(&self) -> [(&'static str, f64); 6] {
        [
            ("WORKGROUP", WORKGROUP as f64),
            ("RATE", f64::from(u8::from(self.rate))),
            ("PINS", f64::from(u8::from(self.pins))),
            ("UPDATE", self.update as f64),
            ("GRIDS", f64::from(u8::from(self.grids))),
            ("FORCES", f64::from(u8::from(self.forces))),
        ]
    }
}

/// The compute pipelines of one specialisation.
pub(super) struct Pipelines {
    pub(super) spec: Specialisation,
    pub(super) spring_pass: wgpu::ComputePipeline,
    pub(super) grid_pass: wgpu::ComputePipeline,
    pub(super) particle_pass: wgpu::ComputePipeline,
    pub(super) add_gravity: wgpu::ComputePipeline,
    pub(super) sweep_colour: wgpu::ComputePipeline,
    pub(super) drift: wgpu::ComputePipeline,
}

impl GpuSolver {
    pub(super) fn pipelines(&self, spec: Specialisation) -> Result<Pipelines, GpuError> {
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
}
