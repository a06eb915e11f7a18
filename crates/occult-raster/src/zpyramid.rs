//! The max z-pyramid of hierarchical z-buffer visibility, over a [`Frame`]'s depth.
//!
//! # References
//! - C. Georges, *Obscuration Culling on Parallel Graphics Architectures*, UNC TR95-017 (1995),
//!   §3.2 (the z-pyramid and the box-face test), §5.3 (the global maximum depth), after
//!   N. Greene, M. Kass, G. Miller, *Hierarchical Z-Buffer Visibility* (SIGGRAPH 1993).
//!
//! Level 0 is the frame's depth buffer itself (never copied); level `k` has
//! `ceil(w / 2^k) × ceil(h / 2^k)` samples, sample `(i, j)` covering the pixels
//! `[i·2^k, (i+1)·2^k) × [j·2^k, (j+1)·2^k)` clipped to the frame; the last level is one sample.
//! Each sample holds the **farthest** depth of the pixels it covers. The paper's "maximum z"
//! is, in our reversed depth (greater is nearer, cleared to 0), the **minimum** stored value:
//! so this is a min pyramid over stored depth, and an uncovered pixel (0) makes every sample
//! above it 0, which occludes nothing.
//!
//! **Conservative by construction.** A pixel's stored depth only grows while a frame is drawn
//! (the rasterizer keeps the nearer fragment). A sample computed earlier is therefore never
//! nearer than the true farthest depth now: a stale pyramid can only fail to reject, never
//! reject wrongly. So [`ZPyramid::update`] may be called as rarely as the caller likes, over
//! any rectangle that holds the pixels drawn since the last update; renderers update it once
//! per rasterized batch, over the union of the batch's screen rectangles (a per-triangle update
//! would cost more than the triangle on a CPU; per batch keeps the update a linear pass over the
//! dirty region, amortized over the batch's triangles).
//!
//! [`ZPyramid::occludes`] is the §3.2 test: a rectangle whose content is no nearer than
//! `nearest` is hidden when every covered pixel is strictly nearer than `nearest` (a tie may
//! still be won by a smaller item id). As Greene et al. do, it starts at the finest level where
//! the rectangle meets at most 2×2 samples, compares, and descends into the (up to four)
//! samples below where the comparison fails, down to full resolution; a failing sample whose
//! pixels all lie in the rectangle ends the test at once (one of its pixels is not nearer).
//! The answer is always the full-resolution scan's: the pyramid only saves reads.

use crate::frame::Frame;
use crate::query::PixelRect;
use crate::RasterError;

/// Work done by pyramid tests (added to by [`ZPyramid::occludes`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PyramidCounts {
    /// Samples compared (any level, full-resolution pixels included).
    pub samples_tested: u64,
    /// Descents from a sample to the level below.
    pub descents: u64,
    /// Rectangles rejected by the global farthest depth alone (§5.3).
    pub global_rejects: u64,
}

/// How [`ZPyramid::occludes`] searches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PyramidTest {
    /// Compare with the single farthest depth of the whole frame first (§5.3).
    pub global: bool,
    /// Use the pyramid (§3.2); when false, scan the rectangle at full resolution.
    pub hierarchical: bool,
}

/// The pyramid's coarse levels (level 0 being the frame).
#[derive(Clone, Debug, Default)]
pub struct ZPyramid {
    width: u32,
    height: u32,
    /// `levels[k - 1]` is level `k`: (width, height, samples).
    levels: Vec<(u32, u32, Vec<f32>)>,
}

impl ZPyramid {
    /// An all-far (0) pyramid for `width × height` frames.
    ///
    /// # Errors
    /// [`RasterError::BadConfig`] for a zero side; [`RasterError::OutOfMemory`] past the
    /// engine's pixel limit.
    pub fn new(width: u32, height: u32) -> Result<Self, RasterError> {
        if width == 0 || height == 0 {
            return Err(RasterError::BadConfig(format!("z-pyramid of {width}x{height} pixels")));
        }
        if width as u64 * height as u64 > occult_core::MAX_PIXEL_COUNT {
            return Err(RasterError::OutOfMemory(width as usize * height as usize * 4));
        }
        let mut levels = Vec::new();
        let (mut w, mut h) = (width, height);
        while w > 1 || h > 1 {
            w = w.div_ceil(2);
            h = h.div_ceil(2);
            // Written, not allocated zeroed: the pages are made here (at a renderer's
            // preparation, when it makes its pyramid then), not at the first frame's clear.
            let mut samples = Vec::with_capacity(w as usize * h as usize);
            samples.resize(w as usize * h as usize, 0.0);
            levels.push((w, h, samples));
        }
        Ok(Self { width, height, levels })
    }

