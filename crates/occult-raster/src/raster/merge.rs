//! Sort-last drawing: workers draw parts of the triangle stream into private frames, which are
//! then merged into the frame under the (depth, item) rule, scalar or with AVX2.

use super::dispatch;
use super::project::Viewport;
use super::scan::FrameTarget;
use super::setup::TriStream;
use super::sinks::{union_rect, EMPTY_RECT};
use super::threads::Workers;
use super::{Draw, RasterMode, Rasterizer};
use crate::frame::Frame;
use occult_core::ItemId;
use std::time::Instant;

impl Rasterizer {
    /// Sort-last drawing for large draws on several threads: worker `k` draws the `k`-th part of
    /// the triangle stream directly (no binning) into the frame (`k = 0`) or a private scratch
    /// frame, and the scratch frames are then merged into the frame under the same (depth, item)
    /// rule, over the box each worker touched only, and cleared there for the next draw.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn draw_sort_last(
        &mut self,
        workers: &Workers<'_>,
        vp: &Viewport,
        frame: &mut Frame,
        draws: &[Draw<'_>],
        draw_starts: &[usize],
        vertex_offsets: &[usize],
        mode: RasterMode,
    ) -> Option<(u64, u64, f64, [u32; 4])> {
        let parts = workers.threads;
        let (w, h) = (vp.width as usize, vp.height as usize);
        if !self.ready_scratch(parts - 1, w * h) {
            return None;
        }
        self.scratch_clean = false;
        let isa = self.isa;
        let stream = TriStream::new(draws, draw_starts, vertex_offsets, &self.vertices);
        let total = stream.len();
        let mut targets: Vec<FrameTarget<'_>> = vec![FrameTarget::new(frame)];
        for (d, i) in self.scratch.iter_mut().take(parts - 1) {
            targets.push(FrameTarget::from_buffers(d, i, w));
        }
        let results: Vec<(u64, u64, Vec<[u32; 4]>, f64)> = workers.share((0..parts).collect(), |k| {
            let target = &targets[k];
            let t = Instant::now();
            // Worker k takes every parts-th block: each gets a share of near and far, large
            // and small triangles, and a block is long enough to keep the frame in cache.
            let (mut rasterized, mut written, mut boxes) = (0, 0, Vec::new());
            for start in (k * SORT_LAST_BLOCK..total).step_by(parts * SORT_LAST_BLOCK) {
                let range = start..(start + SORT_LAST_BLOCK).min(total);
                // SAFETY: each worker owns its own frame (the real one or a scratch one).
                let (r, f, d) = unsafe { dispatch::draw_direct(isa, vp, &stream, range, target, mode) };
                rasterized += r;
                written += f;
                if d[0] <= d[2] && d[1] <= d[3] {
                    boxes.push(d);
                }
            }
            (rasterized, written, boxes, t.elapsed().as_nanos() as f64)
        });
        let (depth, items) = frame.buffers_mut();
        for (k, (_, _, boxes, _)) in results.iter().enumerate().skip(1) {
            // The merge reads and resets only each row's span of the boxes of this worker's
            // blocks, not their bounding box: where the blocks of a coherent stream touch bands
            // of the frame, the merge (memory bound) skips the rows between them.
            let Some(spans) = row_spans(boxes, h) else { continue };
            let (sd, si) = &mut self.scratch[k - 1];
            let rows = MERGE_ROWS * w;
            let jobs = depth
                .chunks_mut(rows)
                .zip(items.chunks_mut(rows))
                .zip(sd.chunks_mut(rows))
                .zip(si.chunks_mut(rows))
                .zip(spans.chunks(MERGE_ROWS))
                .collect();
            workers.share(jobs, |((((d, it), sd), si), spans)| {
                let rows = d
                    .chunks_mut(w)
                    .zip(it.chunks_mut(w))
                    .zip(sd.chunks_mut(w))
                    .zip(si.chunks(w));
                for ((((d, it), sd), si), &(x0, x1)) in rows.zip(spans) {
                    let (x0, x1) = (x0 as usize, x1 as usize);
                    if x0 < x1 {
                        dispatch::merge_row(isa, &mut d[x0..x1], &mut it[x0..x1], &mut sd[x0..x1], &si[x0..x1], mode);
                    }
                }
            });
        }
        self.scratch_clean = true;
        // Every pixel written, by any worker, lies in one of the boxes.
        let written_box = results
            .iter()
            .flat_map(|r| r.2.iter())
            .fold(EMPTY_RECT, |a, &b| union_rect(a, b));
        let (rasterized, written, thread_ns) = results
            .iter()
            .fold((0, 0, 0.0), |(r, f, t), &(rr, ff, _, tt)| (r + rr, f + ff, t + tt));
        Some((rasterized, written, thread_ns, written_box))
    }
}

