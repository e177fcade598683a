//! Static equilibrium by dynamic relaxation, for "start at equilibrium" runs and static strain.

use harmonic::glam::DVec3;

use harmonic::internals::buffers::Packed;
use harmonic::internals::integrate::{Integrator, Solver};
use harmonic::internals::metrics;
use harmonic::internals::step_control;

/// Result of a relaxation.
#[derive(Clone, Debug)]
pub struct Relaxed {
    pub positions: Vec<DVec3>,
    /// Largest net acceleration left on a particle when it stopped (m/s²).
    pub residual_acceleration: f64,
    pub iterations: usize,
}

/// Relaxes the packed state to rest under `gravity`: symplectic Euler at half its measured
/// stable step, all velocities zeroed whenever the kinetic energy passes a peak
/// (kinetic damping). Stops when every particle's net acceleration is below `tol` (m/s²) or after `max_iter` steps.
pub fn relax(packed: &Packed, gravity: DVec3, tol: f64, max_iter: usize) -> Relaxed {
    // Half the step symplectic Euler is measured to take on this network and damping; should
    // it still diverge, halve the step and start again.
    let choice = step_control::choose(packed, Integrator::SymplecticEuler, 1.0);
    let mut h = match (choice.limit, choice.omega_max > 0.0) {
        (Some(limit), true) => 0.5 * limit / choice.omega_max,
        _ => 1e-3,
    };
    let mut out = relax_at(packed, gravity, tol, max_iter, h);
    for _ in 0..6 {
        let sane = out.positions.iter().all(|x| x.is_finite()) && {
            let mut p = packed.clone();
            p.x.clone_from(&out.positions);
            metrics::max_strain(&p) < 10.0
        };
        if sane {
            break;
        }
        h *= 0.5;
        out = relax_at(packed, gravity, tol, max_iter, h);
    }
    out
}

fn relax_at(packed: &Packed, gravity: DVec3, tol: f64, max_iter: usize, h: f64) -> Relaxed {
    let mut p = packed.clone();
    p.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
    let mut solver = Solver::new(Integrator::SymplecticEuler, false, gravity);
    let ke = |p: &Packed| {
        (0..p.particle_count())
            .filter(|&i| p.inv_mass[i] != 0.0)
            .map(|i| p.mass(i) * p.v[i].length_squared())
            .sum::<f64>()
    };
    let mut before = p.x.clone();
    let mut last = 0.0;
    let mut residual = f64::INFINITY;
    let mut it = 0;
    while it < max_iter {
        before.copy_from_slice(&p.x);
        if solver.substep(&mut p, h).is_err() {
            break;
        }
        it += 1;
        let k = ke(&p);
        if !k.is_finite() {
            break;
        }
        if k < last {
            // Past the peak: restart from the previous (lower-energy) positions at rest.
            p.x.copy_from_slice(&before);
            p.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
            last = 0.0;
        } else {
            last = k;
        }
        if it % 64 == 0 {
            residual = acceleration_left(&p, &mut solver, h);
            if residual < tol {
                break;
            }
        }
    }
    Relaxed {
        positions: p.x,
        residual_acceleration: residual,
        iterations: it,
    }
}

/// Largest acceleration a particle gets when released from rest: the net force left.
fn acceleration_left(p: &Packed, solver: &mut Solver, h: f64) -> f64 {
    let mut q = p.clone();
    q.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
    if solver.substep(&mut q, h).is_err() {
        return f64::INFINITY;
    }
    q.v.iter().map(|v| v.length()).fold(0.0, f64::max) / h
}

/// Max strain at the relaxed state.
pub fn static_strain(packed: &Packed, relaxed: &Relaxed) -> f64 {
    let mut p = packed.clone();
    p.x.clone_from(&relaxed.positions);
    metrics::max_strain(&p)
}
