//! `harmonic-lab bench --backend gpu`: GPU substeps per second against cloth size, beside the CPU
//! kernel in the same run, with the bytes each substep moves against the device's measured copy
//! bandwidth (the memory-bound floor); and what each shader specialisation buys.

use std::fmt::Write;
use std::time::{Duration, Instant};

use harmonic::hecs::{Entity, World};

use harmonic::internals::buffers::Packed;
use harmonic::internals::gpu::GpuContext;
use harmonic::internals::hanging_cloth;
use harmonic::internals::integrate::Integrator;
use harmonic::scene::Scene;
use harmonic::Backend;
use harmonic::SimError;
use harmonic::{ClothSprings, Spring};
use harmonic::{SimConfig, Simulation};

/// Timed work per measurement (the substep count grows until a run takes this long).
const TARGET: Duration = Duration::from_millis(400);

/// One size of the scaling table.
pub struct ScalingRow {
    pub n: u32,
    pub particles: usize,
    pub springs: usize,
    pub gpu_substeps_per_s: f64,
    pub cpu_substeps_per_s: Option<f64>,
    pub bytes_per_substep: u64,
    /// For an integrator with a grid pass: the GPU with the cloth's springs spawned one by one
    /// instead (substeps/s, bytes/substep).
    pub one_by_one: Option<(f64, u64)>,
}

/// A simulation of `scene` at the step automatic control picks for its frame step, then fixed
/// at one substep per frame (the bench drives the substeps itself).
fn simulation(
    scene: &Scene,
    integrator: Integrator,
    backend: Backend,
) -> Result<Simulation, SimError> {
    simulation_of(scene, Ok, integrator, backend)
}

/// As [`simulation`], with the built World passed through `edit` first.
fn simulation_of(
    scene: &Scene,
    edit: impl FnOnce(World) -> Result<World, SimError>,
    integrator: Integrator,
    backend: Backend,
) -> Result<Simulation, SimError> {
    let built = scene.build();
    let mut sim = Simulation::new(
        edit(built.world)?,
        SimConfig {
            integrator,
            backend,
            auto_substeps: true,
            ..built.config
        },
    )?;
    let config = SimConfig {
        dt: sim.config().h(),
        substeps: 1,
        auto_substeps: false,
        ..*sim.config()
    };
    sim.set_config(config)?;
    Ok(sim)
}

/// The World with every cloth's springs spawned one by one as [`Spring`]s: how the GPU stepped a
/// cloth before it had a grid pass, for the comparison column.
fn springs_one_by_one(mut world: World) -> Result<World, SimError> {
    let packed = Packed::gather(&world)?;
    // Packed springs: the World's own first, then the cloths' expanded.
    let own = world.query::<&Spring>().iter().count();
    let cloths: Vec<Entity> = world
        .query::<(Entity, &ClothSprings)>()
        .iter()
        .map(|(e, _)| e)
        .collect();
    for e in cloths {
        let _ = world.despawn(e);
    }
    let e = &packed.topology.entities;
    for s in &packed.springs[own..] {
        world.spawn((Spring {
            a: e[s.a as usize],
            b: e[s.b as usize],
            rest_length: s.rest,
            stiffness: s.stiffness,
            damping: s.damping,
        },));
    }
    Ok(world)
}

/// Median substeps per second of `run(k)` over `repeats`, with `k` grown to fill [`TARGET`].
fn rate(repeats: u32, mut run: impl FnMut(u32) -> Result<(), SimError>) -> Result<f64, SimError> {
    run(2)?;
    let mut k = 2u32;
    loop {
        let t = Instant::now();
        run(k)?;
        let e = t.elapsed();
        if e >= TARGET / 4 || k >= 1 << 20 {
            let per = e.as_secs_f64() / k as f64;
            k = ((TARGET.as_secs_f64() / per) as u32).clamp(1, 1 << 20);
            break;
        }
        k *= 4;
    }
    let mut samples = Vec::new();
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        run(k)?;
        samples.push(k as f64 / t.elapsed().as_secs_f64());
    }
    samples.sort_by(f64::total_cmp);
    Ok(samples[samples.len() / 2])
}

