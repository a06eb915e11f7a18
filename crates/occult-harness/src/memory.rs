//! Whole-process memory measurement, opt-in: the peak resident set size of this process over
//! stretches of work, read from the kernel (Linux only).
//!
//! A [`PeakRss`] resets the kernel's resident high-water mark (`5` written to
//! `/proc/self/clear_refs`, see proc(5)) at the start of a stretch and reads it back (`VmHWM`
//! of `/proc/self/status`) at the end. Both act on the **whole process**: every thread, every
//! allocation, and any other code that reads or resets the same mark. That is why nothing in
//! this crate touches them unless a caller hands a `PeakRss` over (for example
//! [`CompareConfig::peak_rss`](crate::compare::CompareConfig::peak_rss)).
//!
//! Because each window resets the mark, the process's own peak is the highest of all
//! readings: a `PeakRss` keeps it, and clones share it, so a program that measures several
//! runs should make one and pass clones of it to each.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// A handle on the process's resident-memory peaks (module doc). Cheap to clone; clones share
/// the highest reading.
#[derive(Clone, Debug, Default)]
pub struct PeakRss {
    /// The highest `VmHWM` read so far through this handle or its clones, KiB.
    highest_kib: Arc<AtomicU64>,
}

impl PeakRss {
    /// A handle with no reading yet. Touches nothing until used.
    pub fn new() -> Self {
        Self::default()
    }

    /// Peak resident set size of this process since it started, bytes: the kernel's
    /// high-water mark now, or the highest one read through this handle before one of its
    /// resets, if that was higher. `None` where `/proc/self/status` is unavailable (not Linux).
    pub fn process_peak_bytes(&self) -> Option<u64> {
        self.high_water_mark_kib()
            .map(|kib| self.highest_kib.load(Ordering::Relaxed).max(kib) * 1024)
    }

    /// The kernel's resident high-water mark (`VmHWM`) now, KiB, folded into the highest
    /// reading; `None` where `/proc/self/status` is unavailable.
    fn high_water_mark_kib(&self) -> Option<u64> {
        let status = std::fs::read_to_string("/proc/self/status").ok()?;
        let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
        let kib: u64 = line
            .trim_start_matches("VmHWM:")
            .trim()
            .trim_end_matches("kB")
            .trim()
            .parse()
            .ok()?;
        self.highest_kib.fetch_max(kib, Ordering::Relaxed);
        Some(kib)
    }

    /// Starts a window: folds the current mark into the highest reading, then resets the
    /// kernel's mark to the current resident size.
    pub(crate) fn window(&self) -> PeakWindow<'_> {
        let reset = self.high_water_mark_kib().is_some() && std::fs::write("/proc/self/clear_refs", "5").is_ok();
        PeakWindow { rss: self, reset }
    }
}

/// The process's resident peak over a stretch of work ([`PeakRss::window`]).
pub(crate) struct PeakWindow<'a> {
    rss: &'a PeakRss,
    /// Whether the reset succeeded.
    reset: bool,
}

impl PeakWindow<'_> {
    /// The peak since the window started, bytes; `None` when the mark was not reset (it
    /// would be an older peak) or cannot be read.
    pub(crate) fn end(self) -> Option<u64> {
        self.reset
            .then(|| self.rss.high_water_mark_kib())
            .flatten()
            .map(|kib| kib * 1024)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_process_peak_survives_the_resets() {
        let rss = PeakRss::new();
        if rss.process_peak_bytes().is_none() {
            return;
        }
        // 64 MiB touched and freed, then the mark reset: the process peak still holds it.
        let block = vec![1u8; 64 << 20];
        assert_eq!(block.iter().step_by(4096).map(|&b| b as usize).sum::<usize>(), 16384);
        let grown = rss.process_peak_bytes().expect("the process peak was readable above");
        drop(block);
        assert!(grown >= 64 << 20, "{grown}");
        let window = rss.clone().window_owned();
        assert!(rss.process_peak_bytes().expect("the process peak was readable above") >= grown);
        assert!(window.is_none_or(|a| a <= rss.process_peak_bytes().expect("the process peak was readable above")));
    }

    impl PeakRss {
        /// A window opened and closed at once, through a clone: clones share the peak.
        fn window_owned(self) -> Option<u64> {
            self.window().end()
        }
    }
}
