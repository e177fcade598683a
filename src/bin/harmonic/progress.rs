//! Progress on stderr: a bar on a terminal, plain lines elsewhere.

/// Progress on stderr: a bar on a terminal, else a plain line at every tenth of the run.
pub struct Progress {
    bar: Option<indicatif::ProgressBar>,
    total: u64,
    tenth: u64,
}

impl Progress {
    pub fn new(total: u64) -> Self {
        Progress {
            bar: progress_bar(total),
            total,
            tenth: 0,
        }
    }

    pub fn set(&mut self, done: u64, t: f64) {
        match &self.bar {
            Some(b) => b.set_position(done),
            None => {
                let tenth = done.saturating_mul(10) / self.total.max(1);
                if tenth > self.tenth {
                    self.tenth = tenth;
                    eprintln!(
                        "progress: frame {done} of {} ({} %), t = {t:.3} s",
                        self.total,
                        tenth * 10
                    );
                }
            }
        }
    }

    pub fn println(&self, line: String) {
        match &self.bar {
            Some(b) => b.println(line),
            None => println!("{line}"),
        }
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