/// GPU substeps per second of a scene (state resident, one submit per batch, waited for).
fn gpu_rate(sim: &mut Simulation, repeats: u32) -> Result<(f64, u64), SimError> {
    let solver = sim.gpu_solver().ok_or(harmonic::GpuError::NoAdapter)?;
    let bytes = solver.bytes_per_substep();
    let r = rate(repeats, |k| {
        solver.run(k)?;
        solver.finish()?;
        Ok(())
    })?;
    Ok((r, bytes))
}

/// The device's copy bandwidth (bytes read + written per second), from buffer-to-buffer copies.
pub fn copy_bandwidth(ctx: &GpuContext) -> f64 {
    let size: u64 = (256 << 20).min(ctx.limits.max_buffer_size / 2);
    let make = |usage| {
        ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("bandwidth"),
            size,
            usage,
            mapped_at_creation: false,
        })
    };
    let src = make(wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST);
    let dst = make(wgpu::BufferUsages::COPY_DST);
    let copy = |times: u32| {
        let mut enc = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        for _ in 0..times {
            enc.copy_buffer_to_buffer(&src, 0, &dst, 0, size);
        }
        ctx.queue.submit([enc.finish()]);
        let _ = ctx.device.poll(wgpu::PollType::wait_indefinitely());
    };
    copy(2);
    let mut best = 0.0f64;
    for _ in 0..3 {
        let t = Instant::now();
        copy(8);
        best = best.max(2.0 * size as f64 * 8.0 / t.elapsed().as_secs_f64());
    }
    best
}

/// The scaling table: each `n`×`n` hanging cloth on the GPU, and on the CPU up to `cpu_max`.
pub fn scaling(
    sizes: &[u32],
    integrator: Integrator,
    repeats: u32,
    cpu_max: u32,
    mut progress: impl FnMut(&str),
) -> Result<Vec<ScalingRow>, SimError> {
    let mut rows = Vec::new();
    for &n in sizes {
        progress(&format!("{n}×{n} GPU"));
        let scene = hanging_cloth(n);
        let mut sim = simulation(&scene, integrator, Backend::Gpu)?;
        let (gpu, bytes) = gpu_rate(&mut sim, repeats)?;
        // A frame with the read back: the state after the timed substeps must be finite.
        sim.step()?;
        let (particles, springs) = (sim.packed().particle_count(), sim.packed().spring_count());
        drop(sim);
        let one_by_one = if integrator.runs_on_gpu_grids() {
            progress(&format!("{n}×{n} GPU, springs one by one"));
            let mut sim = simulation_of(&scene, springs_one_by_one, integrator, Backend::Gpu)?;
            let r = gpu_rate(&mut sim, repeats)?;
            sim.step()?;
            Some(r)
        } else {
            None
        };
        let cpu = if n <= cpu_max {
            progress(&format!("{n}×{n} CPU"));
            let mut cpu = simulation(&scene, integrator, Backend::Cpu)?;
            let mut config = *cpu.config();
            let h = config.h();
            Some(rate(repeats, |k| {
                config.substeps = k;
                config.dt = h * k as f64;
                cpu.set_config(config)?;
                cpu.step().map(|_| ())
            })?)
        } else {
            None
        };
        rows.push(ScalingRow {
            n,
            particles,
            springs,
            gpu_substeps_per_s: gpu,
            cpu_substeps_per_s: cpu,
            bytes_per_substep: bytes,
            one_by_one,
        });
    }
    Ok(rows)
}

