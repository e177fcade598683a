//! The candidates against triangles found on the device ([`crate::gpu::collide`]) where the
//! springs run there. The device's lists hold the CPU's candidates (its tests add a slack that
//! covers f32's rounding); each is tested again here with the CPU's own test in f64 and put in
//! the CPU's order (members by cell, each member's triangles by cell then index), so both back
//! ends hand the pass the same candidates, and the device finds them without the host's search.

use std::sync::Arc;

use super::edges::Crossing;
use super::search::key;
use super::{CollideStage, Face};
use crate::buffers::Packed;
use crate::error::GpuError;
use crate::gpu::collide::{DeviceFind, FindSetup, FindShape, Search, HELD, NONE, OUT};
use crate::gpu::GpuContext;

/// The device's find of one gather, and the host's scratch for it.
#[derive(Debug, Default)]
pub(super) struct OnDevice {
    pub(super) find: Option<DeviceFind>,
    /// Edges against edges, where a layer asks for them.
    pub(super) edges: Option<DeviceFind>,
    /// The pass over the candidates, where every candidate is a particle against a triangle.
    pub(super) pass: Option<super::device_pass::OnDevicePass>,
    points: Vec<[f32; 4]>,
    flags: Vec<u32>,
    at: Vec<u32>,
    list: Vec<u32>,
    order: Vec<(u64, Face)>,
    pairs: Vec<(Ordered, Ordered, Crossing)>,
}

/// An edge's place in the CPU's order: its midpoint's cell key, then its index.
type Ordered = (u64, u32);

impl CollideStage {
    /// The candidates against triangles found on the device from now on, until the next
    /// gather.
    pub(crate) fn enable_device(&mut self, ctx: Arc<GpuContext>) -> Result<(), GpuError> {
        (self.device.find, self.device.edges) = (None, None);
        if self.triangles.is_empty() {
            return Ok(());
        }
        let layers: Vec<u32> = self.members.iter().map(|m| u32::from(m.1)).collect();
        let thickness: Vec<f32> = self.layers.iter().map(|l| l.thickness as f32).collect();
        let setup = FindSetup {
            search: Search::Faces,
            layers: layers.clone(),
            tris: (self.triangles.iter())
                .map(|t| [t.slots[0], t.slots[1], t.slots[2], u32::from(t.layer)])
                .collect(),
            excluded_at: self.excluded.at.clone(),
            excluded: self.excluded.list.clone(),
            thickness: thickness.clone(),
        };
        self.device.find = Some(DeviceFind::new(ctx.clone(), &setup)?);
        if !self.edges.is_empty() {
            let setup = FindSetup {
                search: Search::Edges,
                layers,
                tris: (self.edges.iter())
                    .map(|e| [e.slots[0], e.slots[1], NONE, u32::from(e.layer)])
                    .collect(),
                excluded_at: self.edge_excluded.at.clone(),
                excluded: self.edge_excluded.list.clone(),
                thickness,
            };
            self.device.edges = Some(DeviceFind::new(ctx, &setup)?);
        }
        Ok(())
    }

    /// `find_faces` with the search on the device: `cell` the CPU's cells' side, the centres
    /// and the members' keys (not yet sorted) made.
    pub(super) fn faces_on_device(&mut self, packed: &Packed, cell: f64) -> Result<(), GpuError> {
        let mut d = std::mem::take(&mut self.device);
        let found = self.search_on_device(&mut d, Search::Faces, packed, cell);
        if found.is_ok() {
            self.order_from_device(&mut d, packed, cell);
        }
        self.device = d;
        found
    }

    /// `find_crossings` with the search on the device: `cell` the CPU's cells' side, the
    /// midpoints and their keys (sorted) made.
    pub(super) fn crossings_on_device(
        &mut self,
        packed: &Packed,
        cell: f64,
    ) -> Result<(), GpuError> {
        let mut d = std::mem::take(&mut self.device);
        let found = self.search_on_device(&mut d, Search::Edges, packed, cell);
        if found.is_ok() {
            self.crossings_from_device(&mut d, packed, cell);
        }
        self.device = d;
        found
    }