    /// Frame width it serves.
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Frame height it serves.
    pub fn height(&self) -> u32 {
        self.height
    }
    /// Number of levels, level 0 (the frame) included.
    pub fn level_count(&self) -> usize {
        self.levels.len() + 1
    }

    /// Sets every sample to 0 (far), as for a cleared frame.
    pub fn clear(&mut self) {
        for (_, _, s) in &mut self.levels {
            s.fill(0.0);
        }
    }

    /// Sets every sample to what `frame` holds just after [`crate::Rasterizer::clear_region`]
    /// prepared it: 0 (far) where a sample covers a pixel of the frame's region,
    /// [`crate::BLOCKED_DEPTH`] where it covers none (as [`ZPyramid::clear`] for a whole
    /// frame), so that tests of a box beside a band of the screen find it hidden there.
    ///
    /// # Panics
    /// If `frame` is not of the pyramid's size (a programmer error).
    pub fn clear_for(&mut self, frame: &Frame) {
        assert!(
            frame.width() == self.width && frame.height() == self.height,
            "z-pyramid and frame sizes differ"
        );
        let [x0, y0, x1, y1] = frame.region();
        if [x0, y0, x1, y1] == [0, 0, self.width, self.height] || x0 >= x1 || y0 >= y1 {
            return self.clear();
        }
        for (k, (lw, _, samples)) in self.levels.iter_mut().enumerate() {
            // Level k + 1: a sample covers 2^(k+1) pixels a side.
            let shift = k as u32 + 1;
            let (c0, c1) = ((x0 >> shift) as usize, ((x1 - 1) >> shift) as usize + 1);
            let (r0, r1) = (y0 >> shift, (y1 - 1) >> shift);
            for (j, row) in samples.chunks_mut(*lw as usize).enumerate() {
                if (j as u32) < r0 || j as u32 > r1 {
                    row.fill(crate::BLOCKED_DEPTH);
                    continue;
                }
                let c1 = c1.min(row.len());
                row[..c0].fill(crate::BLOCKED_DEPTH);
                row[c0..c1].fill(0.0);
                row[c1..].fill(crate::BLOCKED_DEPTH);
            }
        }
    }

    /// The farthest depth of the whole frame at the last update (§5.3's global maximum z).
    pub fn farthest(&self, frame: &Frame) -> f32 {
        match self.levels.last() {
            Some((_, _, s)) => s[0],
            None => frame.depth()[0],
        }
    }

