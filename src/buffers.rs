//! Gather and scatter: the World packed into structure-of-arrays buffers.
//!
//! Topology (springs, CSR incidence, masses) is packed once per topology change; between
//! gathers the buffers are the state and the World is only written back at scatter.

use glam::DVec3;
use hecs::{Entity, World};

use crate::components::{Particle, Pin, SceneIndex, Spring};
use crate::error::SimError;
use crate::integrate::paper::reduced_mass;

/// A spring in packed form. `wa`/`wb` split the pair's relative velocity change by mass:
/// `Δv_a = −wa φ n`, `Δv_b = +wb φ n`, with `wa = μ/m_a`, `wb = μ/m_b` (0 at a pinned end).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PackedSpring {
    pub a: u32,
    pub b: u32,
    pub rest: f64,
    pub stiffness: f64,
    pub damping: f64,
    /// Reduced mass; infinite when both ends are pinned (the spring then does nothing).
    pub mu: f64,
    pub wa: f64,
    pub wb: f64,
}

impl PackedSpring {
    /// `κ/μ`, 0 when both ends are pinned.
    pub fn omega0_sq(&self) -> f64 {
        if self.mu.is_finite() {
            self.stiffness / self.mu
        } else {
            0.0
        }
    }
    /// `c/(2μ)`, 0 when both ends are pinned.
    pub fn alpha(&self) -> f64 {
        if self.mu.is_finite() {
            self.damping / (2.0 * self.mu)
        } else {
            0.0
        }
    }
    /// Damping ratio `ζ = α/ω0`.
    pub fn zeta(&self) -> f64 {
        let w2 = self.omega0_sq();
        if w2 > 0.0 {
            self.alpha() / w2.sqrt()
        } else {
            0.0
        }
    }
}

/// Per-particle lists of incident springs (CSR); pinned ends get no entry.
#[derive(Clone, Debug, Default)]
pub struct Incidence {
    /// `offsets[i]..offsets[i+1]` indexes `spring`/`coef` for particle `i`.
    pub offsets: Vec<u32>,
    pub spring: Vec<u32>,
    /// `−wa` at a spring's `a` end, `+wb` at its `b` end.
    pub coef: Vec<f64>,
}

impl Incidence {
    /// `Σ coef · per_spring[s]` over particle `i`'s springs, in a fixed order (deterministic).
    #[inline(always)]
    pub fn sum(&self, per_spring: &[DVec3], i: usize) -> DVec3 {
        let (lo, hi) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
        let mut sum = DVec3::ZERO;
        for k in lo..hi {
            sum += self.coef[k] * per_spring[self.spring[k] as usize];
        }
        sum
    }
}

/// Springs grouped by colour: springs of one colour share no particle, so a colour can be
/// processed in parallel in Gauss–Seidel order. Springs with both ends pinned are left out.
#[derive(Clone, Debug, Default)]
pub struct Colouring {
    /// `offsets[c]..offsets[c+1]` indexes `springs` for colour `c`.
    pub offsets: Vec<u32>,
    pub springs: Vec<u32>,
}

