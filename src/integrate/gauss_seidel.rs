//! Gauss–Seidel application of the spring step: colour by colour, each spring sees the
//! velocities its predecessors already changed. Springs of one colour share no particle.

use std::marker::PhantomData;

use glam::DVec3;

use super::harmonic::Linear;
use super::par;
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
        par::each_of(colouring.members(c), |&k| {
            let k = k as usize;
            let s = &springs[k];
            let (a, b) = (s.a as usize, s.b as usize);
            // SAFETY: springs of one colour have pairwise distinct ends, and a != b.
            let (va, vb) = unsafe { (v.get(a), v.get(b)) };
            let l = &lin[k];
            let (n, mut phi) = super::spring_response(s, x, *va, *vb, l);
            if let Some(f) = forcing {
                phi += l.s * f[k];
            }
            let dv = super::guard(phi * n, s, x, *va, *vb);
            *va -= s.wa * dv;
            // End b's share is 1 − wa (shaders/integrate.wgsl stores wa only).
            *vb += (1.0 - s.wa) * dv;
        });
    }
}

/// `v += g h` on free particles.
pub(super) fn add_gravity(packed: &mut Packed, g: DVec3, h: f64) {
    let Packed { v, inv_mass, .. } = packed;
    par::each(v, |i, vi| {
        if inv_mass[i] != 0.0 {
            *vi += g * h;
        }
    });
}

/// `x += h v` on free particles.
pub(super) fn drift(packed: &mut Packed, h: f64) {
    let Packed { x, v, inv_mass, .. } = packed;
    par::each(x, |i, xi| {
        if inv_mass[i] != 0.0 {
            *xi += h * v[i];
        }
    });
}
