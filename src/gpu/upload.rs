//! The gather's upload: the state, the springs in colour order, the grids' links and the CSR incidence.

use super::*;

/// Device buffers of one topology.
pub(super) struct Buffers {
    pub(super) params: wgpu::Buffer,
    pub(super) pos: wgpu::Buffer,
    pub(super) vel: wgpu::Buffer,
    pub(super) coefs: wgpu::Buffer,
    pub(super) sdv: wgpu::Buffer,
    pub(super) staging: wgpu::Buffer,
    /// The external accelerations (one per particle with forces; one element without).
    pub(super) accel: wgpu::Buffer,
    pub(super) bind_group: wgpu::BindGroup,
    /// Colour ranges (start, count), in sweep order.
    pub(super) colours: Vec<(u32, u32)>,
    /// Each cloth grid's particles (first, count); their `Range`s follow the colours' in the
    /// uniform.
    pub(super) grids: Vec<(u32, u32)>,
    /// Dynamic-offset stride of the colour uniform.
    pub(super) colour_stride: u32,
    pub(super) particles: u32,
    pub(super) springs_len: u32,
}

/// Binding `binding` to the whole of `buffer`.
pub(super) fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// The device form of the state: compensated positions, and velocities whose `w` is the
/// inverse mass, 0 only for a pinned particle (the shader's pin mask; a free particle's is
/// kept within f32's normal range, so it never reads as pinned).
pub(super) fn fill_state(packed: &Packed, pos: &mut Vec<Position>, vel: &mut Vec<[f32; 4]>) {
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
pub(super) fn grid_device(packed: &Packed, h: f64, harmonic: bool) -> (Vec<grid::Fix>, Vec<Coef>) {
    let (mut fixes, mut links) = (Vec::new(), Vec::new());
    for g in &packed.topology.grids {
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
pub(super) fn incidence(
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

impl GpuSolver {
    /// Gather: uploads state and topology, with coefficients `lin` (per packed spring) for step
    /// `h`, and builds the pipelines if the scene needs another specialisation (`forces`: the
    /// schedule lists a force stage, whose accelerations [`Self::set_accel`] sets each frame).
    pub fn upload(
        &mut self,
        packed: &Packed,
        lin: &[Linear],
        (gravity, forces): (DVec3, bool),
        h: f64,
        integrator: Integrator,
    ) -> Result<(), GpuError> {
        self.contacts = None;
        self.tethers = None;
        self.air = None;
        if !packed.topology.grids.is_empty() && !integrator.runs_on_gpu_grids() {
            return Err(GpuError::Device {
                adapter: self.ctx.describe(),
                what: format!("{integrator} does not step cloth grids kept whole"),
            });
        }
        let mut spec = Specialisation {
            forces,
            ..Specialisation::of(packed, lin, h, integrator)
        };
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
                    .topology
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
        let (mut links, mut grids) = (0, Vec::with_capacity(packed.topology.grids.len()));
        for g in &packed.topology.grids {
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
        let sdv_len = springs_len
            + if packed.topology.grids.is_empty() {
                0
            } else {
                n
            };
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
            // Only with forces: per particle (n at most u32 range, so the size fits).
            let accel = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("accel"),
                size: if forces { 16 * n.max(1) as u64 } else { 16 },
                usage: U::STORAGE | U::COPY_DST,
                mapped_at_creation: false,
            });
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
                    entry(9, &accel),
                ],
            });
            Buffers {
                params,
                pos,
                vel,
                coefs,
                sdv,
                staging,
                accel,
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
}
