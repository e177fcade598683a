"""Research prototype for issue 3's large-step target: one multigrid V-cycle toward an implicit
step, on the linearised chain of 20 and the 16x16 cloth (in-plane, about rest).

The bound in STABILITY.md says a step made of s local passes cannot out-step symplectic Euler's
s substeps, because each pass moves information one spring. A V-cycle moves it across the whole
network in one cycle at the cost of a few passes, so this asks whether a theta-step
  (M + theta h C + theta^2 h^2 K) dv = h (f - theta h K v),  x' = x + h ((1 - theta) v + theta v'),
solved by ONE V-cycle (weighted Jacobi smoothing, Galerkin coarse levels from linear
interpolation, Jacobi sweeps on the coarsest level: no global solve) meets the target:
stable at h/h_c >= 2 at zeta = 0.2, error no worse than implicit Euler's, <= 3 passes.

Unit masses and springs, damping ratio zeta per spring (reduced mass 1/2), h_c = pi / omega0.
Stable: spectral radius of the linear step map <= 1.001 (the growth-rate rule of
benches/lab/src/stability.rs). Error: RMS position error per particle after 16 h_c of motion, released at
rest from a smooth stretch, against the exact solution (mode by mode). Passes: matrix-vector
products per step, a coarse level's counted by its size relative to the fine one.
Needs numpy: `python3 benches/lab/research/multigrid_prototypes.py` (about 3 minutes).
"""
import math
import sys

import numpy as np

HC = math.pi / math.sqrt(2.0)
POINTS = (0.25, 0.5, 1, 2, 2.0625, 4, 6.0625, 8.0625)
ERROR_AT = (0.5, 1, 2, 4)