impl Colouring {
    pub fn colours(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// The springs of colour `c`.
    pub fn members(&self, c: usize) -> &[u32] {
        &self.springs[self.offsets[c] as usize..self.offsets[c + 1] as usize]
    }

    /// Greedy edge colouring in spring order (at most 2·max degree − 1 colours).
    fn build(n: usize, springs: &[PackedSpring]) -> Self {
        let mut degree = vec![0u32; n];
        for s in springs {
            degree[s.a as usize] += 1;
            degree[s.b as usize] += 1;
        }
        let max_deg = degree.iter().copied().max().unwrap_or(0) as usize;
        let words = (2 * max_deg) / 64 + 1;
        let mut used = vec![0u64; n * words];
        let mut colour = vec![u32::MAX; springs.len()];
        let mut count = Vec::<u32>::new();
        for (k, s) in springs.iter().enumerate() {
            if s.wa == 0.0 && s.wb == 0.0 {
                continue;
            }
            let (a, b) = (s.a as usize * words, s.b as usize * words);
            #[allow(
                clippy::expect_used,
                reason = "a spring meets at most 2·max_deg − 2 others"
            )]
            let c = (0..words)
                .find_map(|w| {
                    let free = !(used[a + w] | used[b + w]);
                    (free != 0).then(|| w * 64 + free.trailing_zeros() as usize)
                })
                .expect("2·max degree colours always suffice");
            used[a + c / 64] |= 1 << (c % 64);
            used[b + c / 64] |= 1 << (c % 64);
            colour[k] = c as u32;
            if count.len() <= c {
                count.resize(c + 1, 0);
            }
            count[c] += 1;
        }
        let mut offsets = vec![0u32; count.len() + 1];
        for c in 0..count.len() {
            offsets[c + 1] = offsets[c] + count[c];
        }
        let mut fill = offsets.clone();
        let mut order = vec![0u32; offsets[count.len()] as usize];
        for (k, &c) in colour.iter().enumerate() {
            if c != u32::MAX {
                order[fill[c as usize] as usize] = k as u32;
                fill[c as usize] += 1;
            }
        }
        Colouring {
            offsets,
            springs: order,
        }
    }
}

/// The packed scene: particle state in scene order, springs, and per-particle incidence (CSR).
#[derive(Clone, Debug, Default)]
pub struct Packed {
    pub entities: Vec<Entity>,
    pub x: Vec<DVec3>,
    pub v: Vec<DVec3>,
    /// kg; infinite for pinned particles.
    pub mass: Vec<f64>,
    /// 0 for pinned particles.
    pub inv_mass: Vec<f64>,
    pub springs: Vec<PackedSpring>,
    pub incidence: Incidence,
    pub colouring: Colouring,
    /// Entity id → packed index (`u32::MAX` where none).
    index_by_id: Vec<u32>,
}

impl Packed {
    pub fn particle_count(&self) -> usize {
        self.x.len()
    }