    /// Recomputes every level over the pixels of `rect` (clipped to the frame) from `frame`.
    ///
    /// # Panics
    /// If `frame` is not of the pyramid's size (a programmer error).
    pub fn update(&mut self, frame: &Frame, rect: PixelRect) {
        assert!(
            frame.width() == self.width && frame.height() == self.height,
            "z-pyramid and frame sizes differ"
        );
        let (mut x0, mut y0) = (rect.x0.min(self.width), rect.y0.min(self.height));
        let (mut x1, mut y1) = (rect.x1.min(self.width), rect.y1.min(self.height));
        if x0 >= x1 || y0 >= y1 {
            return;
        }
        let (mut below_w, mut below_h) = (self.width, self.height);
        for k in 0..self.levels.len() {
            // Samples of this level over the rectangle of the level below.
            x0 >>= 1;
            y0 >>= 1;
            x1 = x1.div_ceil(2);
            y1 = y1.div_ceil(2);
            let (done, rest) = self.levels.split_at_mut(k);
            let (lw, _, samples) = &mut rest[0];
            let (below, bw): (&[f32], usize) = match done.last() {
                Some((w, _, s)) => (s, *w as usize),
                None => (frame.depth(), self.width as usize),
            };
            // Samples whose two columns below both exist: a branch-free loop over pairs, which
            // the compiler vectorizes; the last column of an odd-width level below is its own.
            let xe = x1.min(below_w / 2);
            for y in y0..y1 {
                let r0 = 2 * y as usize;
                let r1 = (r0 + 1).min(below_h as usize - 1);
                let out = &mut samples[y as usize * *lw as usize..][..*lw as usize];
                if x0 < xe {
                    let (c0, c1) = (2 * x0 as usize, 2 * xe as usize);
                    let top = &below[r0 * bw + c0..r0 * bw + c1];
                    let bottom = &below[r1 * bw + c0..r1 * bw + c1];
                    for ((o, t), b) in out[x0 as usize..xe as usize]
                        .iter_mut()
                        .zip(top.chunks_exact(2))
                        .zip(bottom.chunks_exact(2))
                    {
                        *o = t[0].min(t[1]).min(b[0].min(b[1]));
                    }
                }
                for x in xe.max(x0)..x1 {
                    let c0 = 2 * x as usize;
                    let c1 = (c0 + 1).min(below_w as usize - 1);
                    let a = below[r0 * bw + c0].min(below[r0 * bw + c1]);
                    let b = below[r1 * bw + c0].min(below[r1 * bw + c1]);
                    out[x as usize] = a.min(b);
                }
            }
            below_w = below_w.div_ceil(2);
            below_h = below_h.div_ceil(2);
        }
    }

    /// Recomputes the whole pyramid from `frame`.
    pub fn rebuild(&mut self, frame: &Frame) {
        self.update(frame, PixelRect::whole(frame));
    }

    /// True when every pixel of `rect` (clipped to the frame) holds a depth strictly nearer than
    /// `nearest`, as far as the pyramid (and the frame, at level 0) knows: then nothing at
    /// depth `nearest` or farther can appear there (§3.2). An empty rectangle is occluded.
    /// A NaN `nearest` is never occluded.
    ///
    /// When the pyramid is up to date over the rectangle (every change of the frame there was
    /// followed by an [`update`](Self::update) over it), the answer is exactly the
    /// full-resolution scan's. A stale pyramid may answer false where the scan would answer
    /// true, never the reverse.
    pub fn occludes(
        &self,
        frame: &Frame,
        rect: PixelRect,
        nearest: f32,
        how: PyramidTest,
        counts: &mut PyramidCounts,
    ) -> bool {
        let x1 = rect.x1.min(self.width);
        let y1 = rect.y1.min(self.height);
        if rect.x0 >= x1 || rect.y0 >= y1 {
            return true;
        }
        if nearest.is_nan() {
            return false;
        }
        if how.global {
            counts.samples_tested += 1;
            // §5.3: the whole frame's farthest depth is nearer than the box: reject at once.
            if self.farthest(frame) > nearest {
                counts.global_rejects += 1;
                return true;
            }
        }
        let r = PixelRect {
            x0: rect.x0,
            y0: rect.y0,
            x1,
            y1,
        };
        if !how.hierarchical {
            return self.scan(frame, r, nearest, counts);
        }
        // Greene et al.: the finest level where the rectangle meets at most 2×2 samples (at
        // most four reads), rather than the level where one sample covers it, which for a small
        // rectangle across a coarse sample boundary is the top of the pyramid.
        let mut level = 0;
        while ((r.x1 - 1) >> level) - (r.x0 >> level) > 1 || ((r.y1 - 1) >> level) - (r.y0 >> level) > 1 {
            level += 1;
        }
        for j in r.y0 >> level..=(r.y1 - 1) >> level {
            for i in r.x0 >> level..=(r.x1 - 1) >> level {
                if !self.sample_occludes(frame, level, i, j, r, nearest, counts) {
                    return false;
                }
            }
        }
        true
    }

