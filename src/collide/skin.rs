//! Whether the candidates still hold: no pair left out of them can have closed to its
//! thickness since they were found. A pair left out was at least its thickness plus the margin
//! apart then; its distance has closed since by at most the largest difference of its ends'
//! moves (the particle's and a corner's, or two edges' ends'), and the moves are linear over
//! each substep, so no pair crossed on the way either. Two members at the find within blocks
//! (cubes of side `side`, by where they were) that touch may close by the margin; two further
//! apart were at least `side` apart, so any pair they belong to was at least `side` less the
//! widest primitive's reach across itself, and may close by `far`. The test bounds each
//! difference of moves by the diagonal of the box around them: over each block and the blocks
//! around it, and over all members. Nearby parts of a cloth move alike however fast it falls
//! or slides, so the candidates are found far less often than where every member's move,
//! less the mean, was held to half the margin.

use glam::DVec3;

use super::search::{beside, key};

/// How far, in margins, two members in blocks that do not touch may close: the blocks' side
/// grows with it, and so does the spread of the moves the test allows in a block's
/// neighbourhood.
const FAR: f64 = 2.0;

/// The members' blocks at the find and each block's neighbours, and the boxes of the moves.
#[derive(Debug, Default)]
pub(super) struct Skin {
    /// Each member's block (an index into the blocks), or `u32::MAX` where its place was not
    /// finite (the quarantine's: the others' moves decide).
    block_of: Vec<u32>,
    /// Each block's blocks around it (itself among them): `near[near_at[b]..near_at[b + 1]]`.
    near: Vec<u32>,
    near_at: Vec<u32>,
    keys: Vec<(u64, u32)>,
    lo: Vec<DVec3>,
    hi: Vec<DVec3>,
    /// How far two members in blocks that do not touch may close.
    far: f64,
}

impl Skin {
    /// The blocks of the members' places `built` at a find: `reach` is the most a pair's
    /// distance exceeds the distance between two of their ends (twice the widest triangle's
    /// radius, or four times the longest edge's half), `thickest` the largest thickness.
    pub(super) fn build(&mut self, built: &[DVec3], reach: f64, thickest: f64, margin: f64) {
        self.far = FAR * margin;
        let side = reach + thickest + self.far;
        self.keys.clear();
        (self.keys).extend(
            built
                .iter()
                .filter(|x| x.is_finite())
                .map(|&x| (key(x, side), 0)),
        );
        self.keys.sort_unstable();
        self.keys.dedup();
        for (b, k) in self.keys.iter_mut().enumerate() {
            k.1 = b as u32;
        }
        self.block_of.clear();
        (self.block_of).extend(built.iter().map(|&x| {
            let k = key(x, side);
            let at = x
                .is_finite()
                .then(|| self.keys.binary_search_by_key(&k, |e| e.0));
            match at {
                Some(Ok(b)) => b as u32,
                _ => u32::MAX,
            }
        }));
        self.near.clear();
        self.near_at.clear();
        self.near_at.push(0);
        let (keys, near, near_at) = (&self.keys, &mut self.near, &mut self.near_at);
        beside(keys, keys, |run, ranges| {
            for &(_, b) in run {
                let around = ranges.iter().flat_map(|r| &keys[r.clone()]);
                near.extend(around.map(|k| k.1).filter(|&u| u != b));
                near.push(b);
                near_at.push(near.len() as u32);
            }
        });
    }

