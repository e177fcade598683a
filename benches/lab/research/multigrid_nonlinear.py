"""Nonlinear 3-D check of multigrid_prototypes.py's one-V-cycle theta-step.

A 16x16 cloth (structural, shear and bend springs, unit masses and stiffness), flat, pinned at two
corners, falls under gravity and swings (large rotation) for 200 h_c. Each step linearises the
springs at the current state (Baraff-Witkin Jacobian, the geometric term clamped at zero) and
rebuilds the Galerkin levels (or keeps fixed isotropic ones); the linear solve is exact or one
V-cycle. RMS position error per particle at the end against symplectic Euler at h_c/80 (its
distance to h_c/40 is printed).
`python3 benches/lab/research/multigrid_nonlinear.py [zeta] [gravity] [duration] [variant filter]`
(numpy; about 5 minutes for every variant on an idle 2-core machine).
"""
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from multigrid_prototypes import (HC, Work, cloth_springs, galerkin, hierarchy,  # noqa: E402
                                  smoothed_aggregation, vcycle)  # noqa: E402
S = 16; n = S * S
zeta = float(sys.argv[1]) if len(sys.argv) > 1 else 0.2
g = float(sys.argv[2]) if len(sys.argv) > 2 else 1e-3
c = 2 * zeta * math.sqrt(0.5)
pos0 = np.array([[j, i, 0.0] for i in range(S) for j in range(S)], float)
sa, sb = (np.array(k) for k in zip(*((a, b) for a, b, _ in cloth_springs(S))))
L = np.linalg.norm(pos0[sb] - pos0[sa], axis=1)
pins = np.array([0, S - 1])
free = np.ones(n, bool); free[pins] = False
grav = np.zeros((n, 3)); grav[:, 2] = -g

def force(x, v):
    d = x[sb] - x[sa]; l = np.linalg.norm(d, axis=1); u = d / l[:, None]
    rel = np.einsum('ij,ij->i', v[sb] - v[sa], u)
    f = (l - L + c * rel)[:, None] * u
    F = grav.copy()
    np.add.at(F, sa, f); np.add.at(F, sb, -f)
    F[pins] = 0
    return F

def jac(x):
    d = x[sb] - x[sa]; l = np.linalg.norm(d, axis=1); u = d / l[:, None]
    uu = np.einsum('si,sj->sij', u, u)
    Ks = uu + np.maximum(1 - L / l, 0)[:, None, None] * (np.eye(3) - uu)   # clamped geometric term
    Cs = c * uu
    return Ks, Cs

def assemble(blocks):
    A = np.zeros((3 * n, 3 * n))
    for (p, q, sgn) in ((sa, sa, 1), (sb, sb, 1), (sa, sb, -1), (sb, sa, -1)):
        for r in range(3):
            for cc in range(3):
                np.add.at(A, (3 * p + r, 3 * q + cc), sgn * blocks[:, r, cc])
    return A

fd = np.repeat(free, 3)

LEVELS = hierarchy((S, S), set(np.nonzero(free)[0]), 3)
_lap = np.zeros((n, n))
np.add.at(_lap, (sa, sa), 1)
np.add.at(_lap, (sb, sb), 1)
np.add.at(_lap, (sa, sb), -1)
np.add.at(_lap, (sb, sa), -1)
AGGREGATES = smoothed_aggregation(_lap[np.ix_(free, free)], 3)

ISOTROPIC = {}


def isotropic_levels(h, theta, share, transfers):
    """Coarse levels fixed for the run: the Galerkin levels of the rest state's operator with every
    spring's block replaced by `share` of its stiffness in every direction (rotation-invariant)."""
    key = (h, theta, share, id(transfers))
    if key not in ISOTROPIC:
        ones = np.broadcast_to(share * np.eye(3), (len(sa), 3, 3))
        k = assemble(ones)[np.ix_(fd, fd)]
        a = np.eye(fd.sum()) + (theta * h * c + theta * theta * h * h) * k
        ISOTROPIC[key] = galerkin(a, transfers)
    return ISOTROPIC[key]


