//! The particles' move: the external acceleration the integrators read where gravity was
//! (`External`), and pass 2 of the Jacobi steps, each particle gathering its springs' changes.

use glam::DVec3;

use super::{par, Update};
use crate::buffers::Packed;

/// The external acceleration the integrators add where they read gravity: gravity alone, a
/// constant, or per particle (gravity included) when the schedule lists a force stage.
#[derive(Clone, Copy, Debug)]
pub enum External<'a> {
    /// The same acceleration for every particle.
    Uniform(DVec3),
    /// One acceleration per particle, in packed order.
    PerParticle(&'a [DVec3]),
}

impl External<'_> {
    /// Particle `i`'s external acceleration.
    #[inline(always)]
    pub fn at(self, i: usize) -> DVec3 {
        match self {
            External::Uniform(g) => g,
            External::PerParticle(a) => a[i],
        }
    }
}

/// A particle's external acceleration as a hot loop reads it, the loop compiled once per kind:
/// a constant where there are no forces, so that loop has no per-particle branch.
pub(crate) trait Accel: Copy {
    /// Particle `i`'s external acceleration.
    fn at(self, i: usize) -> DVec3;
}

/// The same acceleration for every particle ([`External::Uniform`]).
#[derive(Clone, Copy)]
pub(crate) struct Constant(pub(crate) DVec3);

impl Accel for Constant {
    #[inline(always)]
    fn at(self, _: usize) -> DVec3 {
        self.0
    }
}

impl Accel for &[DVec3] {
    #[inline(always)]
    fn at(self, i: usize) -> DVec3 {
        self[i]
    }
}

/// Symplectic (velocity first) or explicit (position first) Euler: one particle's move with
/// its springs' velocity change `dv`.
#[inline(always)]
pub(crate) fn euler_move(
    update: Update,
    x: DVec3,
    v: DVec3,
    dv: DVec3,
    g: DVec3,
    h: f64,
) -> (DVec3, DVec3) {
    if update == Update::PositionFirst {
        (x + h * v, v + (dv + g * h))
    } else {
        let v = v + (dv + g * h);
        (x + h * v, v)
    }
}

/// Pass 2: each particle in no grid gathers its springs' changes and moves.
pub fn particle_pass(
    packed: &mut Packed,
    sdv: &[DVec3],
    sdx: &[DVec3],
    g: External<'_>,
    h: f64,
    update: Update,
) {
    let Packed {
        topology,
        x,
        v,
        inv_mass,
        incidence,
        ..
    } = packed;
    let loose = &topology.loose;
    let (inv_mass, inc) = (&inv_mass[..], &*incidence);
    for range in loose.iter() {
        let first = range.start;
        let (x, v) = (&mut x[range.clone()], &mut v[range.clone()]);
        par::each2(x, v, |k, xi, vi| {
            let i = first + k;
            if inv_mass[i] == 0.0 {
                return;
            }
            let dv = inc.sum(sdv, i);
            let g = g.at(i);
            match update {
                Update::VelocityFirst | Update::PositionFirst => {
                    (*xi, *vi) = euler_move(update, *xi, *vi, dv, g, h);
                }
                Update::Exact => {
                    *xi += h * *vi + 0.5 * h * h * g + inc.sum(sdx, i);
                    *vi += dv + g * h;
                }
            }
        });
    }
}
