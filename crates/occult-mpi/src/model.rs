//! Scaling on paper: the communication of sort-last compositing per frame and rank, measured
//! over thread ranks (the bytes a rank sends do not depend on the transport) and predicted by
//! binary swap's known cost for ranks and frame sizes this machine cannot run.
//!
//! # The model
//! With `p` ranks, `q` the largest power of two ≤ `p`, `n` pixels of [`BYTES_PER_PIXEL`]
//! bytes `B` (Ma et al. 1994; Moreland et al., "An image compositing solution at scale",
//! SC 2011, for IceT's use of it):
//! - swap: `log2 q` rounds; a rank sends `n·B·(1/2 + 1/4 + … + 1/q) = n·B·(1 − 1/q)`;
//! - fold (`p > q`): the `p − q` extra ranks send `n·B` once;
//! - gather: each of ranks `1..q` sends `n·B/q`; rank 0 receives `n·B·(1 − 1/q)`;
//! - time, the α–β model: `(log2 q + 1)·α + bytes/β` on a rank's link, plus merging
//!   `n·(1 − 1/q)` pixels at `γ` per pixel; rank 0's gather is bound by its own link
//!   (`n·B·(1 − 1/q)/β`), the term that stops binary swap's scaling at large `p`.
//!
//! `α`, `β` are the interconnect's ([`Link`]); `γ` is measured here.

use std::sync::Arc;
use std::time::Instant;

use occult_core::{Scene, View};
use occult_raster::{Frame, RasterConfig};
use occult_render::{Algorithm, RenderOptions, Result};
use serde::Serialize;

use crate::comm::run_threads;
use crate::composite::BYTES_PER_PIXEL;
use crate::sortlast::{sort_last_options, SortLastConfig};

/// An interconnect, for the α–β model.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Link {
    /// Message latency α, µs.
    pub latency_us: f64,
    /// Bandwidth β per rank's link, GB/s (10^9 bytes per second).
    pub bandwidth_gb_s: f64,
}

impl Default for Link {
    /// InfiniBand EDR (100 Gb/s): about 12 GB/s and 1.5 µs.
    fn default() -> Self {
        Self {
            latency_us: 1.5,
            bandwidth_gb_s: 12.0,
        }
    }
}

/// One rank count's communication per frame, measured or modelled.
#[derive(Clone, Debug, Serialize)]
pub struct RanksCost {
    /// Ranks.
    pub ranks: usize,
    /// Frame width × height, pixels.
    pub width: u32,
    /// Frame height.
    pub height: u32,
    /// Most bytes one rank sent in a frame.
    pub bytes_sent_max: f64,
    /// Bytes sent per rank and frame, mean over ranks.
    pub bytes_sent_mean: f64,
    /// Bytes rank 0 received in a frame.
    pub bytes_received_root: f64,
    /// Compositing time per frame, ms: measured wall time of rank 0 (thread ranks on this
    /// machine), or the model's.
    pub composite_ms: f64,
    /// True for a measurement, false for the model.
    pub measured: bool,
}

/// The model's cost of compositing one `width` × `height` frame over `ranks` ranks.
/// `merge_ns_per_pixel`: γ.
pub fn model(ranks: usize, width: u32, height: u32, link: Link, merge_ns_per_pixel: f64) -> RanksCost {
    let p = ranks.max(1);
    let q = 1usize << (usize::BITS - 1 - p.leading_zeros());
    let n = f64::from(width) * f64::from(height);
    let b = BYTES_PER_PIXEL as f64;
    let frame = n * b;
    let share = 1.0 - 1.0 / q as f64;
    // A rank below q: swap plus its finished part (rank 0 sends nothing in the gather).
    let swap = frame * share;
    let gather_part = frame / q as f64;
    let folded = (p - q) as f64;
    let bytes_sent_max = if p == 1 {
        0.0
    } else {
        (swap + if q > 1 { gather_part } else { 0.0 }).max(if folded > 0.0 { frame } else { 0.0 })
    };
    let total = swap * q as f64 + gather_part * (q as f64 - 1.0) + frame * folded;
    let bytes_received_root = if p == 1 {
        0.0
    } else {
        swap + frame * share + if folded > 0.0 { frame } else { 0.0 }
    };
    let rounds = q.trailing_zeros() as f64 + 1.0 + if folded > 0.0 { 1.0 } else { 0.0 };
    let beta = link.bandwidth_gb_s * 1e9;
    let merged = n * share + if folded > 0.0 { n } else { 0.0 };
    let composite_ms = if p == 1 {
        0.0
    } else {
        (rounds * link.latency_us * 1e-6
            + (swap + if folded > 0.0 { frame } else { 0.0 }) / beta
            + frame * share / beta
            + merged * merge_ns_per_pixel * 1e-9)
            * 1e3
    };
    RanksCost {
        ranks: p,
        width,
        height,
        bytes_sent_max,
        bytes_sent_mean: total / p as f64,
        bytes_received_root,
        composite_ms,
        measured: false,
    }
}

