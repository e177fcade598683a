"""Nonlinear 3-D check of multigrid_prototypes.py's one-V-cycle theta-step.

A 16x16 cloth (structural, shear and bend springs, unit masses and stiffness), flat, pinned at two
corners, falls under gravity and swings (large rotation) for 200 h_c. Each step linearises the
springs at the current state (Baraff-Witkin Jacobian, the geometric term clamped at zero) and
rebuilds the Galerkin levels; the linear solve is exact or one V-cycle. RMS position error per
particle at the end against symplectic Euler at h_c/80 (its distance to h_c/40 is printed).
`python3 benches/research/multigrid_nonlinear.py [zeta] [gravity]` (numpy, about 2 minutes).
"""
import numpy as np, math, sys, time
S = 16; n = S * S
HC = math.pi / math.sqrt(2.0)
zeta = float(sys.argv[1]) if len(sys.argv) > 1 else 0.2
g = float(sys.argv[2]) if len(sys.argv) > 2 else 1e-3
c = 2 * zeta * math.sqrt(0.5)
pos0 = np.array([[j, i, 0.0] for i in range(S) for j in range(S)], float)
sa, sb = [], []
for i in range(S):
    for j in range(S):
        for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1), (0, 2), (2, 0)):
            a, b = i + di, j + dj
            if 0 <= a < S and 0 <= b < S:
                sa.append(i * S + j); sb.append(a * S + b)
sa, sb = np.array(sa), np.array(sb)
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

def interp1(nf):
    nc = (nf + 1) // 2; P = np.zeros((nf, nc))
    for f in range(nf):
        if f % 2 == 0: P[f, f // 2] = 1
        elif (f + 1) // 2 < nc: P[f, (f - 1) // 2] = P[f, (f + 1) // 2] = 0.5
        else: P[f, (f - 1) // 2] = 1
    return P

# hierarchy over free dofs
Ps = []
fshape, ffree = (S, S), set(np.nonzero(free)[0])
while fshape[0] * fshape[1] > 4:
    pn = np.kron(interp1(fshape[0]), interp1(fshape[1]))
    cs = tuple((s + 1) // 2 for s in fshape)
    at = lambda cn, cs=cs, fs=fshape: 2 * (cn // cs[1]) * fs[1] + 2 * (cn % cs[1])
    cfree = {cn for cn in range(cs[0] * cs[1]) if at(cn) in ffree}
    rows = [3 * f + k for f in sorted(ffree) for k in range(3)]
    cols = [3 * f + k for f in sorted(cfree) for k in range(3)]
    Ps.append(np.kron(pn, np.eye(3))[np.ix_(rows, cols)])
    fshape, ffree = cs, cfree

def vcycle(levels, l, b, smooth, w):
    A, D = levels[l][0], levels[l][1]
    x = np.zeros_like(b)
    if l == len(levels) - 1:
        for k in range(sum(smooth) + 2): x += w * (b - A @ x) / D
        return x
    for k in range(smooth[0]): x += w * ((b - A @ x) if k else b) / D
    r = b - A @ x if smooth[0] else b
    P = levels[l + 1][2]
    x += P @ vcycle(levels, l + 1, P.T @ r, smooth, w)
    for _ in range(smooth[1]): x += w * (b - A @ x) / D
    return x

def theta_step(x, v, h, theta, cycle):
    Ks, Cs = jac(x)
    K = assemble(Ks)[np.ix_(fd, fd)]; C = assemble(Cs)[np.ix_(fd, fd)]
    A = np.eye(fd.sum()) + theta * h * C + theta * theta * h * h * K
    F = force(x, v)
    b = h * (F[free].ravel() - theta * h * (K @ v[free].ravel()))
    if cycle is None:
        dv = np.linalg.solve(A, b)
    else:
        levels = [(A, np.diag(A).copy(), None)]
        for P in Ps:
            Ac = P.T @ levels[-1][0] @ P
            levels.append((Ac, np.diag(Ac).copy(), P))
        dv = vcycle(levels, 0, b, *cycle)
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
for name, st in (('IE exact', lambda x, v, h: theta_step(x, v, h, 1.0, None)),
                 ('theta0.6 exact', lambda x, v, h: theta_step(x, v, h, 0.6, None)),
                 ('trap exact', lambda x, v, h: theta_step(x, v, h, 0.5, None)),
                 ('theta0.6 1V pre1 w0.5', lambda x, v, h: theta_step(x, v, h, 0.6, ((1, 0), 0.5))),
                 ('theta0.6 1V pre1post1 w0.5', lambda x, v, h: theta_step(x, v, h, 0.6, ((1, 1), 0.5))),
                 ('IE 1V post1 w0.5', lambda x, v, h: theta_step(x, v, h, 1.0, ((0, 1), 0.5)))):
    cells = []
    for r in (0.5, 1, 2, 4):
        x, k = run(st, r * HC, T)
        cells.append(f"{r}: " + (f"{rms(x, ref):.4f}" if x is not None else f"blew up at step {k}"))
    print(f"{name:28s} " + " | ".join(cells), f"({time.time()-t0:.0f}s)", flush=True)