impl Rasterizer {
    /// Makes `count` cleared private frames of `pixels` pixels ready for a sort-last draw
    /// (those of another size dropped); false when memory is refused.
    pub(super) fn ready_scratch(&mut self, count: usize, pixels: usize) -> bool {
        // Private frames are kept cleared between draws; one a panic left drawn is dropped.
        if !self.scratch_clean {
            self.scratch.clear();
            self.scratch_clean = true;
        }
        self.scratch.retain(|(d, _)| d.len() == pixels);
        while self.scratch.len() < count {
            let (mut d, mut i) = (Vec::new(), Vec::new());
            if d.try_reserve_exact(pixels).is_err() || i.try_reserve_exact(pixels).is_err() {
                return false;
            }
            d.resize(pixels, crate::CLEAR_DEPTH);
            i.resize(pixels, occult_core::NO_ITEM);
            self.scratch.push((d, i));
        }
        true
    }
}

/// Per row of a `height`-row frame, the half-open pixel span `x0..x1` that the inclusive boxes
/// touch (`x0 == x1`: none); `None` when there are no boxes.
pub(super) fn row_spans(boxes: &[[u32; 4]], height: usize) -> Option<Vec<(u32, u32)>> {
    if boxes.is_empty() {
        return None;
    }
    let mut spans = vec![(u32::MAX, 0u32); height];
    for b in boxes {
        for span in &mut spans[b[1] as usize..=b[3] as usize] {
            *span = (span.0.min(b[0]), span.1.max(b[2] + 1));
        }
    }
    for span in &mut spans {
        span.0 = span.0.min(span.1);
    }
    Some(spans)
}

/// See [`dispatch::merge_row`]. The row goes by runs of [`MERGE_RUN`] pixels: a run the worker
/// left clear (the rows between its triangles, the parts of the frame the other workers drew)
/// costs only the read of its private depths; the others are merged branch-free, so that the
/// compiler vectorizes them (a branch per pixel on whether the worker drew it mispredicts
/// along the borders of everything drawn), and their private depths reset.
#[inline(always)]
pub(super) fn merge_row(d: &mut [f32], it: &mut [ItemId], sd: &mut [f32], si: &[ItemId], mode: RasterMode) {
    let n = d.len();
    let (it, sd, si) = (&mut it[..n], &mut sd[..n], &si[..n]);
    let mut dc = d.chunks_exact_mut(MERGE_RUN);
    let mut ic = it.chunks_exact_mut(MERGE_RUN);
    let mut sdc = sd.chunks_exact_mut(MERGE_RUN);
    let mut sic = si.chunks_exact(MERGE_RUN);
    for (((d, it), sd), si) in (&mut dc).zip(&mut ic).zip(&mut sdc).zip(&mut sic) {
        // Not an early-exit search: a fold over the run that the compiler vectorizes.
        let drawn = sd.iter().fold(false, |drawn, &s| drawn | (s != crate::CLEAR_DEPTH));
        if drawn {
            merge_run(d, it, sd, si, mode);
        }
    }
    merge_run(
        dc.into_remainder(),
        ic.into_remainder(),
        sdc.into_remainder(),
        sic.remainder(),
        mode,
    );
}

