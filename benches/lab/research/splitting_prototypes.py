"""Research prototypes for issue 3's large-step target, on the 1-D linearised chain.

Chain of 20 unit masses, the first hung from a pin, unit springs, damping ratio zeta per
spring (two-body reduced mass). A variant is "stable" at h/h_c when a random state's norm
grows by at most 0.1 % per step over 3,000 steps (h_c = pi / omega0 of a free-free spring).
Then, for a few variants, the RMS position error on the damped chain against an RK4 reference.
Pure Python, no dependencies: `python3 benches/lab/research/splitting_prototypes.py`.
"""
import math
import random

N = 20
POINTS = (0.25, 0.5, 0.75, 1, 1.5, 2, 2.0625, 4, 6.0625, 8.0625)


def propagator(w2, a, h):
    """(p, q, r, s) of src/integrate/harmonic.rs: phi = p d + q d', D = r d + s d'."""
    b2 = w2 - a * a
    e = math.exp(-a * h)
    if b2 > 0:
        b = math.sqrt(b2)
        c, s = math.cos(b * h), math.sin(b * h) / b
    else:
        g = math.sqrt(-b2)
        c, s = math.cosh(g * h), math.sinh(g * h) / g
    return (-w2 * e * s, e * c - 1 - a * e * s, e * c - 1 + a * e * s, e * s - h)


def oscillate(u, w, h, omega, zeta):
    """Exact u'' + 2 zeta omega u' + omega^2 u = 0 over h (under-damped)."""
    wd = omega * math.sqrt(1 - zeta * zeta)
    e = math.exp(-zeta * omega * h)
    c, s = math.cos(wd * h), math.sin(wd * h)
    return (e * (u * c + (w + zeta * omega * u) / wd * s),
            e * (w * c - (omega * omega * u + zeta * omega * w) / wd * s))


def spring_sweeps(x, v, h, zeta, displacement, sweeps=1, split=False, iterated=False, rho=0.0):
    """Coloured Gauss-Seidel over springs with the closed form, `sweeps` sweeps alternating
    direction. `displacement` adds the closed form's displacement D beyond free drift,
    accumulated over the sweeps (x += h v0 + sum D); otherwise x += h v_new.
    - one sweep: harmonic-gs;
    - `split`: each sweep applies 1/sweeps of the impulse (and of D): harmonic-sgs;
    - `iterated`: each sweep re-solves every spring from the start stretch and the stretch rate
      its neighbours' latest impulses give it (its own removed) and applies the difference to
      what it applied before: a fixed-point iteration toward a step in which every spring sees
      the others' impulses, implicitly coupled; with `rho` > 0 the sweeps are
      Chebyshev-accelerated over the applied impulses for an assumed spectral radius `rho`."""
    inv = [0.0] + [1.0] * N
    v0, dx = v[:], [0.0] * (N + 1)
    applied = [(0.0, 0.0)] * N
    prev, omega = applied[:], 1.0
    scale = 1 / sweeps if split else 1
    for k in range(sweeps):
        before = applied[:]
        order = list(range(0, N, 2)) + list(range(1, N, 2))
        if k % 2 == 1:
            order.reverse()
        for a in order:
            b = a + 1
            mu = 1 / (inv[a] + inv[b])
            p, q, r, s = propagator(1 / mu, zeta / math.sqrt(mu), h)
            wa = inv[a] / (inv[a] + inv[b])
            old_phi, old_d = applied[a] if iterated else (0.0, 0.0)
            d, dd = x[b] - x[a], v[b] - v[a] - old_phi
            phi, big_d = scale * (p * d + q * dd), scale * (r * d + s * dd)
            v[a] -= wa * (phi - old_phi)
            v[b] += (1 - wa) * (phi - old_phi)
            if displacement:
                dx[a] -= wa * (big_d - old_d)
                dx[b] += (1 - wa) * (big_d - old_d)
            applied[a] = (phi, big_d)
        if rho > 0 and k > 0:
            omega = 2 / (2 - rho * rho) if k == 1 else 4 / (4 - rho * rho * omega)
            applied = [tuple(omega * (n - o) + o for n, o in zip(applied[a], prev[a]))
                       for a in range(N)]
            v[:], dx = v0[:], [0.0] * (N + 1)
            for a, (phi, big_d) in enumerate(applied):
                wa = inv[a] / (inv[a] + inv[a + 1])
                v[a] -= wa * phi
                v[a + 1] += (1 - wa) * phi
                dx[a] -= wa * big_d
                dx[a + 1] += (1 - wa) * big_d
        prev = before
    for i in range(1, N + 1):
        x[i] += h * (v0[i] if displacement else v[i]) + dx[i]


