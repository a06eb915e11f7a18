//! The measured choice between drawing last frame's visible list first and letting the tested
//! traversal draw the frame alone (`weigh`, not in the papers).
//!
//! Temporal coherence (Georges §3.3, after Greene) draws the nodes visible last frame first and
//! untested, so that the depth buffer is "almost complete" before the tested traversal. Where
//! the view moves far between frames, part of that list is hidden now and drawn anyway, and
//! where the traversal finds the occluders itself (front to back through a scene of opaque
//! blocks) the list adds only those hidden triangles: on an 8-step orbit of `city:blocks=32`,
//! 15 M triangles a frame with the list against 9.9 M without. Where occluders are small and
//! scattered (the pipes of a plant), drawing the list first is what lets the traversal cull
//! at all, and in large batches. Which holds is a property of the scene and the path, so it is
//! measured: the time of the last frame that drew the list and of the last that did not (the
//! first frame, which has no list, is one), and the faster way is taken; the other is measured
//! again after [`FIRST_PROBE`] frames, and after each probe that confirms the choice twice as
//! many, up to [`MAX_PROBE`] (frames recorded: a renderer does not record a frame whose list
//! does not show what the list costs, as one drawn from a frame that neither drew nor pruned
//! one). Time, not triangles: with the list first, `clusters` submits
//! more triangles on `plant`'s orbits but in fewer, larger batches, and is twice as fast.
//! Frames do not change either way (the traversal is conservative), only their time.

/// Frames after which the way not taken is measured again, the first time ...
pub const FIRST_PROBE: u32 = 16;
/// ... and at most, after probes that confirmed the choice.
pub const MAX_PROBE: u32 = 64;

/// What one visible list's owner keeps to choose ([module doc](self)).
#[derive(Clone, Copy, Debug)]
pub struct ListChoice {
    /// The time of the last frame that drew the list first, seconds.
    with: Option<f64>,
    /// The time of the last frame that did not.
    without: Option<f64>,
    /// Frames of the preferred way since the other was last measured.
    since: u32,
    /// Frames of the preferred way before the other is measured again.
    interval: u32,
}

impl Default for ListChoice {
    fn default() -> Self {
        Self {
            with: None,
            without: None,
            since: 0,
            interval: FIRST_PROBE,
        }
    }
}

impl ListChoice {
    /// The way the measurements prefer: `Some(true)` to draw the list; `None` before both ways
    /// were measured.
    fn preferred(&self) -> Option<bool> {
        Some(self.with? <= self.without?)
    }

    /// Whether this frame skips the list: the measurements prefer the traversal alone and no
    /// probe of the list is due, or they prefer the list and a probe of the traversal is due.
    /// Before both are measured the list is drawn (the papers' way).
    pub fn skip(&self) -> bool {
        match self.preferred() {
            Some(draw) => draw == (self.since >= self.interval),
            None => false,
        }
    }

    /// Records a frame that tested to its end: whether it drew the list first (a list with
    /// entries in view), and how long it took.
    pub fn record(&mut self, drew: bool, time: std::time::Duration) {
        let before = self.preferred();
        let t = Some(time.as_secs_f64());
        if drew {
            self.with = t;
        } else {
            self.without = t;
        }
        match before {
            Some(way) if way != drew => {
                // A probe of the way not taken: confirmed, the next comes later; else the
                // choice changes and the other way is probed again soon.
                self.interval = if self.preferred() == Some(way) {
                    (self.interval * 2).min(MAX_PROBE)
                } else {
                    FIRST_PROBE
                };
                self.since = 0;
            }
            Some(_) => self.since += 1,
            None => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use std::time::Duration;

    fn ms(t: u64) -> Duration {
        Duration::from_millis(t)
    }

    /// Drives a choice through frames whose time depends on the way taken.
    fn run(frames: usize, with: Duration, without: Duration) -> Vec<bool> {
        let mut c = ListChoice::default();
        (0..frames)
            .map(|i| {
                // The first frame has no list: it is a frame without.
                let drew = i > 0 && !c.skip();
                c.record(drew, if drew { with } else { without });
                drew
            })
            .collect()
    }

    #[test]
    fn a_list_that_costs_time_is_skipped_after_one_frame() {
        let ways = run(10, ms(200), ms(120));
        assert_eq!(
            ways,
            [false, true, false, false, false, false, false, false, false, false]
        );
    }

    #[test]
    fn a_list_that_saves_time_is_drawn_and_the_traversal_probed_rarely() {
        let ways = run(200, ms(10), ms(20));
        assert!(!ways[0] && ways[1..=FIRST_PROBE as usize + 1].iter().all(|&d| d));
        let probes: Vec<usize> = (1..ways.len()).filter(|&i| !ways[i]).collect();
        // Probes after 16, 32, 64, 64 frames of the list (the first counted from the frame after
        // the first with it, when both ways are known).
        assert_eq!(probes, [18, 51, 116, 181]);
    }

    #[test]
    fn a_probe_that_wins_changes_the_choice() {
        let mut c = ListChoice::default();
        c.record(false, ms(100));
        c.record(true, ms(50));
        for _ in 0..FIRST_PROBE {
            assert!(!c.skip());
            c.record(true, ms(50));
        }
        assert!(c.skip(), "the traversal alone is probed");
        c.record(false, ms(40));
        assert!(c.skip(), "it won: taken from now on");
        for _ in 0..FIRST_PROBE {
            c.record(false, ms(40));
        }
        assert!(!c.skip(), "the list is probed again after the first interval");
    }
}