    /// The §3.2 descent below sample `(i, j)` of `level`.
    #[allow(clippy::too_many_arguments)]
    fn sample_occludes(
        &self,
        frame: &Frame,
        level: u32,
        i: u32,
        j: u32,
        r: PixelRect,
        nearest: f32,
        counts: &mut PyramidCounts,
    ) -> bool {
        counts.samples_tested += 1;
        if level == 0 {
            return frame.depth()[j as usize * self.width as usize + i as usize] > nearest;
        }
        let (lw, _, s) = &self.levels[level as usize - 1];
        if s[j as usize * *lw as usize + i as usize] > nearest {
            return true;
        }
        // The comparison failed: some pixel under the sample is not nearer than `nearest`. When
        // every pixel under it lies in the rectangle, that pixel is one of the rectangle's, and
        // the answer is known without descending (the full-resolution scan's answer exactly).
        let (px0, py0) = (i << level, j << level);
        let px1 = ((i + 1) << level).min(self.width);
        let py1 = ((j + 1) << level).min(self.height);
        if r.x0 <= px0 && px1 <= r.x1 && r.y0 <= py0 && py1 <= r.y1 {
            return false;
        }
        // Otherwise descend into the samples below that meet the rectangle.
        counts.descents += 1;
        let l = level - 1;
        let (bx0, bx1) = ((r.x0 >> l).max(2 * i), ((r.x1 - 1) >> l).min(2 * i + 1));
        let (by0, by1) = ((r.y0 >> l).max(2 * j), ((r.y1 - 1) >> l).min(2 * j + 1));
        for y in by0..=by1 {
            for x in bx0..=bx1 {
                if !self.sample_occludes(frame, l, x, y, r, nearest, counts) {
                    return false;
                }
            }
        }
        true
    }