class WarmStart:
    """The previous step's acceleration, for vertex block descent's first guess (reset when a
    new run starts: another state list, step or damping)."""

    def __init__(self, beta):
        self.beta, self.run, self.accel = beta, None, None

    def guess(self, x, y, h, zeta):
        if self.run is None or self.run[0] is not x or self.run[1:] != (h, zeta):
            self.run, self.accel = (x, h, zeta), [0.0] * (N + 1)
        return [y[i] + self.beta * h * h * self.accel[i] for i in range(N + 1)]


def vertex_block_descent(x, v, h, zeta, iterations, rho=0.0, warm=None):
    """Vertex block descent on implicit Euler's incremental potential (no closed form): start
    from the inertial guess y = x + h v, then `iterations` coloured Gauss-Seidel passes, each
    particle minimising over its own position with its neighbours fixed (spring and damping
    terms of implicit Euler), and v = (x_new - x) / h. With `rho` > 0 the passes are
    Chebyshev-accelerated for an assumed spectral radius `rho` of the plain pass. With `warm`
    (a WarmStart) the first guess adds beta h^2 times the previous step's acceleration, as
    the vertex block descent paper's adaptive initialisation does (there along gravity)."""
    c = 2 * zeta * math.sqrt(0.5)  # per-spring damping for the pair's reduced mass 1/2
    start, v0 = x[:], v[:]
    y = [x[i] + h * v[i] for i in range(N + 1)]
    y[0] = x[0]
    new = y[:] if warm is None else warm.guess(x, y, h, zeta)
    new[0] = x[0]
    prev, omega = y[:], 1.0
    for k in range(iterations):
        before = new[:]
        for first in (1, 2):
            for i in range(first, N + 1, 2):
                nb = [j for j in (i - 1, i + 1) if 0 <= j <= N]
                stiff = len(nb) * (1 + c / h)
                rhs = y[i] / (h * h)
                for j in nb:
                    # spring toward x_j; damping toward the neighbour's motion over the step
                    rhs += new[j] + (c / h) * (start[i] + new[j] - start[j])
                new[i] = rhs / (1 / (h * h) + stiff)
        if rho > 0 and k > 0:
            omega = 2 / (2 - rho * rho) if k == 1 else 4 / (4 - rho * rho * omega)
            new = [omega * (new[i] - prev[i]) + prev[i] for i in range(N + 1)]
        prev = before
    for i in range(1, N + 1):
        v[i] = (new[i] - start[i]) / h
        x[i] = new[i]
        if warm is not None:
            warm.accel[i] = (v[i] - v0[i]) / h


def implicit_euler(x, v, h, zeta):
    """Implicit Euler solved exactly (Gauss-Seidel to convergence): the target VBD approaches."""
    vertex_block_descent(x, v, h, zeta, 400)


def vertex_exact(x, v, h, zeta, neighbours):
    """Coloured Gauss-Seidel over particles: each particle follows its exact oscillation
    about its neighbours, which either move uniformly from where they are now ("moving"),
    move uniformly from where they started the step ("moving from start"), or stay put
    ("frozen")."""
    c = 2 * zeta * math.sqrt(0.5)
    start = x[:]
    for first in (1, 2):
        for i in range(first, N + 1, 2):
            nb = [j for j in (i - 1, i + 1) if 0 <= j <= N]
            n = len(nb)
            pos = start if neighbours == "moving from start" else x
            cx = sum(pos[j] for j in nb) / n
            cv = sum(v[j] for j in nb) / n
            omega, z = math.sqrt(n), n * c / (2 * math.sqrt(n))
            if neighbours == "frozen":
                off = n * c * cv / n
                u, w = oscillate(x[i] - cx - off, v[i], h, omega, z)
                x[i], v[i] = cx + off + u, w
            else:
                u, w = oscillate(pos[i] - cx, v[i] - cv, h, omega, z)
                x[i], v[i] = cx + cv * h + u, cv + w


def growth(step, hr, zeta, steps=3000):
    h = hr * math.pi / math.sqrt(2.0)
    random.seed(3)
    x = [0.0] + [random.uniform(-1, 1) for _ in range(N)]
    v = [0.0] + [random.uniform(-1, 1) for _ in range(N)]
    n0 = math.sqrt(sum(a * a for a in x + v))
    for _ in range(steps):
        step(x, v, h, zeta)
        n = math.sqrt(sum(a * a for a in x + v))
        if not math.isfinite(n) or n > 1e12 * n0:
            return math.inf
    return (n / n0) ** (1 / steps)