def theta_step(x, v, h, theta, cycle, coarse=None, transfers=LEVELS):
    """One linearised theta-step; the coarse levels are the current operator's Galerkin levels,
    or with `coarse` = share the fixed isotropic ones of `isotropic_levels`."""
    Ks, Cs = jac(x)
    K = assemble(Ks)[np.ix_(fd, fd)]; C = assemble(Cs)[np.ix_(fd, fd)]
    A = np.eye(fd.sum()) + theta * h * C + theta * theta * h * h * K
    F = force(x, v)
    b = h * (F[free].ravel() - theta * h * (K @ v[free].ravel()))
    if cycle is None:
        dv = np.linalg.solve(A, b)
    else:
        if coarse is None:
            levels = galerkin(A, transfers)
        else:
            levels = [(A, np.diag(A).copy(), None)] + isotropic_levels(h, theta, coarse, transfers)[1:]
        dv = vcycle(levels, 0, b[:, None], Work(), *cycle)[:, 0]
    v1 = v.copy(); v1[free] += dv.reshape(-1, 3)
    x1 = x.copy(); x1[free] += h * (v[free] + theta * dv.reshape(-1, 3))
    return x1, v1

def se_step(x, v, h):
    v1 = v + h * force(x, v); v1[pins] = 0
    return x + h * v1, v1

def run(stepper, h, T):
    x, v = pos0.copy(), np.zeros((n, 3))
    steps = round(T / h); h = T / steps
    for k in range(steps):
        x, v = stepper(x, v, h)
        if not np.all(np.isfinite(x)) or np.abs(x).max() > 1e4: return None, k
    return x, steps

T = float(sys.argv[3]) if len(sys.argv) > 3 else 200 * HC
t0 = time.time()
ref, _ = run(se_step, HC / 40, T)
ref2, _ = run(se_step, HC / 80, T)
rms = lambda a, b: math.sqrt(((a - b) ** 2).sum(axis=1).mean())
print(f"zeta {zeta} g {g} T {T/HC:.0f} h_c; ref halving diff {rms(ref, ref2):.2e}; never moving {rms(pos0, ref2):.3f}; lowest point z = {ref2[:,2].min():.3f}", flush=True)
ref = ref2
VARIANTS = {
    'implicit Euler, solved exactly': lambda x, v, h: theta_step(x, v, h, 1.0, None),
    'theta = 0.6, solved exactly': lambda x, v, h: theta_step(x, v, h, 0.6, None),
    'trapezoidal, solved exactly': lambda x, v, h: theta_step(x, v, h, 0.5, None),
    'theta = 0.6, 1 V-cycle, 1 pre-sweep': lambda x, v, h: theta_step(x, v, h, 0.6, ((1, 0), 0.5)),
    'theta = 0.6, 1 V-cycle, 1 pre- and 1 post-sweep':
        lambda x, v, h: theta_step(x, v, h, 0.6, ((1, 1), 0.5)),
    'implicit Euler, 1 V-cycle, 1 post-sweep': lambda x, v, h: theta_step(x, v, h, 1.0, ((0, 1), 0.5)),
}
for share in (1 / 3, 0.5, 1.0):
    VARIANTS[f'theta = 0.6, 1 V-cycle, 1 pre- and 1 post-sweep, fixed isotropic coarse levels ({share:.2f})'] = \
        lambda x, v, h, share=share: theta_step(x, v, h, 0.6, ((1, 1), 0.5), share)
for sweeps, label in (((1, 0), '1 pre-sweep'), ((1, 1), '1 pre- and 1 post-sweep')):
    VARIANTS[f'theta = 0.6, 1 V-cycle, {label}, fixed isotropic coarse levels (1.00), smoothed aggregation'] = \
        lambda x, v, h, sweeps=sweeps: theta_step(x, v, h, 0.6, (sweeps, 0.5), 1.0, AGGREGATES)
pick = sys.argv[4] if len(sys.argv) > 4 else ''
for name, st in VARIANTS.items():
    if pick not in name:
        continue
    cells = []
    for r in (0.5, 1, 2, 4):
        x, k = run(st, r * HC, T)
        cells.append(f"{r}: " + (f"{rms(x, ref):.4f}" if x is not None else f"blew up at step {k}"))
    print(f"{name:28s} " + " | ".join(cells), f"({time.time()-t0:.0f}s)", flush=True)
