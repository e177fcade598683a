//! Air on the device (`shaders/air.wgsl`), the twin of the CPU's air (`src/air.rs`:
//! `triangle_force` and the wind field): once a frame, at the start of its first submit, one
//! pass writes a third of each triangle's drag and lift and a second sums each particle's
//! thirds in triangle order and adds their `F/m` to the host's acceleration (gravity and the
//! game's forces) for the integrate kernels. The sums come back with the state, where the host
//! books their work as it does the CPU's air: no round trip of its own.

use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use super::GpuContext;
use crate::error::GpuError;

/// The WGSL source of the air's passes: the prelude ([`super::PRELUDE`]), then
/// `shaders/air.wgsl`.
pub const SHADER: &str = concat!(
    include_str!("../../shaders/prelude.wgsl"),
    include_str!("../../shaders/air.wgsl")
);

/// `AirFrame` in shaders/air.wgsl: the wind field at the frame's start (`air::Field`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct AirFrame {
    pub mean: [f32; 3],
    pub strength: f32,
    pub along: [f32; 3],
    pub phase: f32,
    pub keys: [u32; 3],
    pub cell: u32,
    pub triangles: u32,
    pub particles: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// `Tri` in shaders/air.wgsl: a triangle's corners and its cloth's coefficients.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Tri {
    pub a: u32,
    pub b: u32,
    pub c: u32,
    pub cloth: u32,
}

/// What the air's passes need of a gather (particles in packed order).
#[derive(Debug, Default)]
pub struct AirSetup {
    pub tris: Vec<Tri>,
    /// Per cloth: `¼ ρ C_d` and `¼ ρ C_l`.
    pub coefs: Vec<[f32; 2]>,
    /// Particle `i`'s triangles are `incident[first[i]..first[i + 1]]`, increasing.
    pub first: Vec<u32>,
    pub incident: Vec<u32>,
}

impl AirSetup {
    /// The setup of `cloths` (`(end of the cloth's triangles, its air)`, in order) over
    /// `triangles`, for `particles` particles. A triangle naming a particle past the last is
    /// left out, as the CPU skips it.
    pub(crate) fn new(
        triangles: &[[u32; 3]],
        cloths: &[(usize, crate::Aero)],
        particles: usize,
    ) -> Self {
        let mut s = AirSetup::default();
        let mut start = 0;
        for (cloth, &(end, aero)) in cloths.iter().enumerate() {
            s.coefs.push([
                (0.25 * aero.density * aero.drag) as f32,
                (0.25 * aero.density * aero.lift) as f32,
            ]);
            for &[a, b, c] in &triangles[start..end] {
                if [a, b, c].iter().all(|&i| (i as usize) < particles) {
                    let cloth = cloth as u32;
                    s.tris.push(Tri { a, b, c, cloth });
                }
            }
            start = end;
        }
        // Counting sort by corner, triangles in order within each particle.
        let mut count = vec![0u32; particles + 1];
        for t in &s.tris {
            for i in [t.a, t.b, t.c] {
                count[i as usize + 1] += 1;
            }
        }
        for i in 0..particles {
            count[i + 1] += count[i];
        }
        s.first = count.clone();
        s.incident = vec![0; count[particles] as usize];
        for (k, t) in s.tris.iter().enumerate() {
            for i in [t.a, t.b, t.c] {
                let at = &mut count[i as usize];
                s.incident[*at as usize] = k as u32;
                *at += 1;
            }
        }
        s
    }
}

impl AirFrame {
    /// The device form of the wind field.
    pub(crate) fn of(field: &crate::air::Field, triangles: u32, particles: u32) -> Self {
        AirFrame {
            mean: field.mean.as_vec3().to_array(),
            strength: field.strength as f32,
            along: field.along.as_vec3().to_array(),
            phase: field.phase as f32,
            keys: field.keys,
            cell: field.cell,
            triangles,
            particles,
            ..Default::default()
        }
    }
}

