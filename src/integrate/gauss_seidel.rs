//! Gauss–Seidel application of the spring step: colour by colour, each spring sees the
//! velocities its predecessors already changed. Springs of one colour share no particle.

use std::marker::PhantomData;

use glam::DVec3;
use rayon::prelude::*;

use super::harmonic::Linear;
use super::{PAR_CHUNK, PAR_MIN};
use crate::buffers::Packed;

/// A slice written from parallel tasks at indices that never collide.
pub(super) struct Disjoint<'a, T> {
    ptr: *mut T,
    len: usize,
    _life: PhantomData<&'a mut [T]>,
}

// SAFETY: tasks write disjoint elements (the colouring guarantees it), so sharing the
// pointer across threads creates no aliasing `&mut`.
unsafe impl<T: Send> Send for Disjoint<'_, T> {}
unsafe impl<T: Send> Sync for Disjoint<'_, T> {}

impl<'a, T> Disjoint<'a, T> {
    pub(super) fn new(slice: &'a mut [T]) -> Self {
        Self {
            ptr: slice.as_mut_ptr(),
            len: slice.len(),
            _life: PhantomData,
        }
    }
    /// # Safety
    /// No two live references may point at the same index.
    #[allow(clippy::mut_from_ref)]
    pub(super) unsafe fn get(&self, i: usize) -> &mut T {
        assert!(i < self.len);
        // SAFETY: in bounds (checked above); exclusivity is the caller's contract.
        unsafe { &mut *self.ptr.add(i) }
    }
}

/// One sweep over all colours: `φ = p δ + q δ̇ + s a` per spring (with `a` the frozen relative
/// acceleration from everything else when `forcing` is given), applied to both ends at once.
pub(super) fn sweep(packed: &mut Packed, lin: &[Linear], forcing: Option<&[f64]>, reverse: bool) {
    let Packed {
        x,
        v,
        springs,
        colouring,
        ..
    } = packed;
    let (x, springs) = (&x[..], &springs[..]);
    let v = Disjoint::new(&mut v[..]);
    let colours = colouring.colours();
    for i in 0..colours {
        let c = if reverse { colours - 1 - i } else { i };
        let range = colouring.offsets[c] as usize..colouring.offsets[c + 1] as usize;
        let members = &colouring.springs[range];
        let body = |&k: &u32| {
            let k = k as usize;
            let s = &springs[k];
            let (a, b) = (s.a as usize, s.b as usize);
            // SAFETY: springs of one colour have pairwise distinct ends, and a != b.
            let (va, vb) = unsafe { (v.get(a), v.get(b)) };
            let d = x[b] - x[a];
            let len = d.length();
            let n = d / len;
            let delta = len - s.rest;
            let delta_dot = n.dot(*vb - *va);
            let l = &lin[k];
            let mut phi = l.p * delta + l.q * delta_dot;
            if let Some(f) = forcing {
                phi += l.s * f[k];
            }
            *va -= s.wa * phi * n;
            *vb += s.wb * phi * n;
        };
        if members.len() < PAR_MIN {
            members.iter().for_each(body);
        } else {
            members.par_iter().with_min_len(PAR_CHUNK).for_each(body);
        }
    }
}

/// `v += g h` on free particles.
pub(super) fn add_gravity(packed: &mut Packed, g: DVec3, h: f64) {
    let Packed { v, inv_mass, .. } = packed;
    let body = |(vi, &w): (&mut DVec3, &f64)| {
        if w != 0.0 {
            *vi += g * h;
        }
    };
    if v.len() < PAR_MIN {
        v.iter_mut().zip(inv_mass.iter()).for_each(body);
    } else {
        v.par_iter_mut()
            .zip(inv_mass.par_iter())
            .with_min_len(PAR_CHUNK)
            .for_each(body);
    }
}

/// `x += h v` on free particles.
pub(super) fn drift(packed: &mut Packed, h: f64) {
    let Packed { x, v, inv_mass, .. } = packed;
    let body = |((xi, vi), &w): ((&mut DVec3, &DVec3), &f64)| {
        if w != 0.0 {
            *xi += h * *vi;
        }
    };
    if x.len() < PAR_MIN {
        x.iter_mut()
            .zip(v.iter())
            .zip(inv_mass.iter())
            .for_each(body);
    } else {
        x.par_iter_mut()
            .zip(v.par_iter())
            .zip(inv_mass.par_iter())
            .with_min_len(PAR_CHUNK)
            .for_each(body);
    }
}
