//! The entry points of the hot loops, each compiled once per instruction set by
//! [`occult_core::isa_dispatch!`] and run for the [`occult_core::simd::Isa`] a rasterizer
//! chose once ([`occult_core::simd::Isa::select`] of [`super::RasterConfig::simd`]). Each
//! takes that `Isa` first. The const-generic bodies (`AVX2 = true`) are the ones that may use AVX2
//! intrinsics: they only run inside the AVX2 wrappers written here.

use super::project::{ProjVertex, Viewport};
use super::scan::FrameTarget;
use super::setup::TriStream;
use super::sinks::ChunkBins;
use super::RasterMode;
use occult_core::{ItemId, Mat4, Vec3};
use std::ops::Range;

/// [`occult_core::isa_dispatch!`] with the rasterizer's one AVX2 feature set (the features of
/// [`occult_core::simd::Isa::Avx2`], all of which the setup's and scan's bit tricks may use).
macro_rules! hot_loop {
    ($(#[$attr:meta])* $vis:vis fn $name:ident $args:tt -> $ret:ty = $base:expr, $avx2:expr;) => {
        occult_core::isa_dispatch! {
            $(#[$attr])*
            $vis fn $name $args -> $ret;
            baseline => $base,
            avx2("avx2,bmi1,bmi2,popcnt,lzcnt") => $avx2,
        }
    };
    ($(#[$attr:meta])* $vis:vis unsafe fn $name:ident $args:tt -> $ret:ty = $base:expr, $avx2:expr;) => {
        occult_core::isa_dispatch! {
            $(#[$attr])*
            $vis unsafe fn $name $args -> $ret;
            baseline => $base,
            avx2("avx2,bmi1,bmi2,popcnt,lzcnt") => $avx2,
        }
    };
}

hot_loop! {
    /// Merges one row of a worker's private frame into the frame under the (depth, item) rule
    /// and resets the private depth to clear.
    pub(super) fn merge_row(d: &mut [f32], it: &mut [ItemId], sd: &mut [f32], si: &[ItemId], mode: RasterMode) -> ()
        = super::merge::merge_row, super::merge::merge_row;
}

hot_loop! {
    /// Sets up and bins the triangles `range` of the stream into `out`.
    pub(super) fn setup_range(vp: &Viewport, stream: &TriStream<'_>, range: Range<usize>, out: &mut ChunkBins) -> () = super::setup::setup_range::<false>, super::setup::setup_range::<true>;
}

hot_loop! {
    /// Projects `positions` into `out` (as many as `out` holds).
    pub(super) fn project_all(vp: &Viewport, clip_from_object: &Mat4, positions: &[Vec3], out: &mut [ProjVertex]) -> ()
        = super::project::project_all::<false>, super::project::project_all::<true>;
}

hot_loop! {
    /// Sets up and scans `range` of the triangle stream at once over the whole frame;
    /// returns (triangles rasterized, fragments written, the inclusive pixel box of the
    /// triangles that wrote any: every pixel written lies in it).
    ///
    /// # Safety
    /// No other thread may access `target` during the call.
    pub(super) unsafe fn draw_direct(
        vp: &Viewport,
        stream: &TriStream<'_>,
        range: Range<usize>,
        target: &FrameTarget<'_>,
        mode: RasterMode,
    ) -> (u64, u64, [u32; 4]) = super::sinks::draw_direct::<false>, super::sinks::draw_direct::<true>;
}

hot_loop! {
    /// Sets up every triangle of `range` of the stream and scans it over the rows of bands
    /// `band, band + bands, …` only; returns (triangles rasterized, fragments written, the
    /// inclusive pixel box of the triangles that wrote any).
    ///
    /// # Safety
    /// No other thread may access the rows of those bands in `target` during the call.
    pub(super) unsafe fn draw_banded(
        vp: &Viewport,
        stream: &TriStream<'_>,
        range: Range<usize>,
        target: &FrameTarget<'_>,
        mode: RasterMode,
        band: u32,
        bands: u32,
    ) -> (u64, u64, [u32; 4]) = super::sinks::draw_banded::<false>, super::sinks::draw_banded::<true>;
}

hot_loop! {
    /// Scans every triangle binned to `tile`.
    ///
    /// # Safety
    /// As [`super::scan::scan_tile`].
    pub(super) unsafe fn scan_tile(vp: &Viewport, chunks: &[ChunkBins], tile: usize, target: &FrameTarget<'_>, mode: RasterMode) -> u64 = super::scan::scan_tile::<false>, super::scan::scan_tile::<true>;
}
