//! Semantic checks; each problem names its entry.

use super::{Anchor, Scene, SpringSpec, MAX_PARTICLES, V3};
use crate::error::Issue;
use crate::integrate::Integrator;

struct Issues(Vec<Issue>);

impl Issues {
    fn push(&mut self, location: impl Into<String>, message: impl Into<String>) {
        self.0.push(Issue {
            location: location.into(),
            message: message.into(),
        });
    }
    fn positive(&mut self, location: impl Into<String>, v: f64) {
        if !(v.is_finite() && v > 0.0) {
            self.push(location, format!("must be finite and > 0, got {v}"));
        }
    }
    fn non_negative(&mut self, location: impl Into<String>, v: f64) {
        if !(v.is_finite() && v >= 0.0) {
            self.push(location, format!("must be finite and ≥ 0, got {v}"));
        }
    }
    fn finite(&mut self, location: impl Into<String>, v: V3) {
        if !v.iter().all(|c| c.is_finite()) {
            self.push(location, format!("must be finite, got {v:?}"));
        }
    }
    fn spec(&mut self, at: &str, s: &SpringSpec) {
        match (s.stiffness, s.frequency) {
            (Some(k), None) => self.non_negative(format!("{at}.stiffness"), k),
            (None, Some(f)) => self.positive(format!("{at}.frequency"), f),
            (Some(_), Some(_)) => self.push(at, "give `stiffness` or `frequency`, not both"),
            (None, None) => self.push(at, "needs `stiffness` (N/m) or `frequency` (Hz)"),
        }
        match (s.damping, s.damping_ratio) {
            (Some(c), None) => self.non_negative(format!("{at}.damping"), c),
            (None, Some(z)) => self.non_negative(format!("{at}.damping_ratio"), z),
            (Some(_), Some(_)) => self.push(at, "give `damping` or `damping_ratio`, not both"),
            (None, None) => {}
        }
    }
}

impl Scene {
    /// Every semantic problem, in file order; empty when the scene is sound.
    pub fn validate(&self) -> Vec<Issue> {
        let mut is = Issues(Vec::new());
        is.positive("dt", self.dt);
        if self.substeps == Some(0) {
            is.push("substeps", "must be ≥ 1");
        }
        is.finite("gravity", self.gravity);
        if let Some(name) = &self.integrator {
            if name.parse::<Integrator>().is_err() {
                let known: Vec<_> = Integrator::ALL.iter().map(|i| i.name()).collect();
                is.push(
                    "integrator",
                    format!("unknown `{name}` (known: {})", known.join(", ")),
                );
            }
        }
        if let Some(name) = &self.backend {
            if name.parse::<crate::Backend>().is_err() {
                is.push(
                    "backend",
                    format!("unknown `{name}` (known: cpu, gpu, auto)"),
                );
            }
        }
        if let Some(t) = self.seconds {
            is.positive("seconds", t);
        }
        for (i, p) in self.particles.iter().enumerate() {
            is.finite(format!("particles[{i}].position"), p.position);
            is.finite(format!("particles[{i}].velocity"), p.velocity);
            is.positive(format!("particles[{i}].mass"), p.mass);
        }
        let n = self.particles.len();
        for (k, s) in self.springs.iter().enumerate() {
            let at = format!("springs[{k}]");
            let mut ends_ok = true;
            for (end, idx) in [("a", s.a), ("b", s.b)] {
                if idx >= n {
                    is.push(
                        format!("{at}.{end}"),
                        format!("particle {idx} does not exist ({n} particles)"),
                    );
                    ends_ok = false;
                }
            }
            if s.a == s.b {
                is.push(&at, format!("both ends are particle {}", s.a));
                ends_ok = false;
            }
            is.spec(&at, &s.spec());
            if let Some(l) = s.rest_length {
                is.positive(format!("{at}.rest_length"), l);
            }
            if ends_ok {
                let (pa, pb) = (self.particles[s.a].position, self.particles[s.b].position);
                let d = (0..3).map(|c| (pb[c] - pa[c]).powi(2)).sum::<f64>().sqrt();
                if d == 0.0 {
                    let what = if s.rest_length.is_none() {
                        "zero-length spring with no rest_length: its ends start at the same point"
                    } else {
                        "its ends start at the same point, so its direction is undefined"
                    };
                    is.push(&at, what);
                }
            }
        }
        for (i, c) in self.cloths.iter().enumerate() {
            let at = format!("cloths[{i}]");
            is.finite(format!("{at}.origin"), c.origin);
            is.finite(format!("{at}.velocity"), c.velocity);
            is.positive(format!("{at}.size.0"), c.size.0);
            is.positive(format!("{at}.size.1"), c.size.1);
            is.positive(format!("{at}.mass"), c.mass);
            let (cols, rows) = c.resolution;
            if cols < 2 || rows < 2 {
                is.push(
                    format!("{at}.resolution"),
                    format!("needs ≥ 2 particles each way, got {cols}×{rows}"),
                );
            }
            is.spec(&format!("{at}.structural"), &c.structural);
            if let Some(s) = &c.shear {
                is.spec(&format!("{at}.shear"), s);
            }
            if let Some(s) = &c.bend {
                is.spec(&format!("{at}.bend"), s);
                if cols < 3 && rows < 3 {
                    is.push(
                        format!("{at}.bend"),
                        "bend springs need ≥ 3 particles along a row or column",
                    );
                }
            }
            for (j, p) in c.pins.iter().enumerate() {
                if let Anchor::Particle(col, row) = *p {
                    if col >= cols || row >= rows {
                        is.push(
                            format!("{at}.pins[{j}]"),
                            format!("particle ({col}, {row}) is outside the {cols}×{rows} grid"),
                        );
                    }
                }
            }
        }
        for (i, r) in self.ropes.iter().enumerate() {
            let at = format!("ropes[{i}]");
            is.finite(format!("{at}.start"), r.start);
            is.finite(format!("{at}.end"), r.end);
            is.positive(format!("{at}.mass"), r.mass);
            if r.particles < 2 {
                is.push(
                    format!("{at}.particles"),
                    format!("needs ≥ 2, got {}", r.particles),
                );
            }
            if r.start == r.end {
                is.push(&at, "start and end coincide: zero-length segments");
            }
            is.spec(&format!("{at}.spring"), &r.spring);
            if let Some(s) = &r.bend {
                is.spec(&format!("{at}.bend"), s);
            }
        }
        let total = self.particle_count();
        if total > MAX_PARTICLES {
            is.push(
                "scene",
                format!("asks for {total} particles; the limit is {MAX_PARTICLES}"),
            );
        }
        is.0
    }
}
