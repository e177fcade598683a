//! Research prototype (not the engine, not built by cargo): how fast could `harmonic-gs` sweep
//! a cloth if the sweep followed the grid? The springs of a 128×128 cloth (structural, shear,
//! bend) in 12 structured colours (each link direction split by the parity of its start row, or
//! of its start column pair), state per coordinate (x, y, z arrays), the closed form's
//! `φ = p δ + q δ̇` with one pair of coefficients, one thread, no pins or guard. Run:
//! `rustc -C opt-level=3 benches/lab/research/gs_grid_prototype.rs -o /tmp/gs && /tmp/gs`
//! (BENCHMARKS.md, "The implicit steps' spring blocks", has the figures beside the engine's).
use std::time::Instant;

const N: usize = 128;
const LINKS: [(usize, isize); 6] = [(0, 1), (1, 0), (1, 1), (1, -1), (0, 2), (2, 0)];

struct St { x: [Vec<f64>; 3], v: [Vec<f64>; 3] }

#[inline(always)]
fn spring(st: &mut St, i: usize, j: usize, rest: f64, p: f64, q: f64) {
    let dx = st.x[0][j] - st.x[0][i];
    let dy = st.x[1][j] - st.x[1][i];
    let dz = st.x[2][j] - st.x[2][i];
    let len = (dx * dx + dy * dy + dz * dz).sqrt();
    let inv = 1.0 / len;
    let (nx, ny, nz) = (dx * inv, dy * inv, dz * inv);
    let dd = nx * (st.v[0][j] - st.v[0][i]) + ny * (st.v[1][j] - st.v[1][i]) + nz * (st.v[2][j] - st.v[2][i]);
    let phi = p * (len - rest) + q * dd;
    let h = 0.5 * phi;
    st.v[0][i] -= h * nx; st.v[1][i] -= h * ny; st.v[2][i] -= h * nz;
    st.v[0][j] += h * nx; st.v[1][j] += h * ny; st.v[2][j] += h * nz;
}

// Links that go down (dr > 0): one colour is every start row r with (r / dr) % 2 == parity, so
// no particle is met twice; both ends run along contiguous columns.
#[inline(never)]
fn vertical(st: &mut St, dr: usize, dc: isize, parity: usize, rest: f64, p: f64, q: f64) {
    let (c0, c1) = if dc >= 0 { (0, N - dc as usize) } else { ((-dc) as usize, N) };
    for r in 0..N - dr {
        if (r / dr) % 2 != parity { continue; }
        let (bi, bj) = (r * N, (r + dr) * N);
        for c in c0..c1 {
            let cj = (c as isize + dc) as usize;
            spring(st, bi + c, bj + cj, rest, p, q);
        }
    }
}

// Links along a row: one colour is every start column c with (c / dc) % 2 == parity.
#[inline(never)]
fn horizontal(st: &mut St, dc: usize, parity: usize, rest: f64, p: f64, q: f64) {
    for r in 0..N {
        let b = r * N;
        for c in 0..N - dc {
            if (c / dc) % 2 != parity { continue; }
            spring(st, b + c, b + c + dc, rest, p, q);
        }
    }
}

fn main() {
    let n = N * N;
    let l = 1.0 / (N - 1) as f64;
    let mut st = St { x: [vec![0.0; n], vec![0.0; n], vec![0.0; n]], v: [vec![0.0; n], vec![0.0; n], vec![0.0; n]] };
    for r in 0..N { for c in 0..N { let i = r * N + c; st.x[0][i] = c as f64 * l * 1.01; st.x[1][i] = -(r as f64) * l * 1.02; st.x[2][i] = 1e-3 * ((i * 7919) % 13) as f64; } }
    let springs: usize = LINKS.iter().map(|&(dr, dc)| (N - dr) * (N - dc.unsigned_abs())).sum();
    let (p, q) = (-50.0, -0.3);
    let steps = 300;
    let t = Instant::now();
    for _ in 0..steps {
        for &(dr, dc) in &LINKS {
            let rest = l * (((dr * dr) as f64 + (dc * dc) as f64).sqrt());
            for parity in 0..2 {
                if dr == 0 { horizontal(&mut st, dc as usize, parity, rest, p, q); }
                else { vertical(&mut st, dr, dc, parity, rest, p, q); }
            }
        }
    }
    let dt = t.elapsed().as_secs_f64();
    let s: f64 = st.v[0].iter().sum();
    println!("{} springs, {:.1} M spring-substeps/s (one thread), checksum {s:e}", springs, springs as f64 * steps as f64 / dt / 1e6);
}