/// Measures sort-last `zbuffer` on `scene` over `ranks` thread ranks (one rasterizer thread
/// each), rendering `views`: bytes per rank and frame from the composites' own counts, and
/// rank 0's compositing time.
///
/// # Errors
/// Build and render errors of any rank.
pub fn measure(scene: &Arc<Scene>, views: &[View], ranks: usize) -> Result<RanksCost> {
    let (width, height) = views.first().map_or((1, 1), |v| (v.width(), v.height()));
    // Rank 0's sums over the frames: most bytes a rank sent, bytes all ranks sent, and its
    // time exchanging (agreement, composite, report).
    let out = run_threads(ranks, |comm| -> Result<(f64, f64, f64)> {
        let base = RenderOptions {
            raster: RasterConfig {
                threads: 1,
                ..RasterConfig::default()
            },
            ..RenderOptions::default()
        };
        let options = sort_last_options(comm.clone(), base, SortLastConfig::default());
        let mut r = Algorithm::ZBUFFER.build(scene.clone(), &options)?;
        let mut frame = Frame::new(width, height)?;
        let mut sums = (0.0, 0.0, 0.0);
        for v in views {
            let c = r.render(v, &mut frame)?.counters;
            sums.0 += c.get("mpi_bytes_sent_max") as f64;
            sums.1 += c.get("mpi_bytes_total") as f64;
            sums.2 += c.get("mpi_comm_us") as f64 / 1e3;
        }
        Ok(sums)
    });
    let (max, total, comm_ms) = out
        .into_iter()
        .next()
        .expect("rank 0 exists")
        .map_err(|_| occult_render::RenderError::Ranks("a thread rank panicked".into()))??;
    let frames = views.len().max(1) as f64;
    let modelled = model(ranks, width, height, Link::default(), 0.0);
    Ok(RanksCost {
        ranks,
        width,
        height,
        bytes_sent_max: max / frames,
        bytes_sent_mean: total / frames / ranks as f64,
        // Not counted by the composite's report; binary swap's is exact.
        bytes_received_root: modelled.bytes_received_root,
        composite_ms: comm_ms / frames,
        measured: true,
    })
}

/// γ: the merge's cost per pixel here, ns (one merge of a `width` × `height` frame pair whose
/// every pixel is covered, encoded and decoded as on the wire, the best of three).
pub fn merge_ns_per_pixel(width: u32, height: u32) -> f64 {
    let run = || {
        let out = run_threads(2, |comm| {
            let mut f = Frame::new(width, height).expect("a frame of a size the caller drew");
            // Covered pixels: empty ones cost nothing to send or merge.
            let (depth, items) = f.buffers_mut();
            for (i, (d, item)) in depth.iter_mut().zip(items.iter_mut()).enumerate() {
                *d = 0.5 + (i % 7) as f32 * 0.01;
                *item = (i * 3 + comm.rank()) as u64;
            }
            let t = Instant::now();
            crate::composite::composite(comm.as_ref(), &mut f, false).expect("thread ranks stay");
            t.elapsed().as_secs_f64()
        });
        let secs = out.into_iter().flatten().fold(0.0f64, f64::max);
        // Two ranks: each merges half the frame, and rank 0 copies the other half.
        secs * 1e9 / (f64::from(width) * f64::from(height))
    };
    (0..3).map(|_| run()).fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_model_counts_binary_swap_bytes() {
        let (w, h) = (64, 32);
        let frame = f64::from(w * h) * BYTES_PER_PIXEL as f64;
        assert_eq!(model(1, w, h, Link::default(), 1.0).bytes_sent_max, 0.0);
        // 2 ranks: rank 1 sends half in the swap and its finished half to rank 0.
        assert_eq!(model(2, w, h, Link::default(), 1.0).bytes_sent_max, frame);
        // 4 ranks: 3/4 in the swap plus a quarter.
        assert_eq!(model(4, w, h, Link::default(), 1.0).bytes_sent_max, frame);
        // 3 ranks: rank 2 folds its whole frame into rank 0.
        assert_eq!(model(3, w, h, Link::default(), 1.0).bytes_sent_max, frame);
        let big = model(1024, 3840, 2160, Link::default(), 1.0);
        assert!(big.composite_ms > model(64, 3840, 2160, Link::default(), 1.0).composite_ms * 0.9);
    }
}
