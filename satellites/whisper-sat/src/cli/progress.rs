//! Terminal progress bars (indicatif) for the converter's phases.

use indicatif::{ProgressBar, ProgressStyle};
use whisper_sat::convert::Progress;

/// One bar per phase, showing bytes done and throughput.
#[derive(Debug, Default)]
pub struct Bars {
    bar: Option<ProgressBar>,
}

impl Progress for Bars {
    fn phase(&mut self, name: &str, total: u64) {
        if let Some(done) = self.bar.take() {
            done.finish();
        }
        let bar = ProgressBar::new(total);
        let style = ProgressStyle::with_template(
            "{msg:24} [{bar:40}] {bytes}/{total_bytes} ({bytes_per_sec})",
        )
        .map(|s| s.progress_chars("=> "))
        .unwrap_or_else(|_| ProgressStyle::default_bar());
        bar.set_style(style);
        bar.set_message(name.to_owned());
        self.bar = Some(bar);
    }

    fn advance(&mut self, done: u64) {
        if let Some(bar) = &self.bar {
            bar.set_position(done);
        }
    }
}

impl Drop for Bars {
    fn drop(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish();
        }
    }
}