    /// Full-resolution scan (the test without the pyramid), stopping at the first pixel that
    /// is not nearer.
    fn scan(&self, frame: &Frame, r: PixelRect, nearest: f32, counts: &mut PyramidCounts) -> bool {
        let w = self.width as usize;
        for y in r.y0..r.y1 {
            let row = &frame.depth()[y as usize * w + r.x0 as usize..y as usize * w + r.x1 as usize];
            for (k, &d) in row.iter().enumerate() {
                if d <= nearest {
                    counts.samples_tested += k as u64 + 1;
                    return false;
                }
            }
            counts.samples_tested += row.len() as u64;
        }
        true
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.levels.iter().map(|(_, _, s)| s.capacity() * 4).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pyramid cleared for a frame prepared for a region holds what one rebuilt from that
    /// frame holds: far over the region, blocked wholly beside it.
    #[test]
    fn clearing_for_a_region_is_rebuilding_from_its_frame() {
        let r = crate::Rasterizer::new(crate::RasterConfig {
            threads: 1,
            ..crate::RasterConfig::default()
        })
        .expect("a one-thread rasterizer");
        for (w, h) in [(97, 61), (64, 48), (1, 9)] {
            let mut frame = Frame::new(w, h).expect("a frame");
            for region in [
                [0, 0, w, h],
                [w / 3, 0, w, h],
                [0, 0, (w / 2).max(1), h],
                [w / 4, h / 5, w / 2 + 1, h - 1],
            ] {
                r.clear_region(&mut frame, region);
                let mut cleared = ZPyramid::new(w, h).expect("a pyramid");
                cleared.clear_for(&frame);
                let mut rebuilt = ZPyramid::new(w, h).expect("a pyramid");
                rebuilt.rebuild(&frame);
                for ((_, _, a), (_, _, b)) in cleared.levels.iter().zip(&rebuilt.levels) {
                    assert!(
                        a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                        "{w}x{h} {region:?}"
                    );
                }
            }
        }
    }

    fn frame_with(w: u32, h: u32, f: impl Fn(u32, u32) -> f32) -> Frame {
        let mut frame = Frame::new(w, h).expect("a test frame of a valid size");
        for y in 0..h {
            for x in 0..w {
                frame.write_fragment(x, y, f(x, y), 1);
            }
        }
        frame
    }

    fn brute(frame: &Frame, r: PixelRect, nearest: f32) -> bool {
        crate::query_rect(frame, r, nearest) == 0
    }

    const HOWS: [PyramidTest; 4] = [
        PyramidTest {
            global: false,
            hierarchical: false,
        },
        PyramidTest {
            global: true,
            hierarchical: false,
        },
        PyramidTest {
            global: false,
            hierarchical: true,
        },
        PyramidTest {
            global: true,
            hierarchical: true,
        },
    ];

    #[test]
    fn zero_size_is_an_error() {
        assert!(ZPyramid::new(0, 5).is_err());
        assert!(ZPyramid::new(5, 0).is_err());
        assert_eq!(ZPyramid::new(1, 1).expect("a 1x1 pyramid").level_count(), 1);
    }

    #[test]
    fn matches_brute_force_on_odd_sizes() {
        let mut seed = 12345u64;
        let mut rnd = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 33) as u32
        };
        for (w, h) in [(1, 1), (1, 7), (13, 1), (37, 23), (64, 64), (96, 65)] {
            let frame = frame_with(w, h, |x, y| {
                if (x * 7 + y * 3) % 11 == 0 {
                    0.0
                } else {
                    0.1 + ((x ^ y) % 9) as f32 * 0.1
                }
            });
            let mut p = ZPyramid::new(w, h).expect("a pyramid of the frame's size");
            p.rebuild(&frame);
            let min_all = frame.depth().iter().copied().fold(f32::INFINITY, f32::min);
            assert_eq!(p.farthest(&frame), min_all);
            for _ in 0..500 {
                let x0 = rnd() % (w + 2);
                let y0 = rnd() % (h + 2);
                let r = PixelRect {
                    x0,
                    y0,
                    x1: x0 + rnd() % (w + 1),
                    y1: y0 + rnd() % (h + 1),
                };
                let nearest = (rnd() % 12) as f32 * 0.1 - 0.05;
                let expect = brute(&frame, r, nearest);
                for how in HOWS {
                    let mut c = PyramidCounts::default();
                    assert_eq!(
                        p.occludes(&frame, r, nearest, how, &mut c),
                        expect,
                        "{w}x{h} {r:?} {nearest} {how:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn stale_pyramid_is_conservative_and_update_refreshes() {
        let mut frame = Frame::new(40, 30).expect("a 40x30 frame");
        let mut p = ZPyramid::new(40, 30).expect("a 40x30 pyramid");
        let r = PixelRect {
            x0: 4,
            y0: 4,
            x1: 12,
            y1: 12,
        };
        let how = HOWS[3];
        let mut c = PyramidCounts::default();
        assert!(!p.occludes(&frame, r, 0.3, how, &mut c));
        for y in 0..16 {
            for x in 0..16 {
                frame.write_fragment(x, y, 0.5, 1);
            }
        }
        // Not yet updated: the coarse levels are stale and fail to reject (conservative).
        assert!(!p.occludes(&frame, r, 0.3, how, &mut c));
        p.update(
            &frame,
            PixelRect {
                x0: 0,
                y0: 0,
                x1: 16,
                y1: 16,
            },
        );
        let mut c2 = PyramidCounts::default();
        assert!(p.occludes(&frame, r, 0.3, how, &mut c2));
        assert_eq!(c2.descents, 0);
        assert!(!p.occludes(&frame, r, 0.5, how, &mut c2)); // ties are not occluded
        assert!(!p.occludes(&frame, r, f32::NAN, how, &mut c2));
        assert!(p.occludes(
            &frame,
            PixelRect {
                x0: 50,
                y0: 0,
                x1: 60,
                y1: 5
            },
            0.0,
            how,
            &mut c2
        ));
    }

    #[test]
    fn global_reject_needs_a_full_frame() {
        let frame = frame_with(17, 9, |_, _| 0.4);
        let mut p = ZPyramid::new(17, 9).expect("a 17x9 pyramid");
        p.rebuild(&frame);
        let mut c = PyramidCounts::default();
        let r = PixelRect {
            x0: 3,
            y0: 2,
            x1: 9,
            y1: 8,
        };
        assert!(p.occludes(&frame, r, 0.2, HOWS[3], &mut c));
        assert_eq!(c.global_rejects, 1);
        p.clear();
        let mut c = PyramidCounts::default();
        // Stale zeros: no global reject, and the stale samples fail to reject (conservative).
        assert!(!p.occludes(&frame, r, 0.2, HOWS[3], &mut c));
        assert_eq!(c.global_rejects, 0);
    }
}
