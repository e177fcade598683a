//! The pass over the candidates on the device ([`crate::gpu::collide_pass`]), where the springs
//! and the search run there and every candidate is a particle against a triangle (no layer
//! asks for `edges` and every layer has triangles). The candidates go up in colours after each
//! find; the host still decides each substep whether to find again, from the places the device
//! hands back.

use glam::DVec3;

use super::CollideStage;
use crate::buffers::Packed;
use crate::error::GpuError;
use crate::gpu::collide_pass::{Contact, DevicePass};

/// The device's pass of one gather, and the host's scratch for it.
#[derive(Debug)]
pub(super) struct OnDevicePass {
    pass: DevicePass,
    contacts: Vec<Contact>,
    start: Vec<[f32; 4]>,
    /// Whether the device holds the start places (from a frame's start on).
    started: bool,
}

impl CollideStage {
    /// Whether the device can run the pass: every candidate a particle against a triangle.
    pub(crate) fn pass_fits_device(&self) -> bool {
        !self.triangles.is_empty()
            && self.surfaced.iter().all(|&s| s)
            && !self.layers.iter().any(|l| l.edges)
    }

    /// The pass on the device from now on (until the next gather), over `pass`'s buffers: in
    /// colours, the device's order.
    pub(crate) fn enable_device_pass(&mut self, pass: DevicePass) {
        self.coloured = true;
        self.device.pass = Some(OnDevicePass {
            pass,
            contacts: Vec::new(),
            start: Vec::new(),
            started: false,
        });
    }

    /// After a find: the candidates up, in colour order.
    pub(super) fn upload_pass(&mut self) -> Result<(), GpuError> {
        let Some(d) = self.device.pass.as_mut() else {
            return Ok(());
        };
        d.contacts.clear();
        d.contacts.extend(self.colours.order.iter().map(|&k| {
            let f = &self.faces[k as usize];
            let [a, b, c] = self.triangles[f.triangle as usize].at;
            let (mu, mu_s) = f.friction;
            Contact {
                p: f.p,
                a,
                b,
                c,
                thickness: f.thickness as f32,
                mu: mu as f32,
                mu_s: mu_s as f32,
                _pad: 0.0,
            }
        }));
        d.pass.set_contacts(&d.contacts, &self.colours.at)
    }

    /// The substep's start places up (a frame's start, after the host set them).
    pub(super) fn start_to_device(&mut self) {
        let Some(d) = self.device.pass.as_mut() else {
            return;
        };
        d.start.clear();
        (d.start).extend(
            self.start
                .iter()
                .map(|x| [x.x as f32, x.y as f32, x.z as f32, 0.0]),
        );
        d.pass.set_start(&d.start);
        d.started = true;
    }

    /// The places the device's last pass kept as the next substep's start (before a frame's
    /// start, and before a gather drops the pass: the game's edits are swept from there).
    pub(crate) fn start_from_device(&mut self) -> Result<(), GpuError> {
        let Some(d) = self.device.pass.as_mut().filter(|d| d.started) else {
            return Ok(());
        };
        d.pass.read_start(&mut d.start)?;
        for (s, x) in self.start.iter_mut().zip(&d.start) {
            *s = DVec3::new(x[0].into(), x[1].into(), x[2].into());
        }
        Ok(())
    }