    /// Whether every pair left out of the candidates is still further apart than its
    /// thickness: `moves` each member's move since the find (by slot).
    pub(super) fn holds(&mut self, moves: impl Iterator<Item = DVec3>, margin: f64) -> bool {
        let blocks = self.keys.len();
        self.lo.clear();
        self.lo.resize(blocks, DVec3::INFINITY);
        self.hi.clear();
        self.hi.resize(blocks, DVec3::NEG_INFINITY);
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for (d, &b) in moves.zip(&self.block_of) {
            if b == u32::MAX || !d.is_finite() {
                continue;
            }
            let b = b as usize;
            self.lo[b] = self.lo[b].min(d);
            self.hi[b] = self.hi[b].max(d);
            (lo, hi) = (lo.min(d), hi.max(d));
        }
        if blocks == 0 || (hi - lo).length_squared() <= margin * margin {
            return true;
        }
        if (hi - lo).length_squared() > self.far * self.far {
            return false;
        }
        (0..blocks).all(|b| {
            let around = &self.near[self.near_at[b] as usize..self.near_at[b + 1] as usize];
            let (lo, hi) = around
                .iter()
                .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), &u| {
                    (lo.min(self.lo[u as usize]), hi.max(self.hi[u as usize]))
                });
            // A block with no finite move (all its members the quarantine's) bounds nothing.
            !(hi - lo).is_finite() || (hi - lo).length_squared() <= margin * margin
        })
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use crate::buffers::Packed;
    use crate::collide::search::closest_on_triangle;
    use crate::collide::search::tests::{grid_triangles, neighbours_at_rest};
    use crate::collide::{CollideStage, SelfCollision};

    /// Three sheets, `n` by `n` at 2 cm: 8 mm, 12 mm and 10 mm thick.
    fn sheets(n: usize) -> (CollideStage, Packed) {
        let mut stage = CollideStage::default();
        for (layer, thickness) in [0.008, 0.012, 0.01].into_iter().enumerate() {
            stage.layers.push(SelfCollision {
                thickness,
                friction: 0.5,
                kinetic_friction: 0.3,
                edges: false,
            });
            stage.surfaced.push(true);
            let first = (layer * n * n) as u32;
            for i in 0..n {
                for j in 0..n {
                    let rest = DVec3::new(i as f64, 0.0, j as f64) * 0.02;
                    let at = first + (i * n + j) as u32;
                    stage.members.push((at, layer as u16, rest));
                }
            }
            grid_triangles(&mut stage, first, n, layer as u16);
        }
        stage.find_excluded();
        stage.gather_edges();
        stage.margin = 0.008;
        let count = 3 * n * n;
        stage.start = vec![DVec3::ZERO; count];
        let packed = Packed {
            x: vec![DVec3::ZERO; count],
            inv_mass: vec![1.0; count],
            ..Default::default()
        };
        (stage, packed)
    }

    /// Where a member at rest at `rest` is at time `t`: the second sheet, 2 cm over the first
    /// (past the reach), sinks onto it and on through it at 0.3 m/s, while the third falls
    /// from 25 cm onto both and on through them at 4 m/s; then the first folds over onto
    /// itself and on through itself about its middle. All fly off at 2 m/s and turn about the
    /// vertical at 1 rad/s, so the members' moves spread far past the margin while nearby
    /// ones move alike.
    fn place(layer: u16, rest: DVec3, t: f64) -> DVec3 {
        let half = 0.09;
        let local = match layer {
            0 => {
                let fold = std::f64::consts::PI * 1.2 * ((t - 0.1) / 0.3).clamp(0.0, 1.0);
                if rest.x > half {
                    let (c, s) = (fold.cos(), fold.sin());
                    let a = rest.x - half;
                    DVec3::new(half + a * c, a * s, rest.z)
                } else {
                    rest
                }
            }
            1 => rest + DVec3::new(0.03, 0.02 - 0.3 * t, 0.01),
            _ => rest + DVec3::new(-0.02, 0.25 - 4.0 * t, 0.03),
        };
        let (c, s) = (t.cos(), t.sin());
        let turned = DVec3::new(
            c * local.x + s * local.z,
            local.y,
            -s * local.x + c * local.z,
        );
        turned + DVec3::new(2.0, -0.5, 1.0) * t
    }

    /// The test's promise, against every pair of members: where it holds, two members less
    /// than a block's side apart at the find have moved apart by at most the margin, and any
    /// two by at most `far`. Moves drawn as a smooth field, a turn and noise, scaled so that it
    /// holds in some draws and not in others, and some that hold spread past the margin.
    #[test]
    fn where_it_holds_near_members_moved_alike() {
        let mut r = crate::collide::uniform(9);
        let (across, thickest, margin) = (0.02, 0.01, 0.008);
        let places: Vec<DVec3> = (0..400)
            .map(|_| DVec3::new(r(), 0.1 * r(), r()) * 0.15)
            .collect();
        let mut skin = super::Skin::default();
        skin.build(&places, across, thickest, margin);
        let side = across + thickest + skin.far;
        let (mut held, mut spread) = (0, 0);
        for draw in 0..600 {
            // In turn: a shear (moves that differ little nearby and much far apart), a wave,
            // and noise (moves that differ as much nearby as far apart).
            let scale = 0.002 * (1 + draw % 20) as f64;
            let shear = [DVec3::new(r(), r(), r()), DVec3::new(r(), r(), r())];
            let (k, kind) = (DVec3::new(r(), r(), r()) * 30.0, draw % 3);
            let moves: Vec<DVec3> = (places.iter())
                .map(|&x| {
                    let noise = DVec3::new(r(), r(), r());
                    let d = match kind {
                        0 => shear[0] * (x.x / 0.15) + shear[1] * (x.z / 0.15),
                        1 => DVec3::new((k.x * x.z).sin(), (k.y * x.x).sin(), (k.z * x.y).cos()),
                        _ => noise,
                    };
                    d * scale + DVec3::splat(0.3)
                })
                .collect();
            if !skin.holds(moves.iter().copied(), margin) {
                continue;
            }
            held += 1;
            let mut widest = 0.0f64;
            for (i, (xi, di)) in places.iter().zip(&moves).enumerate() {
                for (xj, dj) in places[..i].iter().zip(&moves) {
                    let apart = (*di - *dj).length();
                    widest = widest.max(apart);
                    let bound = if (*xi - *xj).length() < side {
                        margin
                    } else {
                        skin.far
                    };
                    assert!(
                        apart <= bound * (1.0 + 1e-12),
                        "draw {draw}: {apart} > {bound}"
                    );
                }
            }
            spread += usize::from(widest > margin);
        }
        println!("held in {held} of 600 draws, {spread} of them spread past the margin");
        assert!((30..570).contains(&held), "{held}");
        assert!(spread >= 5, "{spread}");
    }

    /// Every pair closer than its thickness at the end of a substep or halfway along it is a
    /// candidate then, though the candidates are found again only where a pair may have
    /// closed past the margin: tested against every member with every triangle not its
    /// neighbour at rest, over a fold through itself and sheets sinking through others.
    #[test]
    fn no_pair_left_out_comes_within_its_thickness() {
        let (mut stage, mut packed) = sheets(10);
        let set = |packed: &mut Packed, stage: &CollideStage, t: f64| {
            for m in &stage.members {
                packed.x[m.0 as usize] = place(m.1, m.2, t);
            }
        };
        set(&mut packed, &stage, 0.0);
        stage.begin_frame(&packed).unwrap();
        let (h, substeps) = (1.0 / 600.0, 300);
        let mut close = 0;
        for step in 1..=substeps {
            set(&mut packed, &stage, step as f64 * h);
            stage.refresh(&packed).unwrap();
            let found: std::collections::HashSet<(u32, u32)> =
                stage.faces.iter().map(|f| (f.p, f.triangle)).collect();
            for (s, &(p, lp, _)) in (0u32..).zip(&stage.members) {
                for (k, tri) in (0u32..).zip(&stage.triangles) {
                    if tri.at.contains(&p) || neighbours_at_rest(&stage, s, k) {
                        continue;
                    }
                    let (t, _) = stage.combine(lp, tri.layer);
                    for along in [0.5, 1.0] {
                        let at = |i: u32| {
                            let (s, x) = (stage.start[i as usize], packed.x[i as usize]);
                            s + (x - s) * along
                        };
                        let [a, b, c] = tri.at.map(at);
                        let xp = at(p);
                        let w = closest_on_triangle(xp, a, b, c);
                        if (xp - (a * w[0] + b * w[1] + c * w[2])).length() < t {
                            close += 1;
                            assert!(
                                found.contains(&(p, k)),
                                "substep {step}: {p} within {t} of {k}"
                            );
                        }
                    }
                }
            }
            stage.keep_start(&packed);
        }
        println!("{close} pairs within their thickness, candidates found {} times in {substeps} substeps", stage.rebuilds);
        assert!(close > 1000, "{close}");
        assert!(stage.rebuilds < substeps as u64 / 2, "{}", stage.rebuilds);
    }
}