/// The device air of one gather: pipelines, buffers.
pub struct DeviceAir {
    triangles_pass: wgpu::ComputePipeline,
    particles_pass: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    frame: wgpu::Buffer,
    force: wgpu::Buffer,
    base: wgpu::Buffer,
    staging: wgpu::Buffer,
    triangles: u32,
    particles: u32,
    /// The frame's passes are set and not yet encoded ([`Self::begin`]).
    queued: bool,
    /// Their forces are on the device and not yet read back.
    pending: bool,
}

impl DeviceAir {
    /// Over the state buffers `pos` and `vel`, writing the frame's accelerations into `accel`
    /// (one per particle).
    pub(super) fn new(
        ctx: &GpuContext,
        [pos, vel, accel]: [&wgpu::Buffer; 3],
        setup: &AirSetup,
    ) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let particles = setup.first.len().saturating_sub(1);
        // No binding may be empty: one unread element where there is nothing.
        fn bytes<T: Pod + Default>(v: &[T]) -> Vec<u8> {
            match v {
                [] => bytemuck::bytes_of(&T::default()).to_vec(),
                v => bytemuck::cast_slice(v).to_vec(),
            }
        }
        let (tris, coefs) = (bytes(&setup.tris), bytes(&setup.coefs));
        let (first, incident) = (bytes(&setup.first), bytes(&setup.incident));
        let per_particle = (particles.max(1) * 16) as u64;
        let thirds_bytes = (setup.tris.len().max(1) * 16) as u64;
        ctx.scoped("air stage", || {
            use super::Slot::{Storage, Uniform};
            use wgpu::BufferUsages as U;
            let read = Storage { read_only: true };
            let write = Storage { read_only: false };
            let (layout, [triangles_pass, particles_pass]) = super::stage_pipelines(
                device,
                "air",
                SHADER,
                ["air_triangles", "air_particles"],
                &[
                    Uniform { dynamic: false },
                    read,
                    read,
                    read,
                    read,
                    write,
                    read,
                    read,
                    write,
                    read,
                    write,
                ],
            );
            let init = |label, bytes: &[u8], usage| super::init_buffer(device, label, bytes, usage);
            let empty = |label, size, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage,
                    mapped_at_creation: false,
                })
            };
            let frame = init(
                "air frame",
                bytemuck::bytes_of(&AirFrame::default()),
                U::UNIFORM | U::COPY_DST,
            );
            let tris = init("air triangles", &tris, U::STORAGE);
            let coefs = init("air coefficients", &coefs, U::STORAGE);
            let thirds = empty("air thirds", thirds_bytes, U::STORAGE);
            let first = init("air first", &first, U::STORAGE);
            let incident = init("air incident", &incident, U::STORAGE);
            let force = empty("air force", per_particle, U::STORAGE | U::COPY_SRC);
            let base = empty("accel without air", per_particle, U::STORAGE | U::COPY_DST);
            let staging = empty("air force staging", per_particle, U::MAP_READ | U::COPY_DST);
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("air"),
                layout: &layout,
                entries: &[
                    super::entry(0, &frame),
                    super::entry(1, pos),
                    super::entry(2, vel),
                    super::entry(3, &tris),
                    super::entry(4, &coefs),
                    super::entry(5, &thirds),
                    super::entry(6, &first),
                    super::entry(7, &incident),
                    super::entry(8, &force),
                    super::entry(9, &base),
                    super::entry(10, accel),
                ],
            });
            Self {
                triangles_pass,
                particles_pass,
                bind_group,
                frame,
                force,
                base,
                staging,
                triangles: setup.tris.len() as u32,
                particles: particles as u32,
                queued: false,
                pending: false,
            }
        })
    }

    /// The frame's accelerations without the air (gravity and the game's forces, packed order).
    pub(super) fn set_base(&self, queue: &wgpu::Queue, accel: &[[f32; 4]]) {
        queue.write_buffer(&self.base, 0, bytemuck::cast_slice(accel));
    }

    /// The frame's wind: its passes go at the start of the frame's first submit.
    pub(super) fn begin(&mut self, queue: &wgpu::Queue, field: &crate::air::Field) {
        let frame = AirFrame::of(field, self.triangles, self.particles);
        queue.write_buffer(&self.frame, 0, bytemuck::bytes_of(&frame));
        self.queued = true;
    }

    /// Encodes the frame's passes, if set and not yet encoded.
    pub(super) fn encode(&mut self, pass: &mut wgpu::ComputePass<'_>) -> bool {
        if !std::mem::take(&mut self.queued) {
            return false;
        }
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.set_pipeline(&self.triangles_pass);
        super::dispatch(pass, self.triangles);
        pass.set_pipeline(&self.particles_pass);
        super::dispatch(pass, self.particles);
        self.pending = true;
        true
    }

    /// Bytes of the forces.
    fn bytes(&self) -> u64 {
        u64::from(self.particles) * 16
    }

    /// Encodes the forces' copy for [`Self::take`], when they are pending.
    pub(super) fn copy_out(&self, encoder: &mut wgpu::CommandEncoder) {
        if self.pending && self.particles > 0 {
            encoder.copy_buffer_to_buffer(&self.force, 0, &self.staging, 0, self.bytes());
        }
    }

    /// The pending forces (N, packed order), copied by [`Self::copy_out`] in a submit made
    /// since, written over `out`; false (nothing written) when none were pending.
    pub(super) fn take(&mut self, ctx: &GpuContext, out: &mut [DVec3]) -> Result<bool, GpuError> {
        if !std::mem::take(&mut self.pending) {
            return Ok(false);
        }
        if self.particles == 0 {
            return Ok(true);
        }
        super::map_read(ctx, &self.staging, self.bytes(), |view| {
            let force: &[[f32; 4]] = bytemuck::cast_slice(view);
            for (o, f) in out.iter_mut().zip(force) {
                *o = DVec3::new(f[0].into(), f[1].into(), f[2].into());
            }
        })?;
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::air::{AirSurfaces, Gust, Wind};
    use crate::gpu::Position;
    use crate::Aero;

    /// Two cloths of a wavy 12×12 sheet, moving, in a gusting wind far into a run: the
    /// device's forces are the CPU's to f32's precision. A changed hash or coefficient moves
    /// them by the gusts' or the air's own size.
    #[test]
    fn the_device_blows_as_the_cpu_does() {
        let ctx = match GpuContext::shared(true) {
            Ok(c) => c,
            Err(e) => {
                assert!(
                    std::env::var_os("HARMONIC_REQUIRE_GPU").is_none(),
                    "HARMONIC_REQUIRE_GPU is set but no adapter: {e}"
                );
                assert_eq!(e, GpuError::NoAdapter, "only a missing adapter may skip");
                return;
            }
        };
        let n = 12usize;
        let id = |i: usize, j: usize| (i * n + j) as u32;
        let (mut x, mut v) = (Vec::new(), Vec::new());
        for i in 0..n {
            for j in 0..n {
                let (a, b) = (i as f64 / n as f64, j as f64 / n as f64);
                x.push(DVec3::new(
                    a + 3.0,
                    0.2 * (5.0 * a + 3.0 * b).sin() + 2.0,
                    b,
                ));
                v.push(DVec3::new((7.0 * b).cos(), (3.0 * a).sin(), 0.5 * a - b));
            }
        }
        let mut sheets = [Vec::new(), Vec::new()];
        for i in 0..n - 1 {
            for j in 0..n - 1 {
                let half = usize::from(j >= n / 2);
                sheets[half].push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                sheets[half].push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let mut air = AirSurfaces::default();
        let [left, right] = sheets;
        air.push(left, Aero::default());
        let lifting = Aero {
            density: 1.1,
            drag: 0.9,
            lift: 0.6,
        };
        air.push(right, lifting);
        let wind = Wind {
            velocity: [4.0, 1.0, -2.0],
            gust: Some(Gust {
                strength: 3.0,
                length: 0.4,
                period: 0.7,
                seed: 0x1234_5678_9abc,
            }),
        };
        let t = 123.4;
        let mut cpu = vec![DVec3::ZERO; x.len()];
        // The device's state, and the CPU's air on exactly what the device holds.
        let pos: Vec<Position> = x.iter().map(|&p| Position::from_f64(p)).collect();
        let vel: Vec<[f32; 4]> = v
            .iter()
            .map(|p| p.as_vec3().extend(1.0).to_array())
            .collect();
        let v32: Vec<DVec3> = vel
            .iter()
            .map(|w| DVec3::new(w[0].into(), w[1].into(), w[2].into()))
            .collect();
        let x32: Vec<DVec3> = pos.iter().map(|p| p.to_f64()).collect();
        air.forces(&x32, &v32, &wind, t, &mut cpu);
        use wgpu::BufferUsages as U;
        let device = &ctx.device;
        let init =
            |label, bytes: &[u8], usage| super::super::init_buffer(device, label, bytes, usage);
        let pos = init("pos", bytemuck::cast_slice(&pos), U::STORAGE);
        let vel = init("vel", bytemuck::cast_slice(&vel), U::STORAGE);
        let zero = vec![[0f32; 4]; x.len()];
        let accel = init(
            "accel",
            bytemuck::cast_slice(&zero),
            U::STORAGE | U::COPY_SRC,
        );
        let (triangles, cloths) = air.parts();
        let setup = AirSetup::new(triangles, cloths, x.len());
        let mut dev = DeviceAir::new(&ctx, [&pos, &vel, &accel], &setup).unwrap();
        // The host's share: gravity, and a game's force on every particle of mass 1.
        let base: Vec<[f32; 4]> = (0..x.len())
            .map(|i| [0.5, -9.81, i as f32 * 1e-3, 0.0])
            .collect();
        dev.set_base(&ctx.queue, &base);
        dev.begin(&ctx.queue, &wind.field(t));
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            assert!(dev.encode(&mut pass));
            assert!(!dev.encode(&mut pass), "once a frame");
        }
        dev.copy_out(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: (x.len() * 16) as u64,
            usage: U::MAP_READ | U::COPY_DST,
            mapped_at_creation: false,
        });
        let mut got_accel = Vec::new();
        let bytes = (x.len() * 16) as u64;
        super::super::read_staging(
            &ctx,
            "accel",
            &staging,
            bytes,
            |e| e.copy_buffer_to_buffer(&accel, 0, &staging, 0, bytes),
            |view| got_accel.extend_from_slice(bytemuck::cast_slice::<u8, [f32; 4]>(view)),
        )
        .unwrap();
        let mut gpu = vec![DVec3::ZERO; x.len()];
        assert!(dev.take(&ctx, &mut gpu).unwrap());
        assert!(!dev.take(&ctx, &mut gpu).unwrap(), "taken once");
        // The acceleration is the host's plus the air's F/m (inverse mass 1).
        for ((a, b), f) in got_accel.iter().zip(&base).zip(&gpu) {
            let want = DVec3::new(b[0].into(), b[1].into(), b[2].into()) + *f;
            let got = DVec3::new(a[0].into(), a[1].into(), a[2].into());
            assert!((got - want).length() < 1e-5, "{got} against {want}");
        }
        let scale = cpu.iter().map(|f| f.length()).fold(0.0, f64::max);
        let apart = (cpu.iter().zip(&gpu))
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f64::max);
        println!("air: largest force {scale:e} N, device against CPU {apart:e} N");
        assert!(scale > 0.05, "the test blows: {scale} N");
        assert!(apart <= 1e-5 * scale, "{apart} N apart of {scale} N");
    }
}
