//! [`FrameControl`]: a handle a caller keeps to cancel the frame being drawn and to read how far
//! it got.
//!
//! It travels in [`RasterConfig::control`](crate::RasterConfig::control), so that every
//! rasterizer built from one configuration, and so every batch a renderer submits, sees it
//! without the renderers passing it along. The rasterizer itself never reads it: the renderers
//! (`occult-render`) check it at their batch boundaries and report their progress into it.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::Arc;

/// Cancellation and progress of the frame a renderer is drawing, shared between the thread that
/// draws and any thread that watches.
///
/// [`FrameControl::default`] is inert: it is never cancelled and keeps no progress, at no cost.
/// [`FrameControl::new`] makes a live one; clones share it.
///
/// A frame begins with [`FrameControl::reset`] (the caller's: it clears the flag and the
/// progress); [`FrameControl::cancel`] from any thread makes the renderer stop at its next check
/// and return an error instead of a frame; [`FrameControl::progress`] is the largest fraction of
/// the frame the renderer reported since the reset, in `0.0..=1.0`, so it never decreases
/// within a frame and is 1.0 once the frame is complete.
///
/// ```
/// use occult_raster::FrameControl;
/// let control = FrameControl::new();
/// let watcher = control.clone();
/// control.report(0.25);
/// control.report(0.125);
/// assert_eq!(watcher.progress(), 0.25, "progress never goes back");
/// watcher.cancel();
/// assert!(control.is_cancelled());
/// control.reset();
/// assert!(!control.is_cancelled());
/// assert_eq!(control.progress(), 0.0);
/// ```
#[derive(Clone, Debug, Default)]
pub struct FrameControl(Option<Arc<Shared>>);

#[derive(Debug, Default)]
struct Shared {
    cancel: AtomicBool,
    /// The fraction's `f32` bits: for non-negative floats the bits order as the values do, so
    /// `fetch_max` on them keeps the largest fraction.
    progress_bits: AtomicU32,
    /// Checks left before the control cancels itself ([`FrameControl::cancel_at_check`]);
    /// 0: none armed.
    checks_left: AtomicU64,
}

impl FrameControl {
    /// A live control: not cancelled, progress 0.
    pub fn new() -> Self {
        Self(Some(Arc::new(Shared::default())))
    }

    /// False for the inert [`FrameControl::default`], which is never cancelled and whose
    /// progress stays 0.
    #[inline]
    pub fn is_live(&self) -> bool {
        self.0.is_some()
    }

    /// Asks the frame in flight (or the next, until [`FrameControl::reset`]) to stop. Nothing
    /// on an inert control.
    pub fn cancel(&self) {
        if let Some(s) = &self.0 {
            s.cancel.store(true, Ordering::Relaxed);
        }
    }

    /// True once [`FrameControl::cancel`] was called since the last reset (this is the check
    /// the renderers make; see [`FrameControl::cancel_at_check`]).
    #[inline]
    pub fn is_cancelled(&self) -> bool {
        let Some(s) = &self.0 else {
            return false;
        };
        if s.cancel.load(Ordering::Relaxed) {
            return true;
        }
        if s.checks_left.load(Ordering::Relaxed) == 0 {
            return false;
        }
        // Armed: this check counts; the last one cancels.
        let left = s.checks_left.fetch_sub(1, Ordering::Relaxed);
        if left <= 1 {
            s.checks_left.store(0, Ordering::Relaxed);
            s.cancel.store(true, Ordering::Relaxed);
            return true;
        }
        false
    }

    /// Cancels the frame at the `n`-th call of [`FrameControl::is_cancelled`] from now (`n` of 0:
    /// disarms), so that a test can cancel a frame at each point where the renderer checks, in
    /// turn, deterministically (unlike [`FrameControl::cancel`] from another thread, which
    /// lands wherever the frame is). [`FrameControl::reset`] disarms it. Nothing on an inert
    /// control.
    pub fn cancel_at_check(&self, n: u64) {
        if let Some(s) = &self.0 {
            s.checks_left.store(n, Ordering::Relaxed);
        }
    }

    /// Starts a frame: clears the cancel flag and sets the progress to 0.
    pub fn reset(&self) {
        if let Some(s) = &self.0 {
            s.cancel.store(false, Ordering::Relaxed);
            s.progress_bits.store(0, Ordering::Relaxed);
            s.checks_left.store(0, Ordering::Relaxed);
        }
    }

    /// The largest fraction of the frame reported since the reset, in `0.0..=1.0`; 0 on an
    /// inert control.
    pub fn progress(&self) -> f32 {
        self.0
            .as_ref()
            .map_or(0.0, |s| f32::from_bits(s.progress_bits.load(Ordering::Relaxed)))
    }

    /// Reports that `fraction` of the frame is done (clamped to `0.0..=1.0`; NaN is ignored).
    /// The progress becomes the largest fraction reported since the reset.
    #[inline]
    pub fn report(&self, fraction: f64) {
        if let Some(s) = &self.0 {
            if fraction.is_nan() {
                return;
            }
            let f = fraction.clamp(0.0, 1.0) as f32;
            s.progress_bits.fetch_max(f.to_bits(), Ordering::Relaxed);
        }
    }
}

/// Two controls are equal when they are the same handle (or both inert): a configuration
/// compares equal to its clones.
impl PartialEq for FrameControl {
    fn eq(&self, other: &Self) -> bool {
        match (&self.0, &other.0) {
            (None, None) => true,
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
}

impl Eq for FrameControl {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inert_control_is_never_cancelled_and_keeps_no_progress() {
        let c = FrameControl::default();
        c.cancel();
        c.report(0.5);
        assert!(!c.is_live());
        assert!(!c.is_cancelled());
        assert_eq!(c.progress(), 0.0);
        assert_eq!(c, FrameControl::default());
    }

    #[test]
    fn progress_is_clamped_monotone_and_ignores_nan() {
        let c = FrameControl::new();
        c.report(-1.0);
        assert_eq!(c.progress(), 0.0);
        c.report(0.5);
        c.report(f64::NAN);
        c.report(0.25);
        assert_eq!(c.progress(), 0.5);
        c.report(7.0);
        assert_eq!(c.progress(), 1.0);
        c.reset();
        assert_eq!(c.progress(), 0.0);
    }

    #[test]
    fn an_armed_control_cancels_at_the_nth_check() {
        let c = FrameControl::new();
        c.cancel_at_check(3);
        assert!(!c.is_cancelled());
        assert!(!c.is_cancelled());
        assert!(c.is_cancelled(), "the third check cancels");
        assert!(c.is_cancelled(), "and it stays cancelled");
        c.reset();
        assert!(!c.is_cancelled());
        c.cancel_at_check(2);
        c.reset();
        assert!(!c.is_cancelled() && !c.is_cancelled(), "reset disarms");
        c.cancel_at_check(0);
        assert!(!c.is_cancelled());
    }

    #[test]
    fn clones_share_one_control_and_compare_equal() {
        let a = FrameControl::new();
        let b = a.clone();
        assert_eq!(a, b);
        assert_ne!(a, FrameControl::new());
        assert_ne!(a, FrameControl::default());
        b.cancel();
        assert!(a.is_cancelled());
    }
}