    fn search_on_device(
        &self,
        d: &mut OnDevice,
        search: Search,
        packed: &Packed,
        cell: f64,
    ) -> Result<(), GpuError> {
        let (x, inv) = (&packed.x, &packed.inv_mass);
        d.points.clear();
        d.flags.clear();
        let mut scale = 0.0f64;
        for (m, &swept) in self.members.iter().zip(&self.swept) {
            let p = x[m.0 as usize];
            let finite = p.is_finite();
            if finite {
                scale = scale.max(p.abs().max_element());
            }
            d.points
                .push([p.x as f32, p.y as f32, p.z as f32, swept as f32]);
            let held = if inv[m.0 as usize] == 0.0 { HELD } else { 0 };
            d.flags.push(held | if finite { 0 } else { OUT });
        }
        let reach_max = self.thickest() + self.reach;
        // Well over f32's rounding of the coordinates (up to `scale`), of the reach and of the
        // triangles' radii, so the device's lists hold every pair the CPU's test passes.
        let slack = 1e-4 * cell + 64.0 * f64::from(f32::EPSILON) * scale;
        let shape = FindShape {
            cell: ((cell + 2.0 * slack) * (1.0 + 1e-4)) as f32,
            reach_max: reach_max as f32,
            slack: slack as f32,
            margin: self.margin as f32,
        };
        let find = match search {
            Search::Faces => d.find.as_mut(),
            Search::Edges => d.edges.as_mut(),
        };
        match find {
            Some(find) => find.find(shape, &d.points, &d.flags, &mut d.at, &mut d.list),
            None => Ok(()),
        }
    }

    /// The device's lists tested again with the CPU's test and in the CPU's order.
    fn order_from_device(&mut self, d: &mut OnDevice, packed: &Packed, cell: f64) {
        let (x, inv) = (&packed.x, &packed.inv_mass);
        use rayon::prelude::*;
        self.cells.par_sort_unstable();
        let reach_max = self.thickest() + self.reach;
        for &(_, s) in &self.cells {
            let (p, lp, _) = self.members[s as usize];
            let xp = x[p as usize];
            d.order.clear();
            let at = d.at[s as usize] as usize..d.at[s as usize + 1] as usize;
            for &k in &d.list[at] {
                let (m, r) = self.centres[k as usize];
                let widest = reach_max + r;
                let layer = self.triangles[k as usize].layer;
                if !r.is_finite()
                    || (xp - m).length_squared() >= widest * widest
                    || (layer == lp && self.excluded.contains(s, k))
                {
                    continue;
                }
                if let Some(face) = self.face(s, k, (m, r), x, inv) {
                    d.order.push((key(m, cell), face));
                }
            }
            d.order.sort_unstable_by_key(|(key, f)| (*key, f.triangle));
            self.faces.extend(d.order.iter().map(|o| o.1));
        }
    }

    /// The device's lists of edges tested again with the CPU's test, each pair once from the
    /// first of its two in the cells' order, and in the CPU's order.
    fn crossings_from_device(&mut self, d: &mut OnDevice, packed: &Packed, cell: f64) {
        let (x, inv) = (&packed.x, &packed.inv_mass);
        let reach_max = self.thickest() + self.reach;
        d.pairs.clear();
        let queries = d.at.len().saturating_sub(1);
        for s in 0..queries as u32 {
            let (ms, rs) = self.edge_centres[s as usize];
            if !(ms.is_finite() && rs.is_finite()) {
                continue;
            }
            let own = (key(ms, cell), s);
            let e = self.edges[s as usize];
            for &u in &d.list[d.at[s as usize] as usize..d.at[s as usize + 1] as usize] {
                let (m, r) = self.edge_centres[u as usize];
                let other = (key(m, cell), u);
                let widest = reach_max + rs + r;
                if !(m.is_finite() && r.is_finite())
                    || other <= own
                    || (ms - m).length_squared() >= widest * widest
                    || (self.edges[u as usize].layer == e.layer
                        && self.edge_excluded.contains(s, u))
                {
                    continue;
                }
                if let Some(c) = self.crossing(s, u, (ms, rs), (m, r), x, inv) {
                    d.pairs.push((own, other, c));
                }
            }
        }
        d.pairs.sort_unstable_by_key(|p| (p.0, p.1));
        self.crossings.extend(d.pairs.iter().map(|p| p.2));
    }

    /// The device's last lists as `(member slot, triangle)` pairs, for the parity test.
    #[cfg(test)]
    pub(super) fn device_lists(&self) -> Vec<(u32, u32)> {
        let d = &self.device;
        (0..d.at.len().saturating_sub(1))
            .flat_map(|s| {
                let at = d.at[s] as usize..d.at[s + 1] as usize;
                d.list[at].iter().map(move |&k| (s as u32, k))
            })
            .collect()
    }
}

