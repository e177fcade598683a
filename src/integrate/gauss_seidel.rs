//! Gauss–Seidel application of the spring step: colour by colour, each spring sees the
//! velocities its predecessors already changed. Springs of one colour share no particle.

use std::marker::PhantomData;

use super::harmonic::Linear;
use super::par;
use crate::buffers::{Packed, PackedSpring};

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

/// A spring as the sweep reads it, copied in colour order at prepare: each colour is then one
/// sequential stream instead of a gather through the colouring's index list.
#[derive(Clone, Copy, Debug)]
pub struct SweepSpring {
    spring: PackedSpring,
    lin: Linear,
    /// Index in `Packed::springs` (the forcing is stored by it).
    index: u32,
}

/// The springs of `packed`'s colouring, colour after colour, with their coefficients.
pub fn order(packed: &Packed, lin: &[Linear], out: &mut Vec<SweepSpring>) {
    out.clear();
    out.extend(packed.colouring.springs.iter().map(|&k| SweepSpring {
        spring: packed.springs[k as usize],
        lin: lin[k as usize],
        index: k,
    }));
}

/// One sweep over all colours: `φ = p δ + q δ̇ + s a` per spring (with `a` the frozen relative
/// acceleration from everything else when `forcing` is given), applied to both ends at once.
/// `springs` is [`order`]'s output for `packed`. `harmonic-gs` sweeps forward with no forcing;
/// the lab's research variants pass a forcing (`harmonic-forced-gs`) or sweep the colours in
/// reverse (`harmonic-sgs`).
pub fn sweep(packed: &mut Packed, springs: &[SweepSpring], forcing: Option<&[f64]>, reverse: bool) {
    let Packed {
        x, v, colouring, ..
    } = packed;
    let x = &x[..];
    let v = Disjoint::new(&mut v[..]);
    let colours = colouring.colours();
    for i in 0..colours {
        let c = if reverse { colours - 1 - i } else { i };
        let range = colouring.offsets[c] as usize..colouring.offsets[c + 1] as usize;
        par::each_of(&springs[range], |k| {
            let s = &k.spring;
            let (a, b) = (s.a as usize, s.b as usize);
            // SAFETY: springs of one colour have pairwise distinct ends, and a != b.
            let (va, vb) = unsafe { (v.get(a), v.get(b)) };
            let l = &k.lin;
            let (n, mut phi) = super::spring_response(s, x, *va, *vb, l);
            if let Some(f) = forcing {
                phi += l.s * f[k.index as usize];
            }
            let dv = super::guard(phi * n, s, x, *va, *vb);
            *va -= s.wa * dv;
            // End b's share is 1 − wa (shaders/integrate.wgsl stores wa only).
            *vb += (1.0 - s.wa) * dv;
        });
    }
}

/// `v += g h` on free particles (`g` the external acceleration).
pub fn add_gravity(packed: &mut Packed, g: super::External<'_>, h: f64) {
    let Packed { v, inv_mass, .. } = packed;
    par::each(v, |i, vi| {
        if inv_mass[i] != 0.0 {
            *vi += g.at(i) * h;
        }
    });
}

/// `x += h v` on free particles.
pub fn drift(packed: &mut Packed, h: f64) {
    let Packed { x, v, inv_mass, .. } = packed;
    par::each(x, |i, xi| {
        if inv_mass[i] != 0.0 {
            *xi += h * v[i];
        }
    });
}