def translation_kept(step):
    """Galilean invariance: a chain at rest length moving uniformly keeps its velocity (read at
    the middle particle after one step of 1.3 h_c, too soon for the pin to reach it)."""
    x, v = [0.0] * (N + 1), [1.0] * (N + 1)
    step(x, v, 1.3 * math.pi / math.sqrt(2.0), 0.0)
    return abs(v[N // 2] - 1.0) < 1e-9


def rk4_reference(x, v, h, zeta, steps):
    """Classical RK4 on the linear chain: the fine-step reference of `errors`."""
    c = 2 * zeta * math.sqrt(0.5)

    def deriv(x, v):
        a = [0.0] * (N + 1)
        for s in range(N):
            f = (x[s + 1] - x[s]) + c * (v[s + 1] - v[s])
            a[s] += f
            a[s + 1] -= f
        a[0] = 0.0
        return v[:], a

    for _ in range(steps):
        k1 = deriv(x, v)
        k2 = deriv([x[i] + h / 2 * k1[0][i] for i in range(N + 1)],
                   [v[i] + h / 2 * k1[1][i] for i in range(N + 1)])
        k3 = deriv([x[i] + h / 2 * k2[0][i] for i in range(N + 1)],
                   [v[i] + h / 2 * k2[1][i] for i in range(N + 1)])
        k4 = deriv([x[i] + h * k3[0][i] for i in range(N + 1)],
                   [v[i] + h * k3[1][i] for i in range(N + 1)])
        for i in range(1, N + 1):
            x[i] += h / 6 * (k1[0][i] + 2 * k2[0][i] + 2 * k3[0][i] + k4[0][i])
            v[i] += h / 6 * (k1[1][i] + 2 * k2[1][i] + 2 * k3[1][i] + k4[1][i])


def errors(variants, ratios=(0.5, 1, 2, 4), zeta=0.2):
    """RMS position error after 16 h_c of motion from a smooth stretch, released at rest,
    against RK4 at h_c/200; "never moving" is the initial state's error."""
    hc = math.pi / math.sqrt(2.0)
    init = lambda: ([0.0] + [0.3 * math.sin(math.pi * i / (2 * N)) for i in range(1, N + 1)],
                    [0.0] * (N + 1))
    xr, vr = init()
    rk4_reference(xr, vr, hc / 200, zeta, 3200)
    rms = lambda x: math.sqrt(sum((x[i] - xr[i]) ** 2 for i in range(N + 1)) / N)
    print(f"| variant (zeta = {zeta}) | " + " | ".join(f"{r} h_c" for r in ratios) + " |")
    print("|---|" + "---|" * len(ratios))
    print("| never moving | " + " | ".join(f"{rms(init()[0]):.3f}" for _ in ratios) + " |")
    for name, (step, limit) in variants.items():
        cells = []
        for r in ratios:
            if r > limit:
                cells.append("unstable")
                continue
            x, v = init()
            for _ in range(round(16 / r)):
                step(x, v, r * hc, zeta)
            e = rms(x)
            cells.append(f"{e:.3f}" if math.isfinite(e) and e < 10 else "✗")
        print(f"| {name} | " + " | ".join(cells) + " |")


VARIANTS = {
    "harmonic-gs (plain update, for reference)": lambda x, v, h, z: spring_sweeps(x, v, h, z, False),
    "spring GS + exact displacement": lambda x, v, h, z: spring_sweeps(x, v, h, z, True),
    "harmonic-sgs (plain update, for reference)":
        lambda x, v, h, z: spring_sweeps(x, v, h, z, False, 2, split=True),
    "spring SGS + exact displacement": lambda x, v, h, z: spring_sweeps(x, v, h, z, True, 2, split=True),
    "iterated spring GS, 2 sweeps": lambda x, v, h, z: spring_sweeps(x, v, h, z, False, 2, iterated=True),
    "iterated spring GS, 4 sweeps": lambda x, v, h, z: spring_sweeps(x, v, h, z, False, 4, iterated=True),
    "iterated spring GS, 4 Chebyshev sweeps (rho = 0.5)":
        lambda x, v, h, z: spring_sweeps(x, v, h, z, False, 4, iterated=True, rho=0.5),
    "iterated spring GS, 4 Chebyshev sweeps (rho = 0.9)":
        lambda x, v, h, z: spring_sweeps(x, v, h, z, False, 4, iterated=True, rho=0.9),
    "iterated spring GS + exact displacement, 2 sweeps":
        lambda x, v, h, z: spring_sweeps(x, v, h, z, True, 2, iterated=True),
    "iterated spring GS + exact displacement, 4 sweeps":
        lambda x, v, h, z: spring_sweeps(x, v, h, z, True, 4, iterated=True),
    "vertex block descent (implicit Euler), 1 pass":
        lambda x, v, h, z: vertex_block_descent(x, v, h, z, 1),
    "vertex block descent (implicit Euler), 2 passes":
        lambda x, v, h, z: vertex_block_descent(x, v, h, z, 2),
    "vertex block descent (implicit Euler), 3 passes":
        lambda x, v, h, z: vertex_block_descent(x, v, h, z, 3),
    "vertex block descent, 3 Chebyshev passes (rho = 0.8)":
        lambda x, v, h, z: vertex_block_descent(x, v, h, z, 3, 0.8),
    "vertex block descent, 3 Chebyshev passes (rho = 0.9)":
        lambda x, v, h, z: vertex_block_descent(x, v, h, z, 3, 0.9),
    "vertex block descent, warm start (beta = 1), 2 passes":
        lambda x, v, h, z, w=WarmStart(1.0): vertex_block_descent(x, v, h, z, 2, warm=w),
    "vertex block descent, warm start (beta = 1), 3 passes":
        lambda x, v, h, z, w=WarmStart(1.0): vertex_block_descent(x, v, h, z, 3, warm=w),
    "vertex block descent, warm start (beta = 0.6), 3 passes":
        lambda x, v, h, z, w=WarmStart(0.6): vertex_block_descent(x, v, h, z, 3, warm=w),
    "vertex block descent, warm start (beta = 0.5), 3 passes":
        lambda x, v, h, z, w=WarmStart(0.5): vertex_block_descent(x, v, h, z, 3, warm=w),
    "vertex block descent, warm start (beta = 0.7), 4 Chebyshev passes (rho = 0.7)":
        lambda x, v, h, z, w=WarmStart(0.7): vertex_block_descent(x, v, h, z, 4, 0.7, warm=w),
    "vertex exact, neighbours moving": lambda x, v, h, z: vertex_exact(x, v, h, z, "moving"),
    "vertex exact, neighbours moving from start":
        lambda x, v, h, z: vertex_exact(x, v, h, z, "moving from start"),
    "vertex exact, neighbours frozen": lambda x, v, h, z: vertex_exact(x, v, h, z, "frozen"),
}

if __name__ == "__main__":
    print("| variant | zeta | " + " | ".join(str(p) for p in POINTS) + " | uniform motion kept |")
    print("|---|---|" + "---|" * len(POINTS) + "---|")
    for name, step in VARIANTS.items():
        kept = "yes" if translation_kept(step) else "no"
        for zeta in (0.0, 0.2):
            cells = ["✓" if growth(step, p, zeta) <= 1.001 else "✗" for p in POINTS]
            print(f"| {name} | {zeta} | " + " | ".join(cells) + f" | {kept} |")
    print()
    vbd = "vertex block descent (implicit Euler), {} passes"
    errors({
        "implicit Euler (solved to convergence)": (implicit_euler, math.inf),
        "vertex block descent, 2 passes": (VARIANTS[vbd.format(2)], math.inf),
        "vertex block descent, 3 passes": (VARIANTS[vbd.format(3)], math.inf),
        "vertex block descent, 3 Chebyshev passes (rho = 0.8)":
            (VARIANTS["vertex block descent, 3 Chebyshev passes (rho = 0.8)"], math.inf),
        # at zeta = 0.2 stable to 2.0625 h_c (table above)
        "vertex block descent, 3 Chebyshev passes (rho = 0.9)":
            (VARIANTS["vertex block descent, 3 Chebyshev passes (rho = 0.9)"], 2.0625),
        # warm starts: stable at zeta = 0.2 to 0.75, 2.0625, every point and 2.0625 (table above)
        "vertex block descent, warm start (beta = 1), 3 passes":
            (VARIANTS["vertex block descent, warm start (beta = 1), 3 passes"], 0.75),
        "vertex block descent, warm start (beta = 0.6), 3 passes":
            (VARIANTS["vertex block descent, warm start (beta = 0.6), 3 passes"], 2.0625),
        "vertex block descent, warm start (beta = 0.5), 3 passes":
            (VARIANTS["vertex block descent, warm start (beta = 0.5), 3 passes"], math.inf),
        "vertex block descent, warm start (beta = 0.7), 4 Chebyshev passes (rho = 0.7)":
            (VARIANTS["vertex block descent, warm start (beta = 0.7), 4 Chebyshev passes (rho = 0.7)"],
             2.0625),
        # at zeta = 0.2 stable to 1 h_c (table above)
        "harmonic-sgs": (VARIANTS["harmonic-sgs (plain update, for reference)"], 1),
    })