/// What the shader specialisations buy on an `n`×`n` cloth: four scene variants (damped or
/// not, pinned or free), each with the specialised and the general kernel.
pub fn specialisations(
    n: u32,
    integrator: Integrator,
    repeats: u32,
) -> Result<Vec<(String, String, f64, f64)>, SimError> {
    let mut out = Vec::new();
    for (damped, pinned) in [(true, true), (false, true), (true, false), (false, false)] {
        let mut scene = hanging_cloth(n);
        let cloth = &mut scene.cloths[0];
        if !damped {
            for s in [
                Some(&mut cloth.structural),
                cloth.shear.as_mut(),
                cloth.bend.as_mut(),
            ]
            .into_iter()
            .flatten()
            {
                s.damping = Some(0.0);
            }
        }
        if !pinned {
            cloth.pins.clear();
        }
        let label = format!(
            "{}, {}",
            if damped { "damped" } else { "undamped" },
            if pinned { "pinned" } else { "free" }
        );
        let mut rates = [0.0; 2];
        let mut spec = String::new();
        for (slot, specialise) in [(0, true), (1, false)] {
            let mut sim = simulation(&scene, integrator, Backend::Gpu)?;
            let solver = sim.gpu_solver().ok_or(harmonic::GpuError::NoAdapter)?;
            if !specialise {
                solver.specialise = false;
                sim.world_mut();
                sim.step()?;
            }
            let solver = sim.gpu_solver().ok_or(harmonic::GpuError::NoAdapter)?;
            if specialise {
                spec = solver
                    .specialisation()
                    .map(|s| format!("rate {}, pins {}", s.rate, s.pins))
                    .unwrap_or_default();
            }
            rates[slot] = gpu_rate(&mut sim, repeats)?.0;
            sim.step()?;
        }
        out.push((label, spec, rates[0], rates[1]));
    }
    Ok(out)
}

/// The whole GPU bench as Markdown.
pub fn report(
    sizes: &[u32],
    integrator: Integrator,
    repeats: u32,
    cpu_max: u32,
    mut progress: impl FnMut(&str),
) -> Result<String, SimError> {
    let ctx = GpuContext::shared(true)?;
    progress("copy bandwidth");
    let bandwidth = copy_bandwidth(&ctx);
    let rows = scaling(sizes, integrator, repeats, cpu_max, &mut progress)?;
    let spec_n = sizes
        .iter()
        .copied()
        .find(|&n| n >= 256)
        .unwrap_or(sizes[0]);
    progress("specialisations");
    let specs = specialisations(spec_n, integrator, repeats)?;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "GPU: {} — measured copy bandwidth {:.1} GB/s (read + write). CPU: {} rayon threads, f64.\n\
         Integrator {integrator}; hanging cloth (structural, shear, bend; two corners pinned); \
         median of {repeats}.\n",
        ctx.describe(),
        bandwidth / 1e9,
        rayon::current_num_threads()
    );
    let _ = writeln!(
        md,
        "| cloth | particles | springs | GPU substeps/s | GPU M spring-substeps/s | bytes/substep | floor substeps/s | GPU / floor | CPU substeps/s | GPU / CPU | GPU, springs one by one: substeps/s (bytes/substep) | grid / one by one |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        let floor = bandwidth / r.bytes_per_substep as f64;
        let (cpu, ratio) = match r.cpu_substeps_per_s {
            Some(c) => (
                format!("{c:.0}"),
                format!("{:.2}×", r.gpu_substeps_per_s / c),
            ),
            None => ("-".into(), "-".into()),
        };
        let (one, gain) = match r.one_by_one {
            Some((rate, bytes)) => (
                format!("{rate:.0} ({:.1} MB)", bytes as f64 / 1e6),
                format!("{:.2}×", r.gpu_substeps_per_s / rate),
            ),
            None => ("-".into(), "-".into()),
        };
        let _ = writeln!(
            md,
            "| {n}² | {} | {} | {:.0} | {:.1} | {:.1} MB | {floor:.0} | {:.2} | {cpu} | {ratio} | {one} | {gain} |",
            r.particles,
            r.springs,
            r.gpu_substeps_per_s,
            r.gpu_substeps_per_s * r.springs as f64 / 1e6,
            r.bytes_per_substep as f64 / 1e6,
            r.gpu_substeps_per_s / floor,
            n = r.n,
        );
    }
    let _ = writeln!(
        md,
        "\nSpecialisation on the {spec_n}² cloth (GPU substeps/s; general = every term in):\n\n\
         | scene | specialised to | specialised | general | gain |\n|---|---|---|---|---|"
    );
    for (label, spec, s, g) in &specs {
        let _ = writeln!(md, "| {label} | {spec} | {s:.0} | {g:.0} | {:.2}× |", s / g);
    }
    Ok(md)
}
