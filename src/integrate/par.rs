//! One place for the serial-or-parallel choice of every per-element pass: below `PAR_MIN`
//! elements a pass runs on the calling thread (rayon's fork costs more), above it in chunks of
//! `PAR_CHUNK` on rayon's pool. Each element is computed alone, so results do not depend on it.

use rayon::prelude::*;

/// Below this many elements a pass runs on the calling thread.
pub(crate) const PAR_MIN: usize = 4096;
pub(crate) const PAR_CHUNK: usize = 1024;

/// `body(i, &mut items[i])` for every element.
pub fn each<T: Send>(items: &mut [T], body: impl Fn(usize, &mut T) + Sync + Send) {
    if items.len() < PAR_MIN {
        items.iter_mut().enumerate().for_each(|(i, t)| body(i, t));
    } else {
        items
            .par_iter_mut()
            .enumerate()
            .with_min_len(PAR_CHUNK)
            .for_each(|(i, t)| body(i, t));
    }
}

/// `body(i, &mut a[i], &mut b[i])` for every element of two equally long slices.
pub fn each2<A: Send, B: Send>(
    a: &mut [A],
    b: &mut [B],
    body: impl Fn(usize, &mut A, &mut B) + Sync + Send,
) {
    debug_assert_eq!(a.len(), b.len());
    if a.len() < PAR_MIN {
        a.iter_mut()
            .zip(b.iter_mut())
            .enumerate()
            .for_each(|(i, (x, y))| body(i, x, y));
    } else {
        a.par_iter_mut()
            .zip(b.par_iter_mut())
            .enumerate()
            .with_min_len(PAR_CHUNK)
            .for_each(|(i, (x, y))| body(i, x, y));
    }
}

/// Whether `pred(&a[i], &b[i])` holds for any element (stops early).
pub fn any2<A: Sync, B: Sync>(
    a: &[A],
    b: &[B],
    pred: impl Fn(&A, &B) -> bool + Sync + Send,
) -> bool {
    if a.len() < PAR_MIN {
        a.iter().zip(b).any(|(x, y)| pred(x, y))
    } else {
        a.par_iter()
            .zip(b.par_iter())
            .with_min_len(PAR_CHUNK)
            .any(|(x, y)| pred(x, y))
    }
}

/// `body(&items[i])` for every element (the element decides what it writes).
pub fn each_of<T: Sync>(items: &[T], body: impl Fn(&T) + Sync + Send) {
    if items.len() < PAR_MIN {
        items.iter().for_each(body);
    } else {
        items.par_iter().with_min_len(PAR_CHUNK).for_each(body);
    }
}
