//! Progress bars on stderr, shown only for work that lasts more than a second and only when
//! stderr is a terminal (so that logs and tests see clean output).

use std::io::IsTerminal;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// How long work runs before its bar appears.
const SHOW_AFTER: Duration = Duration::from_secs(1);

/// A progress bar or spinner that appears after [`SHOW_AFTER`] and clears itself when dropped.
pub struct Progress {
    bar: ProgressBar,
    /// Set when the work is over; the thread that shows the bar checks it under the lock.
    done: Arc<Mutex<bool>>,
}

impl Progress {
    /// A spinner with a message, for one long call.
    pub fn spinner(message: impl Into<String>) -> Self {
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden());
        if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} ({elapsed})") {
            bar.set_style(style);
        }
        bar.set_message(message.into());
        Self::start(bar)
    }

    /// A bar of `len` steps with a message.
    pub fn bar(len: u64, message: impl Into<String>) -> Self {
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
        if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:24}] {pos}/{len} ({elapsed}, eta {eta})") {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_message(message.into());
        Self::start(bar)
    }

    fn start(bar: ProgressBar) -> Self {
        let done = Arc::new(Mutex::new(false));
        if std::io::stderr().is_terminal() {
            let (bar, done) = (bar.clone(), Arc::clone(&done));
            std::thread::spawn(move || {
                let step = Duration::from_millis(50);
                let mut waited = Duration::ZERO;
                while waited < SHOW_AFTER {
                    if *done.lock().unwrap_or_else(|e| e.into_inner()) {
                        return;
                    }
                    std::thread::sleep(step);
                    waited += step;
                }
                let done = done.lock().unwrap_or_else(|e| e.into_inner());
                if !*done {
                    bar.set_draw_target(ProgressDrawTarget::stderr());
                    bar.enable_steady_tick(Duration::from_millis(120));
                }
            });
        }
        Self { bar, done }
    }

    /// Advances by one step.
    pub fn inc(&self) {
        self.bar.inc(1);
    }

    /// Replaces the message.
    pub fn set_message(&self, message: impl Into<String>) {
        self.bar.set_message(message.into());
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        let mut done = self.done.lock().unwrap_or_else(|e| e.into_inner());
        *done = true;
        self.bar.finish_and_clear();
    }
}