    /// A substep's pass on the device: `packed` holds the places after its springs; the
    /// candidates found again first where some pair may have closed past the margin.
    pub(crate) fn project_on_device(&mut self, packed: &Packed) -> Result<(), GpuError> {
        self.start_from_device()?;
        self.refresh(packed)?;
        match &self.device.pass {
            Some(d) => d.pass.run(),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collide::device::tests::{context, crumpled};
    use crate::gpu::Position;

    /// The device's pass against the CPU's in the same colours, from one state: two crumpled
    /// sheets moving into each other, some of their particles swept through the other's
    /// triangles over the substep. Both push the same particles by the same amounts to f32's
    /// rounding; on the device one workgroup and a dispatch per colour give the same bits, and
    /// so do two runs.
    #[test]
    fn the_device_passes_as_the_cpu_does() {
        let Some(ctx) = context() else { return };
        let (mut stage, mut packed) = crumpled();
        let n = packed.x.len();
        let mut r = super::super::uniform(5);
        // Each particle came over the substep from 2 mm off, and moves at up to 1 m/s.
        packed.v = (0..n).map(|_| DVec3::new(r(), r(), r())).collect();
        stage.start = (packed.x.iter())
            .map(|&x| x - DVec3::new(r(), r(), r()) * 0.002)
            .collect();
        stage.moves.reset(n);
        stage.before_v.resize(n, DVec3::ZERO);
        stage.coloured = true;
        stage.find_faces(&packed).unwrap();
        stage.colour(n);
        let before = packed.clone();
        let gravity = DVec3::new(0.0, -9.81, 0.0);
        assert!(stage.pass(&mut packed, gravity));
        let (cpu_x, cpu_v) = (packed.x.clone(), packed.v.clone());

        let device = |stage: &mut CollideStage, one_group: bool| -> (Vec<DVec3>, Vec<DVec3>) {
            use wgpu::BufferUsages as U;
            let pos: Vec<Position> = before.x.iter().map(|&x| Position::from_f64(x)).collect();
            let vel: Vec<[f32; 4]> = (before.v.iter().zip(&before.inv_mass))
                .map(|(v, &w)| [v.x as f32, v.y as f32, v.z as f32, w as f32])
                .collect();
            let usage = U::STORAGE | U::COPY_SRC;
            let init =
                |label, bytes: &[u8]| crate::gpu::init_buffer(&ctx.device, label, bytes, usage);
            let (pos_buf, vel_buf) = (
                init("test pos", bytemuck::cast_slice(&pos)),
                init("test vel", bytemuck::cast_slice(&vel)),
            );
            let mut pass = DevicePass::new(ctx.clone(), &pos_buf, &vel_buf, n as u32, 3).unwrap();
            pass.set_form(Some(one_group));
            stage.enable_device_pass(pass);
            stage.upload_pass().unwrap();
            stage.start_to_device();
            stage.device.pass.as_ref().unwrap().pass.run().unwrap();
            let read = |b: &wgpu::Buffer, bytes: usize| -> Vec<u8> {
                let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("test staging"),
                    size: bytes as u64,
                    usage: U::MAP_READ | U::COPY_DST,
                    mapped_at_creation: false,
                });
                let mut out = Vec::new();
                crate::gpu::read_staging(
                    &ctx,
                    "test read",
                    &staging,
                    bytes as u64,
                    |e| e.copy_buffer_to_buffer(b, 0, &staging, 0, bytes as u64),
                    |b| out.extend_from_slice(b),
                )
                .unwrap();
                out
            };
            let pos = read(&pos_buf, n * 32);
            let vel = read(&vel_buf, n * 16);
            let pos: &[Position] = bytemuck::cast_slice(&pos);
            let vel: &[[f32; 4]] = bytemuck::cast_slice(&vel);
            (
                pos.iter().map(|p| p.to_f64()).collect(),
                (vel.iter())
                    .map(|v| DVec3::new(v[0].into(), v[1].into(), v[2].into()))
                    .collect(),
            )
        };
        let (x, v) = device(&mut stage, false);
        let moved = (0..n)
            .filter(|&i| (cpu_x[i] - before.x[i]).length() > 1e-9)
            .count();
        let (mut dx, mut dv, mut most) = (0.0f64, 0.0f64, 0.0f64);
        for i in (0..n).filter(|&i| before.x[i].is_finite()) {
            dx = dx.max((x[i] - cpu_x[i]).length());
            dv = dv.max((v[i] - cpu_v[i]).length());
            most = most.max((cpu_x[i] - before.x[i]).length());
        }
        println!(
            "{} candidates in {} colours; {moved} particles moved, at most {most:.2e} m; \
             device against CPU: places within {dx:.2e} m, velocities within {dv:.2e} m/s",
            stage.faces.len(),
            stage.colours.colours()
        );
        assert!(moved > 500 && most > 1e-3, "{moved} moved, at most {most}");
        assert!(stage.colours.colours() > 8);
        assert!(dx < 3e-5, "places {dx} m apart");
        assert!(dv < 2e-3, "velocities {dv} m/s apart");
        let bits = |x: &[DVec3]| -> Vec<[u64; 3]> {
            x.iter().map(|p| p.to_array().map(f64::to_bits)).collect()
        };
        let one = device(&mut stage, true);
        assert!(
            bits(&one.0) == bits(&x) && bits(&one.1) == bits(&v),
            "the two forms differ"
        );
        let again = device(&mut stage, false);
        assert!(bits(&again.0) == bits(&x), "two runs on the device differ");
    }
}