/// Merges one run of private pixels into the frame's, branch-free, and clears their depths.
#[inline(always)]
pub(super) fn merge_run(d: &mut [f32], it: &mut [ItemId], sd: &mut [f32], si: &[ItemId], mode: RasterMode) {
    let n = d.len();
    let (it, sd, si) = (&mut it[..n], &mut sd[..n], &si[..n]);
    if mode == RasterMode::Full {
        for x in 0..n {
            let (s, t) = (sd[x], d[x]);
            // A clear private pixel was not drawn: its item is stale and must lose. A fragment
            // always beats a clear pixel, so the rule is keep_fragment's for drawn pixels.
            let win = s != crate::CLEAR_DEPTH && (s > t || (s == t && si[x] < it[x]));
            d[x] = if win { s } else { t };
            it[x] = if win { si[x] } else { it[x] };
        }
    } else {
        for x in 0..n {
            // As in full mode, a clear private pixel loses even to a frame depth below it
            // (whether its run was skipped or not).
            let win = sd[x] != crate::CLEAR_DEPTH && sd[x] > d[x];
            d[x] = if win { sd[x] } else { d[x] };
        }
    }
    // Only depth is reset: a private item matters only where the private depth is not clear,
    // so stale items are never read.
    sd.fill(crate::CLEAR_DEPTH);
}

/// Pixels of a sort-last merge run: a run the worker left clear is skipped (see `merge_row`).
/// Sixteen: 64 bytes of depths (runs start at a span's first pixel, not at a cache line).
pub(super) const MERGE_RUN: usize = 16;

/// Rows of the frame per job of a sort-last merge.
pub(super) const MERGE_ROWS: usize = 8;

/// Triangles per block handed round-robin to the workers of a sort-last draw.
pub(super) const SORT_LAST_BLOCK: usize = 16 * 1024;

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::simd::Isa;

    #[test]
    fn merge_keeps_the_rule_on_rows_with_clear_runs() {
        // Rows of every length around the run size, private pixels drawn in stretches (with
        // depth ties) between long clear ones, frame depths below the clear value among them,
        // against the rule applied pixel by pixel, on each instruction set the machine has.
        use crate::CLEAR_DEPTH;
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
        for n in (0..70).chain([333, 1000]) {
            for mode in [RasterMode::Full, RasterMode::DepthOnly] {
                let depths = [0.25f32, 0.5, 0.75];
                let frame_depths = [CLEAR_DEPTH, -0.0, -0.5, 0.25, 0.5, 0.75];
                let d: Vec<f32> = (0..n).map(|_| frame_depths[rng.random_range(0..6)]).collect();
                let it: Vec<ItemId> = (0..n).map(|_| rng.random_range(0..4)).collect();
                let mut drawn = rng.random_bool(0.5);
                let sd: Vec<f32> = (0..n)
                    .map(|_| {
                        drawn ^= rng.random_bool(0.05);
                        if drawn {
                            depths[rng.random_range(0..3)]
                        } else {
                            CLEAR_DEPTH
                        }
                    })
                    .collect();
                // Stale items under clear private depths must never win.
                let si: Vec<ItemId> = (0..n).map(|_| rng.random_range(0..4)).collect();
                for isa in [Isa::select(false), Isa::select(true)] {
                    let (mut got_d, mut got_it, mut got_sd) = (d.clone(), it.clone(), sd.clone());
                    dispatch::merge_row(isa, &mut got_d, &mut got_it, &mut got_sd, &si, mode);
                    for x in 0..n {
                        let (mut want_d, mut want_it) = (d[x], it[x]);
                        if sd[x] != CLEAR_DEPTH {
                            let wins = match mode {
                                RasterMode::Full => sd[x] > d[x] || (sd[x] == d[x] && si[x] < it[x]),
                                RasterMode::DepthOnly => sd[x] > d[x],
                            };
                            if wins {
                                want_d = sd[x];
                                if mode == RasterMode::Full {
                                    want_it = si[x];
                                }
                            }
                        }
                        assert_eq!(
                            (got_d[x].to_bits(), got_it[x]),
                            (want_d.to_bits(), want_it),
                            "{isa:?}, {mode:?}, row {n}, pixel {x}"
                        );
                    }
                    assert!(
                        got_sd.iter().all(|&s| s == CLEAR_DEPTH),
                        "{isa:?}: private depths reset"
                    );
                }
            }
        }
    }
}