    /// Packs every particle and spring of the World.
    pub fn gather(world: &World) -> Result<Self, SimError> {
        let mut rows: Vec<(u32, u32, Entity, Particle, bool)> = world
            .query::<(Entity, &Particle, Option<&Pin>, Option<&SceneIndex>)>()
            .iter()
            .map(|(e, p, pin, idx)| (idx.map_or(u32::MAX, |i| i.0), e.id(), e, *p, pin.is_some()))
            .collect();
        rows.sort_unstable_by_key(|r| (r.0, r.1));

        let n = rows.len();
        let mut packed = Packed {
            entities: Vec::with_capacity(n),
            x: Vec::with_capacity(n),
            v: Vec::with_capacity(n),
            mass: Vec::with_capacity(n),
            inv_mass: Vec::with_capacity(n),
            ..Default::default()
        };
        let max_id = rows.iter().map(|r| r.1).max().map_or(0, |m| m as usize + 1);
        let mut index_of = vec![u32::MAX; max_id];
        for (i, (_, id, e, p, pinned)) in rows.into_iter().enumerate() {
            // Components set through the World get the checks a scene file gets. A non-finite
            // velocity is not refused: the step quarantines the particle instead.
            let bad = |what: String| SimError::BadParticle { particle: e, what };
            if !p.position.is_finite() {
                return Err(bad(format!("position must be finite, got {}", p.position)));
            }
            let mass_ok = p.mass.is_finite() && p.mass > 0.0;
            if !(pinned || mass_ok) {
                return Err(bad(format!("mass must be finite and > 0, got {}", p.mass)));
            }
            index_of[id as usize] = i as u32;
            packed.entities.push(e);
            packed.x.push(p.position);
            packed.v.push(if pinned { DVec3::ZERO } else { p.velocity });
            packed
                .mass
                .push(if pinned { f64::INFINITY } else { p.mass });
            packed
                .inv_mass
                .push(if pinned { 0.0 } else { 1.0 / p.mass });
        }
        packed.index_by_id = index_of;
        let lookup = |spring: Entity, end: Entity| -> Result<u32, SimError> {
            packed
                .index_of(end)
                .map(|i| i as u32)
                .ok_or(SimError::DanglingSpring { spring, end })
        };

        let mut springs: Vec<(Entity, Spring)> = world
            .query::<(Entity, &Spring)>()
            .iter()
            .map(|(e, s)| (e, *s))
            .collect();
        springs.sort_unstable_by_key(|(e, _)| e.id());
        let mut out = Vec::with_capacity(springs.len());
        for (e, s) in &springs {
            let (a, b) = (lookup(*e, s.a)?, lookup(*e, s.b)?);
            let bad = |what: String| SimError::BadSpring { spring: *e, what };
            if a == b {
                return Err(bad("both ends are the same particle".into()));
            }
            if !(s.rest_length.is_finite() && s.rest_length > 0.0) {
                return Err(bad(format!(
                    "rest length must be finite and > 0, got {}",
                    s.rest_length
                )));
            }
            if !(s.stiffness.is_finite() && s.stiffness >= 0.0) {
                return Err(bad(format!(
                    "stiffness must be finite and ≥ 0, got {}",
                    s.stiffness
                )));
            }
            if !(s.damping.is_finite() && s.damping >= 0.0) {
                return Err(bad(format!(
                    "damping must be finite and ≥ 0, got {}",
                    s.damping
                )));
            }
            let (ma, mb) = (packed.mass[a as usize], packed.mass[b as usize]);
            let mu = reduced_mass(ma, mb);
            let (wa, wb) = if mu.is_finite() {
                (mu / ma, mu / mb)
            } else {
                (0.0, 0.0)
            };
            out.push(PackedSpring {
                a,
                b,
                rest: s.rest_length,
                stiffness: s.stiffness,
                damping: s.damping,
                mu,
                wa,
                wb,
            });
        }
        packed.springs = out;
        packed.build_incidence();
        packed.colouring = Colouring::build(packed.x.len(), &packed.springs);
        Ok(packed)
    }

    fn build_incidence(&mut self) {
        let n = self.x.len();
        let mut count = vec![0u32; n + 1];
        for s in &self.springs {
            if s.wa != 0.0 {
                count[s.a as usize + 1] += 1;
            }
            if s.wb != 0.0 {
                count[s.b as usize + 1] += 1;
            }
        }
        for i in 0..n {
            count[i + 1] += count[i];
        }
        let total = count[n] as usize;
        let mut fill = count.clone();
        let mut spring = vec![0; total];
        let mut coef = vec![0.0; total];
        for (k, s) in self.springs.iter().enumerate() {
            for (end, c) in [(s.a, -s.wa), (s.b, s.wb)] {
                if c != 0.0 {
                    let slot = fill[end as usize] as usize;
                    spring[slot] = k as u32;
                    coef[slot] = c;
                    fill[end as usize] += 1;
                }
            }
        }
        self.incidence = Incidence {
            offsets: count,
            spring,
            coef,
        };
    }

    /// Writes positions and velocities back into the World's particles.
    pub fn scatter(&self, world: &mut World) {
        for (e, p) in world.query_mut::<(Entity, &mut Particle)>() {
            if let Some(i) = self.index_of(e) {
                p.position = self.x[i];
                if self.inv_mass[i] != 0.0 {
                    p.velocity = self.v[i];
                }
            }
        }
    }

    /// The packed index of a particle entity, if it was packed.
    pub fn index_of(&self, e: Entity) -> Option<usize> {
        let i = *self.index_by_id.get(e.id() as usize)? as usize;
        (self.entities.get(i) == Some(&e)).then_some(i)
    }

    /// Stretch `δ = |x_b − x_a| − l0` of spring `k`.
    pub fn stretch(&self, k: usize) -> f64 {
        let s = &self.springs[k];
        (self.x[s.b as usize] - self.x[s.a as usize]).length() - s.rest
    }
}