#[cfg(test)]
pub(super) mod tests {
    use std::collections::HashSet;

    use super::*;
    pub(in crate::collide) use crate::collide::search::tests::crumpled;

    /// The shared context, or `None` where there is no adapter at all (a skip only when
    /// `HARMONIC_REQUIRE_GPU` is unset).
    pub(in crate::collide) fn context() -> Option<Arc<GpuContext>> {
        match GpuContext::shared(true) {
            Ok(c) => Some(c),
            Err(e) => {
                assert!(
                    std::env::var_os("HARMONIC_REQUIRE_GPU").is_none(),
                    "HARMONIC_REQUIRE_GPU is set but no adapter: {e}"
                );
                assert_eq!(e, GpuError::NoAdapter, "only a missing adapter may skip");
                None
            }
        }
    }

    /// A candidate's pair, thickness and friction, bit for bit.
    type Bits = (u32, u32, u64, u64, u64);

    fn bits(a: u32, b: u32, thickness: f64, (mu, mu_s): (f64, f64)) -> Bits {
        let [t, mu, mu_s] = [thickness, mu, mu_s].map(f64::to_bits);
        (a, b, t, mu, mu_s)
    }

    fn faces(stage: &CollideStage) -> Vec<Bits> {
        (stage.faces.iter())
            .map(|f| bits(f.p, f.triangle, f.thickness, f.friction))
            .collect()
    }

    fn crossings(stage: &CollideStage) -> Vec<Bits> {
        (stage.crossings.iter())
            .map(|c| bits(c.a, c.b, c.thickness, c.friction))
            .collect()
    }

    /// One search (`find`, whose candidates `of` gives) on the CPU, then on the device: the
    /// device's lists (each pair as `pair` names it, `listed` times) hold every pair the CPU
    /// finds and none past a reach 0.1 mm wider, far more than the slack; tested again and
    /// ordered on the host they are the CPU's candidates in the CPU's order, the same bits;
    /// two finds give the same lists.
    fn parity(
        find: impl Fn(&mut CollideStage, &Packed),
        of: impl Fn(&CollideStage) -> Vec<Bits>,
        pair: impl Fn((u32, u32)) -> (u32, u32),
        listed: usize,
    ) {
        let Some(ctx) = context() else { return };
        let (mut stage, packed) = crumpled();
        let pairs = |s: &CollideStage| -> HashSet<(u32, u32)> {
            of(s).into_iter().map(|c| pair((c.0, c.1))).collect()
        };
        find(&mut stage, &packed);
        let (cpu, found) = (of(&stage), pairs(&stage));
        let (margin, reach) = (stage.margin, stage.reach);
        (stage.margin, stage.reach) = (margin + 1e-4, reach + 1e-4);
        find(&mut stage, &packed);
        let wide = pairs(&stage);
        (stage.margin, stage.reach) = (margin, reach);
        stage.enable_device(ctx).unwrap();
        find(&mut stage, &packed);
        let lists = stage.device_lists();
        let device: HashSet<(u32, u32)> = lists.iter().map(|&p| pair(p)).collect();
        println!(
            "{} on the CPU, {} on the device, {} within 0.1 mm more",
            found.len(),
            device.len(),
            wide.len()
        );
        assert!(found.len() > 1000, "{}", found.len());
        assert_eq!(
            listed * device.len(),
            lists.len(),
            "a pair listed too often"
        );
        let missing: Vec<_> = found.difference(&device).collect();
        assert!(missing.is_empty(), "the device missed {missing:?}");
        let extra: Vec<_> = device.difference(&wide).collect();
        assert!(
            extra.is_empty(),
            "the device found past the slack: {extra:?}"
        );
        assert_eq!(of(&stage), cpu);
        find(&mut stage, &packed);
        assert_eq!(stage.device_lists(), lists);
    }

    /// Particles against triangles: each pair listed once.
    #[test]
    fn the_device_finds_what_the_cpu_finds() {
        parity(|s, x| s.find_faces(x).unwrap(), faces, |p| p, 1);
    }

    /// Edges against edges: the device lists each pair both ways, the CPU once.
    #[test]
    fn the_device_finds_the_edges_the_cpu_finds() {
        let once = |(a, b): (u32, u32)| (a.min(b), a.max(b));
        parity(|s, x| s.find_crossings(x).unwrap(), crossings, once, 2);
    }
}
