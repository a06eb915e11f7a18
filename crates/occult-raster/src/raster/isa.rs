//! The instruction set of the hot loops, chosen once per rasterizer, and the entry points
//! that run each hot loop compiled for it.

use super::merge::merge_row;
use super::project::{project_all, project_all_avx2, ProjVertex, Viewport};
use super::scan::{scan_tile, FrameTarget};
use super::setup::setup_range;
use super::sinks::{draw_direct, ChunkBins};
use super::{Draw, RasterMode};
use occult_core::{ItemId, Mat4, Vec3};
use std::ops::Range;

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
pub(super) unsafe fn merge_row_avx2(d: &mut [f32], it: &mut [ItemId], sd: &mut [f32], si: &[ItemId], mode: RasterMode) {
    merge_row(d, it, sd, si, mode)
}

/// The instruction set of the hot loops, chosen once at run time. The same Rust code is compiled
/// for each; Rust never contracts floating-point operations, so results are bit-identical.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Isa {
    Baseline,
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Isa {
    pub(super) fn select(simd: bool) -> Self {
        #[cfg(target_arch = "x86_64")]
        if simd
            && is_x86_feature_detected!("avx2")
            && is_x86_feature_detected!("bmi1")
            && is_x86_feature_detected!("bmi2")
            && is_x86_feature_detected!("lzcnt")
            && is_x86_feature_detected!("popcnt")
        {
            return Isa::Avx2;
        }
        let _ = simd;
        Isa::Baseline
    }

    /// Merges one row of a worker's private frame into the frame under the (depth, item) rule
    /// and resets the private depth to clear.
    pub(super) fn merge_row(self, d: &mut [f32], it: &mut [ItemId], sd: &mut [f32], si: &[ItemId], mode: RasterMode) {
        match self {
            Isa::Baseline => merge_row(d, it, sd, si, mode),
            // SAFETY: `select` checked that the processor has these features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { merge_row_avx2(d, it, sd, si, mode) },
        }
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn setup_range(
        self,
        vp: &Viewport,
        draws: &[Draw<'_>],
        draw_starts: &[usize],
        vertex_offsets: &[usize],
        vertices: &[ProjVertex],
        range: Range<usize>,
        out: &mut ChunkBins,
    ) {
        match self {
            Isa::Baseline => setup_range::<false>(vp, draws, draw_starts, vertex_offsets, vertices, range, out),
            // SAFETY: `select` checked that the processor has these features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { setup_range_avx2(vp, draws, draw_starts, vertex_offsets, vertices, range, out) },
        }
    }

    /// Projects `positions` into `out` (as many as `out` holds).
    pub(super) fn project_all(
        self,
        vp: &Viewport,
        clip_from_object: &Mat4,
        positions: &[Vec3],
        out: &mut [ProjVertex],
    ) {
        match self {
            Isa::Baseline => project_all(vp, clip_from_object, positions, out),
            // SAFETY: `select` checked that the processor has these features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { project_all_avx2(vp, clip_from_object, positions, out) },
        }
    }

    /// Sets up and scans `range` of the triangle stream at once over the whole frame;
    /// returns (triangles rasterized, fragments written, inclusive pixel box touched).
    ///
    /// # Safety
    /// No other thread may access `target` during the call.
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn draw_direct(
        self,
        vp: &Viewport,
        draws: &[Draw<'_>],
        draw_starts: &[usize],
        vertex_offsets: &[usize],
        vertices: &[ProjVertex],
        range: Range<usize>,
        target: &FrameTarget,
        mode: RasterMode,
    ) -> (u64, u64, [u32; 4]) {
        match self {
            // SAFETY: forwarded.
            Isa::Baseline => unsafe {
                draw_direct::<false>(vp, draws, draw_starts, vertex_offsets, vertices, range, target, mode)
            },
            // SAFETY: forwarded; `select` checked the processor's features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe {
                draw_direct_avx2(vp, draws, draw_starts, vertex_offsets, vertices, range, target, mode)
            },
        }
    }

    /// # Safety
    /// As [`scan_tile`].
    pub(super) unsafe fn scan_tile(
        self,
        vp: &Viewport,
        chunks: &[ChunkBins],
        tile: usize,
        rect: [u32; 4],
        target: &FrameTarget,
        mode: RasterMode,
    ) -> u64 {
        match self {
            // SAFETY: forwarded.
            Isa::Baseline => unsafe { scan_tile::<false>(vp, chunks, tile, rect, target, mode) },
            // SAFETY: forwarded; `select` checked the processor's features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { scan_tile_avx2(vp, chunks, tile, rect, target, mode) },
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn setup_range_avx2(
    vp: &Viewport,
    draws: &[Draw<'_>],
    draw_starts: &[usize],
    vertex_offsets: &[usize],
    vertices: &[ProjVertex],
    range: Range<usize>,
    out: &mut ChunkBins,
) {
    setup_range::<true>(vp, draws, draw_starts, vertex_offsets, vertices, range, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn draw_direct_avx2(
    vp: &Viewport,
    draws: &[Draw<'_>],
    draw_starts: &[usize],
    vertex_offsets: &[usize],
    vertices: &[ProjVertex],
    range: Range<usize>,
    target: &FrameTarget,
    mode: RasterMode,
) -> (u64, u64, [u32; 4]) {
    // SAFETY: forwarded.
    unsafe { draw_direct::<true>(vp, draws, draw_starts, vertex_offsets, vertices, range, target, mode) }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
pub(super) unsafe fn scan_tile_avx2(
    vp: &Viewport,
    chunks: &[ChunkBins],
    tile: usize,
    rect: [u32; 4],
    target: &FrameTarget,
    mode: RasterMode,
) -> u64 {
    // SAFETY: forwarded.
    unsafe { scan_tile::<true>(vp, chunks, tile, rect, target, mode) }
}
