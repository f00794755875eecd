//! indicatif implementation of the library's progress hook.

use hirad::progress::Progress;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::sync::Mutex;

/// Progress bars on stderr; hidden with `--quiet` or when stderr is not a terminal.
pub struct Bars {
    bar: Mutex<Option<ProgressBar>>,
    quiet: bool,
    multi: Option<MultiProgress>,
}

impl Bars {
    pub fn new(quiet: bool) -> Self {
        Self {
            bar: Mutex::new(None),
            quiet,
            multi: None,
        }
    }

    /// Bars drawn below the other bars of `multi` (e.g. under an overall study bar).
    pub fn in_multi(quiet: bool, multi: MultiProgress) -> Self {
        Self {
            bar: Mutex::new(None),
            quiet,
            multi: Some(multi),
        }
    }
}

/// An overall bar (units of work, with ETA) for long multi-step commands.
pub fn overall_bar(multi: &MultiProgress, quiet: bool, total: u64, name: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let b = multi.add(ProgressBar::new(total));
    b.set_style(
        ProgressStyle::with_template(
            "{prefix:>12} [{bar:30}] {pos}/{len} {msg} ({elapsed}, eta {eta})",
        )
        .unwrap()
        .progress_chars("=> "),
    );
    b.set_prefix(name.to_string());
    b
}

impl Progress for Bars {
    fn start(&self, name: &str, total: u64) {
        let bar = if self.quiet {
            ProgressBar::hidden()
        } else if total > 0 {
            let b = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
            b.set_style(
                ProgressStyle::with_template(
                    "{prefix:>12} [{bar:30}] {pos}/{len} {msg} ({elapsed}, eta {eta})",
                )
                .unwrap()
                .progress_chars("=> "),
            );
            b
        } else {
            let b = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
            b.set_style(
                ProgressStyle::with_template("{prefix:>12} {spinner} {msg} ({elapsed})").unwrap(),
            );
            b
        };
        let bar = match &self.multi {
            Some(m) if !self.quiet => m.add(bar),
            _ => bar,
        };
        bar.set_prefix(name.to_string());
        if let Some(old) = self.bar.lock().unwrap().replace(bar) {
            old.finish_and_clear();
        }
    }

    fn inc(&self, n: u64) {
        if let Some(b) = &*self.bar.lock().unwrap() {
            b.inc(n);
        }
    }

    fn message(&self, msg: &str) {
        if let Some(b) = &*self.bar.lock().unwrap() {
            b.set_message(msg.to_string());
        }
    }

    fn finish(&self) {
        if let Some(b) = self.bar.lock().unwrap().take() {
            b.finish_and_clear();
        }
    }
}
