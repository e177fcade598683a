//! The run summary's energy lines.

use harmonic::internals::Readable;
use harmonic::{Diagnostics, EnergyAudit, StageKind, StageTimes, StepStats};

/// A run's wall time by stage and by the work around the stages, summed over its frames.
#[derive(Default)]
pub struct Times {
    stages: StageTimes,
    device: f64,
    /// The device's kernel time per stage by its timestamps, and the frames without them.
    device_stages: StageTimes,
    untimed: u64,
    gather: f64,
    /// The energy audit's passes (s).
    pub audit: f64,
    scatter: f64,
}

impl Times {
    pub fn add(&mut self, s: &StepStats) {
        self.stages += s.stages;
        self.device += s.device.as_secs_f64();
        match s.device_stages {
            Some(t) => self.device_stages += t,
            None => self.untimed += 1,
        }
        self.gather += s.gather.as_secs_f64();
        self.audit += s.audit_time.as_secs_f64();
        self.scatter += s.scatter.as_secs_f64();
    }

    /// One stage kind's time (s).
    pub fn stage(&self, kind: StageKind) -> f64 {
        self.stages[kind].as_secs_f64()
    }

    /// `frame time: 1.234 s by stage: integrate 80.1 %, contacts 12.0 %, …`: each stage with
    /// time, then the device's kernels (the GPU), the audit, gather and scatter.
    pub fn shares(&self) -> String {
        let total = self.stages.total().as_secs_f64()
            + self.device
            + self.gather
            + self.audit
            + self.scatter;
        let share = |t: f64| Readable::new(100.0 * t / total.max(1e-12), 3);
        let mut parts: Vec<String> = (self.stages.iter())
            .filter(|(_, t)| !t.is_zero())
            .map(|(k, t)| format!("{} {} %", k.name(), share(t.as_secs_f64())))
            .collect();
        if self.device > 0.0 {
            // The kernels by the device's timestamps, where every frame had them.
            let kernels: Vec<String> = (self.device_stages.iter())
                .filter(|(_, t)| !t.is_zero() && self.untimed == 0)
                .map(|(k, t)| format!("{} {:.4} s", k.name(), t.as_secs_f64()))
                .collect();
            let by_stage = if kernels.is_empty() {
                String::new()
            } else {
                format!(" (kernels by timestamp: {})", kernels.join(", "))
            };
            parts.push(format!("device {} %{by_stage}", share(self.device)));
        }
        for (name, t) in [
            ("audit", self.audit),
            ("gather", self.gather),
            ("scatter", self.scatter),
        ] {
            parts.push(format!("{name} {} %", share(t)));
        }
        format!("frame time: {total:.3} s by stage: {}", parts.join(", "))
    }
}

/// The energy at the start and end, as a share of the scene's energy scale.
pub fn energy(start: &Diagnostics, end: &Diagnostics) -> String {
    let scale = start.energy_scale;
    let relative = if scale > 0.0 {
        format!(
            "{} % of the scene's energy scale, {scale:.4e} J",
            Readable::signed(100.0 * (end.energy - start.energy) / scale, 3)
        )
    } else {
        "no energy scale: the scene starts at rest and unstretched, with nothing to fall".into()
    };
    format!(
        "energy: start {:.6e} J, end {:.6e} J ({relative})",
        start.energy, end.energy
    )
}

/// The run's energy books: the residual (the steps' own error) and each line.
pub fn audit(a: &EnergyAudit, seconds: f64, integrate: f64) -> String {
    let share = |j: f64| {
        if a.scale > 0.0 {
            format!(" ({} %)", Readable::signed(100.0 * j / a.scale, 4))
        } else {
            String::new()
        }
    };
    format!(
        "energy audit: residual {:+.4e} J{}, peak {:.4e} J{} (made by the steps; negative: numerical \
         damping); dampers took {:.4e} J, contacts {:.4e} J, friction {:.4e} J, limits {:.4e} J, torn {:.4e} J, quarantine {:.4e} J; \
         attachments put in {:.4e} J, forces and air {:.4e} J, edits {:.4e} J; its passes took \
         {seconds:.3} s ({} % of integrate, where the grid pass books its dampers)",
        a.residual,
        share(a.residual),
        a.peak_residual,
        share(a.peak_residual),
        a.damping,
        a.contacts,
        a.friction,
        a.limits,
        a.torn,
        a.quarantine,
        a.attachments,
        a.forces,
        a.edits,
        Readable::new(100.0 * seconds / integrate.max(1e-12), 1)
    )
}

/// What the accuracy controller made of the substeps.
pub fn accuracy(floor: u32, now: u32, changes: u32, motion: f64) -> String {
    let check = if motion.is_nan() {
        "no motion check measured (bodies, the GPU, or a run too short for one)".to_string()
    } else {
        format!(
            "last motion check {:.3e} % of the scene's size per frame",
            100.0 * motion
        )
    };
    format!(
        "accuracy: {now} substep(s) at the end ({floor} for stability; {changes} change(s) for the energy \
         tolerance and the motion check); {check}"
    )
}

/// The process's peak resident set (Linux's VmHWM), in bytes.
pub fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}
