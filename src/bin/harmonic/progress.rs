//! Progress on stderr: a bar on a terminal, plain lines elsewhere.

use std::time::{Duration, Instant};

/// Progress on stderr: a bar on a terminal, else a plain line at every tenth of the run, and
/// on a slow run one within [`FIRST_LINE`] and then at least every [`QUIET`].
pub struct Progress {
    bar: Option<indicatif::ProgressBar>,
    total: u64,
    tenth: u64,
    last: Instant,
    lines: u32,
}

/// A slow run's first plain line comes by then (after the frame that passes it).
const FIRST_LINE: Duration = Duration::from_secs(1);
/// The longest a slow run goes without a plain line after its first.
const QUIET: Duration = Duration::from_secs(10);

impl Progress {
    pub fn new(total: u64) -> Self {
        Progress {
            bar: progress_bar(total),
            total,
            tenth: 0,
            last: Instant::now(),
            lines: 0,
        }
    }

    pub fn set(&mut self, done: u64, t: f64) {
        match &self.bar {
            Some(b) => b.set_position(done),
            None => {
                let tenth = done.saturating_mul(10) / self.total.max(1);
                let wait = if self.lines == 0 { FIRST_LINE } else { QUIET };
                if tenth > self.tenth || self.last.elapsed() >= wait {
                    self.tenth = tenth;
                    self.last = Instant::now();
                    self.lines += 1;
                    let share = 100.0 * done as f64 / self.total.max(1) as f64;
                    eprintln!(
                        "progress: frame {done} of {} ({} %), t = {t:.3} s",
                        self.total,
                        harmonic::internals::Readable::new(share, 0)
                    );
                }
            }
        }
    }

    /// A line to stdout above the bar (`render`'s, so unused without the GPU back end).
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    pub fn println(&self, line: String) -> Result<(), String> {
        match &self.bar {
            Some(b) => b.println(line),
            None => crate::out(format_args!("{line}"))?,
        }
        Ok(())
    }

    pub fn finish(self) {
        if let Some(b) = self.bar {
            b.finish_and_clear();
        }
    }
}

/// A progress bar on stderr when it is a terminal; None otherwise (callers print plain lines).
fn progress_bar(total: u64) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    std::io::stderr().is_terminal().then(|| {
        let bar = indicatif::ProgressBar::new(total);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} {elapsed_precise} {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    })
}