def interp1(nf):
    """Linear interpolation from every other node (the last node copies its coarse neighbour)."""
    nc = (nf + 1) // 2
    p = np.zeros((nf, nc))
    for f in range(nf):
        if f % 2 == 0:
            p[f, f // 2] = 1
        elif (f + 1) // 2 < nc:
            p[f, (f - 1) // 2] = p[f, (f + 1) // 2] = 0.5
        else:
            p[f, (f - 1) // 2] = 1
    return p


def cloth_springs(side):
    """(node, node, grid offset) of a side x side cloth: structural, shear and bend."""
    out = []
    for i in range(side):
        for j in range(side):
            for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1), (0, 2), (2, 0)):
                if 0 <= i + di < side and 0 <= j + dj < side:
                    out.append((i * side + j, (i + di) * side + j + dj, (di, dj)))
    return out


def aggregate1(nf):
    """Piecewise-constant transfer: each pair of nodes is one coarse node (unsmoothed aggregation,
    the transfer a general network gets most cheaply: its coarse level is again a spring network)."""
    p = np.zeros((nf, (nf + 1) // 2))
    for f in range(nf):
        p[f, f // 2] = 1
    return p


def smoothed_aggregation(laplacian, dim):
    """Transfers for any network, finest first, from its scalar spring graph (the Laplacian over
    the free nodes): greedy aggregates (a node whose neighbours are all free of aggregates takes
    them; the rest join a neighbour's), the piecewise-constant transfer smoothed by one damped
    Jacobi step on the Laplacian (weight 4 / (3 rho)), down to 4 nodes."""
    out, lap = [], laplacian
    while lap.shape[0] > 4:
        n = lap.shape[0]
        near = [set(np.nonzero(lap[i])[0]) - {i} for i in range(n)]
        agg = [-1] * n
        count = 0
        for i in range(n):
            if agg[i] < 0 and all(agg[j] < 0 for j in near[i]):
                for j in near[i] | {i}:
                    agg[j] = count
                count += 1
        for i in range(n):
            if agg[i] < 0:
                agg[i] = next(agg[j] for j in near[i] if agg[j] >= 0)
        tentative = np.zeros((n, count))
        tentative[np.arange(n), agg] = 1
        jacobi = lap / np.diag(lap)[:, None]
        rho = max(abs(np.linalg.eigvals(jacobi)))
        p = tentative - (4 / (3 * rho)) * jacobi @ tentative
        out.append(np.kron(p, np.eye(dim)))
        lap = p.T @ lap @ p
    return out


def hierarchy(shape, free_nodes, dim, transfer=interp1):
    """Transfer matrices over the free dofs, finest first, down to 4 nodes; a coarse node
    sits on every other fine node per axis and is free when that fine node is."""
    out = []
    while np.prod(shape) > 4:
        ps = [transfer(s) for s in shape]
        pn = ps[0] if len(ps) == 1 else np.kron(ps[0], ps[1])
        coarse = tuple((s + 1) // 2 for s in shape)

        def at(cn, cs=coarse, fs=shape):
            if len(cs) == 1:
                return 2 * cn
            ci, cj = divmod(cn, cs[1])
            return 2 * ci * fs[1] + 2 * cj

        coarse_free = {cn for cn in range(int(np.prod(coarse))) if at(cn) in free_nodes}
        rows = [dim * f + c for f in sorted(free_nodes) for c in range(dim)]
        cols = [dim * f + c for f in sorted(coarse_free) for c in range(dim)]
        out.append(np.kron(pn, np.eye(dim))[np.ix_(rows, cols)])
        shape, free_nodes = coarse, coarse_free
    return out


class System:
    """Stiffness K over the free dofs (M = I, C = c K) and the interpolation hierarchy."""

    def __init__(self, kind, zeta, transfer=interp1):
        self.kind, self.zeta, self.c = kind, zeta, 2 * zeta * math.sqrt(0.5)
        if kind == "chain":
            nodes, shape, dim, pins = 21, (21,), 1, [0]
            springs = [(s, s + 1, np.ones(1)) for s in range(20)]
        else:
            side = 16
            nodes, shape, dim, pins = side * side, (side, side), 2, [0, side - 1]
            springs = [(a, b, np.array(d, float) / math.hypot(*d))
                       for a, b, d in cloth_springs(side)]
        k = np.zeros((dim * nodes, dim * nodes))
        for a, b, d in springs:
            block = np.outer(d, d)
            for p, q, w in ((a, a, 1), (b, b, 1), (a, b, -1), (b, a, -1)):
                k[dim * p:dim * p + dim, dim * q:dim * q + dim] += w * block
        free = [i for i in range(dim * nodes) if i // dim not in pins]
        self.K, self.n, self.dim = k[np.ix_(free, free)], len(free), dim
        if transfer is smoothed_aggregation:
            lap = np.zeros((nodes, nodes))
            for a, b, _ in springs:
                lap[a, a] += 1
                lap[b, b] += 1
                lap[a, b] -= 1
                lap[b, a] -= 1
            kept = [i for i in range(nodes) if i not in pins]
            self.P = smoothed_aggregation(lap[np.ix_(kept, kept)], dim)
        else:
            self.P = hierarchy(shape, set(range(nodes)) - set(pins), dim, transfer)

    def released(self):
        """A smooth stretch along the hanging direction, at rest."""
        if self.kind == "chain":
            x = [0.3 * math.sin(math.pi * i / 40) for i in range(1, 21)]
        else:
            x = []
            for node in range(256):
                if node not in (0, 15):
                    x += [0.3 * math.sin(math.pi * (node // 16) / 30), 0.0]
        return np.array(x), np.zeros(self.n)

    def exact(self, x, v, t):
        lam, vec = np.linalg.eigh(self.K)
        a0, w0 = vec.T @ x, vec.T @ v
        w = np.sqrt(lam)
        a = self.c * lam / 2
        wd = np.sqrt(w * w - a * a)
        e, cs, sn = np.exp(-a * t), np.cos(wd * t), np.sin(wd * t)
        return vec @ (e * (a0 * cs + (w0 + a * a0) / wd * sn))


class Work:
    def __init__(self):
        self.passes = 0.0


def vcycle(levels, l, b, work, smooth, weight):
    """One V-cycle from zero; `smooth` = (pre, post) weighted-Jacobi sweeps per level."""
    a, diag, _ = levels[l]
    share = a.shape[0] / levels[0][0].shape[0]
    x = np.zeros_like(b)
    if l == len(levels) - 1:
        for k in range(sum(smooth) + 2):
            x += weight * (b - a @ x) / diag[:, None]
            work.passes += share if k else 0
        return x
    for k in range(smooth[0]):
        x += weight * (b - a @ x if k else b) / diag[:, None]
        work.passes += share if k else 0
    r = b - a @ x if smooth[0] else b
    work.passes += share if smooth[0] else 0
    p = levels[l + 1][2]
    x += p @ vcycle(levels, l + 1, p.T @ r, work, smooth, weight)
    for _ in range(smooth[1]):
        x += weight * (b - a @ x) / diag[:, None]
        work.passes += share
    return x


def galerkin(a, interpolations):
    """(operator, its diagonal, the interpolation from it to the level above) per level."""
    levels = [(a, np.diag(a).copy(), None)]
    for p in interpolations:
        coarse = p.T @ levels[-1][0] @ p
        levels.append((coarse, np.diag(coarse).copy(), p))
    return levels


def closed_form(h, zeta):
    """The Jacobi closed form's p, q of src/integrate/harmonic.rs (omega0^2 = 2)."""
    a, wd = zeta * math.sqrt(2.0), math.sqrt(2.0 * (1 - zeta * zeta))
    e = math.exp(-a * h)
    return -2 * e * math.sin(wd * h) / wd, e * math.cos(wd * h) - 1 - a * e * math.sin(wd * h) / wd


def theta_step(system, theta, h, cycle=None, guess=False):
    """The theta-step, solved exactly (cycle None) or by one V-cycle (cycle = (smooth, weight)),
    started from zero or, with `guess`, from the closed form's Jacobi impulse."""
    k, c = system.K, system.c
    a = np.eye(system.n) + (theta * h * c + theta * theta * h * h) * k
    levels = galerkin(a, system.P)
    pc, qc = closed_form(h, system.zeta)

    def step(x, v, work):
        kx, kv = k @ x, k @ v
        work.passes += 1
        b = h * (-kx - c * kv - theta * h * kv)
        if cycle is None:
            dv = np.linalg.solve(a, b)
        elif guess:
            dv = (pc / 2) * kx + (qc / 2) * kv
            work.passes += 1
            dv = dv + vcycle(levels, 0, b - a @ dv, work, *cycle)
        else:
            dv = vcycle(levels, 0, b, work, *cycle)
        return x + h * (v + theta * dv), v + dv

    return step


def radius(system, step):
    eye = np.eye(2 * system.n)
    x, v = step(eye[:system.n], eye[system.n:], Work())
    return max(abs(np.linalg.eigvals(np.vstack([x, v]))))


def error(system, make, ratio):
    x, v = system.released()
    steps = round(16 / ratio)
    step, work = make(16 * HC / steps), Work()
    xs, vs = x[:, None], v[:, None]
    for _ in range(steps):
        xs, vs = step(xs, vs, work)
    reference = system.exact(x, v, 16 * HC)
    return math.sqrt(((xs[:, 0] - reference) ** 2).sum() / (system.n / system.dim)), work.passes / steps


VARIANTS = {
    "implicit Euler, solved exactly": lambda s, h: theta_step(s, 1.0, h),
    "trapezoidal (theta = 0.5), solved exactly": lambda s, h: theta_step(s, 0.5, h),
    "theta = 0.6, solved exactly": lambda s, h: theta_step(s, 0.6, h),
    "implicit Euler, 1 V-cycle, 1 post-sweep (w = 0.5)": lambda s, h: theta_step(s, 1.0, h, ((0, 1), 0.5)),
    "theta = 0.5, 1 V-cycle, 1 pre-sweep (w = 0.5)": lambda s, h: theta_step(s, 0.5, h, ((1, 0), 0.5)),
    "theta = 0.55, 1 V-cycle, 1 pre-sweep (w = 0.5)": lambda s, h: theta_step(s, 0.55, h, ((1, 0), 0.5)),
    "theta = 0.6, 1 V-cycle, 1 pre-sweep (w = 0.5)": lambda s, h: theta_step(s, 0.6, h, ((1, 0), 0.5)),
    "theta = 0.6, 1 V-cycle, 1 pre-sweep (w = 0.6)": lambda s, h: theta_step(s, 0.6, h, ((1, 0), 0.6)),
    "theta = 0.6, 1 V-cycle, 1 pre- and 1 post-sweep (w = 0.5)":
        lambda s, h: theta_step(s, 0.6, h, ((1, 1), 0.5)),
    "theta = 0.6, 1 V-cycle from the closed form's impulse, 1 pre-sweep (w = 0.5)":
        lambda s, h: theta_step(s, 0.6, h, ((1, 0), 0.5), guess=True),
}


AGGREGATED = (
    "theta = 0.6, 1 V-cycle, 1 pre-sweep (w = 0.5)",
    "theta = 0.6, 1 V-cycle, 1 pre- and 1 post-sweep (w = 0.5)",
)


def main():
    for label, transfer in (("unsmoothed", aggregate1), ("smoothed", smoothed_aggregation)):
        print(f"{label} aggregation instead of linear interpolation (stable at every h/h_c, "
              "zeta = 0 / 0.2; errors at " + ", ".join(f"{r}" for r in ERROR_AT) + " h_c):\n")
        for kind in ("chain", "cloth"):
            systems = {z: System(kind, z, transfer) for z in (0.0, 0.2)}
            for name in AGGREGATED:
                make = VARIANTS[name]
                stable = ["yes" if all(radius(s, make(s, p * HC)) <= 1.001 for p in POINTS)
                          else "no" for s in systems.values()]
                errs = [error(systems[0.2], lambda h: make(systems[0.2], h), r) for r in ERROR_AT]
                print(f"- {kind}, {name}: {stable[0]} / {stable[1]}; "
                      + ", ".join(f"{e:.4f}" for e, _ in errs) + f" ({errs[0][1]:.2f} passes)",
                      flush=True)
        print()
    for kind in ("chain", "cloth"):
        title = "chain of 20" if kind == "chain" else "cloth 16x16 (in-plane, linearised at rest)"
        print(f"\n### {title}\n")
        print("| variant | passes | stable at h/h_c, zeta = 0 | zeta = 0.2 | "
              + " | ".join(f"error at {r} h_c" for r in ERROR_AT) + " |")
        print("|---|---|---|---|" + "---|" * len(ERROR_AT))
        systems = {z: System(kind, z) for z in (0.0, 0.2)}
        x, _ = systems[0.2].released()
        never = math.sqrt(((x - systems[0.2].exact(x, 0 * x, 16 * HC)) ** 2).sum() / (len(x) / systems[0.2].dim))
        print(f"| never moving | 0 | | | " + " | ".join(f"{never:.3f}" for _ in ERROR_AT) + " |")
        for name, make in VARIANTS.items():
            cells, passes = [], 0
            for z, system in systems.items():
                ok = [p for p in POINTS if radius(system, make(system, p * HC)) <= 1.001]
                cells.append("all" if len(ok) == len(POINTS) else ", ".join(str(p) for p in ok) or "none")
            errs = []
            for r in ERROR_AT:
                e, passes = error(systems[0.2], lambda h: make(systems[0.2], h), r)
                errs.append(f"{e:.4f}" if math.isfinite(e) and e < 10 else "✗")
            print(f"| {name} | {passes:.2f} | {cells[0]} | {cells[1]} | " + " | ".join(errs) + " |",
                  flush=True)


if __name__ == "__main__":
    sys.exit(main())
