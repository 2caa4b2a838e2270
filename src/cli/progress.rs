//! A terminal progress bar (indicatif) implementing [`Progress`]; draws nothing when stderr is not a terminal.

use crate::progress::Progress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Progress bar over the stages of one run.
pub struct BarProgress {
    bar: ProgressBar,
}

impl BarProgress {
    /// A bar on stderr, hidden when `quiet` or when stderr is not a terminal.
    pub fn new(quiet: bool) -> Self {
        let bar = ProgressBar::with_draw_target(Some(1000), ProgressDrawTarget::stderr());
        if quiet {
            bar.set_draw_target(ProgressDrawTarget::hidden());
        }
        if let Ok(style) =
            ProgressStyle::with_template("{elapsed:>4} {msg:<11} [{bar:30}] {percent:>3}%")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        BarProgress { bar }
    }

    /// Remove the bar from the terminal.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl Progress for BarProgress {
    fn stage(&self, stage: crate::progress::Stage) {
        self.bar.set_message(stage.name());
        self.bar.set_position(0);
    }

    fn fraction(&self, done: f64) {
        self.bar
            .set_position((done.clamp(0.0, 1.0) * 1000.0) as u64);
    }

    fn cancelled(&self) -> bool {
        false
    }
}
