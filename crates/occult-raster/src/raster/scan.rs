//! The scan: exact integer edge functions, 8-pixel inside masks for small boxes, per-row spans
//! for larger ones, and the fragment writes under the (depth, item) rule.

use super::project::Viewport;
use super::setup::TriSetup;
use super::sinks::ChunkBins;
use super::{RasterMode, HALF, SUB};
use crate::frame::Frame;
use occult_core::ItemId;
use std::marker::PhantomData;

/// Raw access to a frame's buffers (or a private frame's), shared by the tasks of one draw
/// that write disjoint pixels: tiles of the binned pass, or each sort-last worker its own frame.
/// It borrows the buffers mutably for `'a`, so they outlive every write through it and nothing
/// else touches them meanwhile; which task writes which pixels is the scan's callers' contract
/// (`# Safety` of [`scan_triangle`]).
pub(super) struct FrameTarget<'a> {
    pub(super) depth: *mut f32,
    pub(super) items: *mut ItemId,
    pub(super) width: usize,
    _buffers: PhantomData<(&'a mut [f32], &'a mut [ItemId])>,
}

// SAFETY: the buffers are borrowed for `'a` (no one else reads or writes them meanwhile), and
// the pointers are only written through `scan_triangle` and `write_mask`, whose callers
// guarantee that concurrent calls touch disjoint pixels (one task per tile or per frame).
unsafe impl Sync for FrameTarget<'_> {}
// SAFETY: as for `Sync`: the target owns its borrow of the buffers.
unsafe impl Send for FrameTarget<'_> {}

impl<'a> FrameTarget<'a> {
    /// The depth and item buffers of `frame`.
    pub(super) fn new(frame: &'a mut Frame) -> Self {
        let width = frame.width() as usize;
        // The rows written are marked by the draw (`Rasterizer::draw`).
        let (depth, items) = frame.buffers_unmarked();
        Self::from_buffers(depth, items, width)
    }

    /// Depth and item buffers of rows of `width` pixels.
    ///
    /// # Panics
    /// If the buffers' lengths differ (a programmer error).
    pub(super) fn from_buffers(depth: &'a mut [f32], items: &'a mut [ItemId], width: usize) -> Self {
        assert_eq!(depth.len(), items.len(), "depth and item buffers of one frame");
        Self {
            depth: depth.as_mut_ptr(),
            items: items.as_mut_ptr(),
            width,
            _buffers: PhantomData,
        }
    }
}

/// Scans every triangle binned to `tile` (the pixels of [`Viewport::tile_rect`]).
///
/// # Safety
/// No other thread may access the pixels of the tile in `target` during the call.
#[inline(always)]
pub(super) unsafe fn scan_tile<const AVX2: bool>(
    vp: &Viewport,
    chunks: &[ChunkBins],
    tile: usize,
    target: &FrameTarget<'_>,
    mode: RasterMode,
) -> u64 {
    let rect = vp.tile_rect(tile);
    let mut written = 0;
    for ch in chunks {
        for &r in &ch.bins[tile] {
            // SAFETY: forwarded.
            written += unsafe { scan_triangle::<AVX2>(vp, &ch.records[r as usize], rect, target, mode) };
        }
    }
    written
}

/// How [`scan_small`] finds the covered centres of a triangle it takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum SmallCover {
    /// The edge functions as [`scan_triangle`] derives them: their values at the centre of
    /// pixel `(px0, py0)` and their steps per pixel right and down.
    Edges {
        row: [i32; 3],
        step_x: [i32; 3],
        step_y: [i32; 3],
    },
    /// For boxes of at most [`TINY`] × [`TINY`] pixels, the covered centres themselves as
    /// [`scan_small`]'s mask (bit `8·j + i` for centre `(i, j)` from the box's corner),
    /// derived in lanes by the 8-lane setup, which then reads no edge functions back.
    Mask(u32),
}

/// Spans shorter than this are written pixel by pixel; longer ones by the vectorized loop.
pub(super) const SHORT_SPAN: usize = 16;

/// Hints the processor to fetch the depth and item of pixel `i`; never faults, never changes
/// results.
#[inline(always)]
pub(super) fn prefetch(target: &FrameTarget<'_>, i: usize) {
    occult_core::simd::prefetch(target.depth.wrapping_add(i));
    occult_core::simd::prefetch(target.items.wrapping_add(i));
}

/// Side of the block scanned without branches for small triangles.
pub(super) const SMALL: u32 = 8;
/// Boxes of at most this many pixels a side have their mask of covered centres derived by the
/// 8-lane setup (in 32-bit lanes: the mask's bits reach `8·(TINY − 1) + TINY − 1`).
pub(super) const TINY: u32 = 4;
const _: () = assert!(SMALL * (TINY - 1) + TINY <= 31);
/// Triangles whose snapped corners span fewer pixels than this (both axes) have their inside
/// masks computed in i32 lanes. The lanes reach up to 8 pixels past the box, so every point
/// evaluated lies within (56 + 8)·√2 pixels of a corner, and |E| <= (64·√2·256)² < 2^31.
pub(super) const MASKED: u32 = 56;

/// Scans a box of at most `SMALL × SMALL` pixels: the inside mask of each row is formed
/// without branches in 32-bit lanes (tiny triangles make per-pixel branches mispredict), or
/// taken from a [`SmallCover::Mask`] the 8-lane setup formed already (anchored at the box's
/// corner, which is then `rect`'s), then only the covered pixels are depth-tested.
/// Bit-identical to the general scan.
///
/// 32 bits suffice: the caller checked that the snapped corners span fewer than [`MASKED`]
/// pixels, and every centre `p` of the 8 × 8 block lies within 8 pixels of the triangle's box,
/// so `|E(p)| = |(v1 - v0) × (p - v0)| <= (64·√2·256)² < 2^31` in 1/256 units.
///
/// # Safety
/// As [`scan_triangle`].
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) unsafe fn scan_small<const AVX2: bool>(
    vp: &Viewport,
    t: &TriSetup,
    rect: [u32; 4],
    cover: SmallCover,
    target: &FrameTarget<'_>,
    mode: RasterMode,
) -> u64 {
    let [x0, y0, x1, y1] = rect;
    let w = x1 - x0 + 1;
    let mask = match cover {
        SmallCover::Mask(tiny) => {
            debug_assert_eq!(
                (x0, y0),
                (t.px0 as u32, t.py0 as u32),
                "a lane mask is anchored at the box"
            );
            tiny as u64
        }
        SmallCover::Edges {
            mut row,
            step_x: sx,
            step_y,
        } => {
            let mut mask = 0u64;
            let valid = (1u64 << w) - 1;
            for j in 0..=(y1 - y0) {
                let bits = row_mask_in::<AVX2>(row, sx);
                mask |= (bits & valid) << (j * SMALL);
                row[0] += step_y[0];
                row[1] += step_y[1];
                row[2] += step_y[2];
            }
            mask
        }
    };
    // SAFETY: the mask's centres lie in the caller's rectangle, owned by this task.
    match mode {
        RasterMode::Full => unsafe { write_mask::<true>(vp, t, x0, y0, mask, target) },
        RasterMode::DepthOnly => unsafe { write_mask::<false>(vp, t, x0, y0, mask, target) },
    }
}

/// The per-pixel loop of [`scan_small`]: depth-tests and writes the fragments of `t` at the
/// centres of `mask` (bit `8·j + i` for pixel `(x0 + i, y0 + j)`), items too when `FULL`.
///
/// # Safety
/// Those pixels lie in the frame, and the caller owns them.
#[inline(always)]
pub(super) unsafe fn write_mask<const FULL: bool>(
    vp: &Viewport,
    t: &TriSetup,
    x0: u32,
    y0: u32,
    mut mask: u64,
    target: &FrameTarget<'_>,
) -> u64 {
    let mode = if FULL { RasterMode::Full } else { RasterMode::DepthOnly };
    let mut written = 0;
    // In locals: the compiler cannot tell that the fragment writes leave `target` unchanged,
    // and would load these again for every fragment.
    let (depth, items, width) = (target.depth, target.items, target.width);
    while mask != 0 {
        let k = mask.trailing_zeros();
        mask &= mask - 1;
        let (x, y) = (x0 + k % SMALL, y0 + k / SMALL);
        let row_depth = row_depth(t, y);
        let z = depth_at(t, row_depth, x);
        if z >= vp.far_depth {
            let i = y as usize * width + x as usize;
            // SAFETY: forwarded from the caller.
            let (d, it) = unsafe { (&mut *depth.add(i), &mut *items.add(i)) };
            written += write_fragment(d, it, z, t.item, mode) as u64;
        }
    }
    written
}

/// Inside bits of the 8 pixel centres `i = 0..8` of a row whose edge functions at `i = 0` are
/// `row` and grow by `sx` per pixel: bit `i` set when all three are `>= 0`.
#[inline(always)]
pub(super) fn row_mask(row: [i32; 3], sx: [i32; 3]) -> u64 {
    let mut bits = 0u64;
    for i in 0..SMALL as i32 {
        let e = (row[0] + sx[0] * i) | (row[1] + sx[1] * i) | (row[2] + sx[2] * i);
        bits |= ((e >= 0) as u64) << i;
    }
    bits
}

/// [`row_mask`] in the instruction set of the scan's instantiation: with `AVX2`, in eight 32-bit
/// lanes (the same bits, tested).
#[inline(always)]
fn row_mask_in<const AVX2: bool>(row: [i32; 3], sx: [i32; 3]) -> u64 {
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        use occult_core::simd::{Avx2, I32x8};
        // SAFETY: the AVX2 instantiation only runs where the dispatcher found AVX2.
        let avx2 = unsafe { Avx2::new_unchecked() };
        let lane = I32x8::lane_index(avx2);
        let e = |k: usize| I32x8::splat(avx2, row[k]).wrapping_add(I32x8::splat(avx2, sx[k]).wrapping_mul(lane));
        // Sign bit set means some edge function is negative: outside.
        return (!e(0).or(e(1)).or(e(2)).sign_mask() & 0xff) as u64;
    }
    row_mask(row, sx)
}

/// Writes a covered fragment under the visibility rule (`keep_fragment`'s). The stored item is
/// read only on a depth tie (rare and predictable): where the fragment wins, its item line is
/// written without being waited for.
#[inline(always)]
pub(super) fn write_fragment(d: &mut f32, it: &mut ItemId, z: f32, item: ItemId, mode: RasterMode) -> bool {
    let stored = *d;
    let keep = if z == stored {
        mode == RasterMode::Full && item < *it
    } else {
        z > stored
    };
    if keep {
        *d = z;
        if mode == RasterMode::Full {
            *it = item;
        }
    }
    keep
}

/// Writes the covered pixels `xa..xa + depth.len()` of one row: no coverage test left, so
/// the loop is branch-free and the compiler vectorizes it (8 lanes where AVX2 is enabled).
#[inline(always)]
pub(super) fn write_span(
    vp: &Viewport,
    t: &TriSetup,
    row_depth: f32,
    xa: u32,
    depth: &mut [f32],
    items: &mut [ItemId],
    mode: RasterMode,
) -> u64 {
    let mut written = 0u32;
    let far = vp.far_depth;
    if depth.len() < SHORT_SPAN {
        return write_pixels(vp, t, row_depth, xa, depth, items, mode);
    }
    match mode {
        RasterMode::Full => {
            for (i, (d, it)) in depth.iter_mut().zip(items.iter_mut()).enumerate() {
                let z = depth_at(t, row_depth, xa + i as u32);
                let keep = (z >= far) & ((z > *d) | ((z == *d) & (t.item < *it)));
                *d = if keep { z } else { *d };
                *it = if keep { t.item } else { *it };
                written += keep as u32;
            }
        }
        RasterMode::DepthOnly => {
            for (i, d) in depth.iter_mut().enumerate() {
                let z = depth_at(t, row_depth, xa + i as u32);
                let keep = (z >= far) & (z > *d);
                *d = if keep { z } else { *d };
                written += keep as u32;
            }
        }
    }
    written as u64
}

/// [`write_span`] pixel by pixel, each with a branch, the item buffer read only on a depth tie
/// (see [`write_fragment`]): for short spans.
#[inline(always)]
fn write_pixels(
    vp: &Viewport,
    t: &TriSetup,
    row_depth: f32,
    xa: u32,
    depth: &mut [f32],
    items: &mut [ItemId],
    mode: RasterMode,
) -> u64 {
    let mut written = 0;
    for (i, (d, it)) in depth.iter_mut().zip(items.iter_mut()).enumerate() {
        let z = depth_at(t, row_depth, xa + i as u32);
        if z >= vp.far_depth {
            written += write_fragment(d, it, z, t.item, mode) as u64;
        }
    }
    written
}

/// [`write_span`] in the instruction set of the scan's instantiation: with `AVX2`, eight
/// pixels at a time (the same fragments, tested).
#[inline(always)]
pub(super) fn write_span_in<const AVX2: bool>(
    vp: &Viewport,
    t: &TriSetup,
    row_depth: f32,
    xa: u32,
    depth: &mut [f32],
    items: &mut [ItemId],
    mode: RasterMode,
) -> u64 {
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: the AVX2 instantiation only runs where the dispatcher found AVX2.
        let avx2 = unsafe { occult_core::simd::Avx2::new_unchecked() };
        return write_span_avx2(avx2, vp, t, row_depth, xa, depth, items, mode);
    }
    write_span(vp, t, row_depth, xa, depth, items, mode)
}

/// [`write_span`] eight pixels at a time: each lane's depth is [`depth_at`]'s (the same
/// operations in the same order, nothing contracted); the depths of a whole group of eight are
/// read and written back whole (a lane that loses keeps its own value), those of the span's
/// last pixels under a lane mask (the lanes past the span are neither read nor written); the
/// items are only written, under a lane mask, where the fragment wins on depth alone. A group
/// where some fragment ties the stored depth (coplanar surfaces) is written pixel by pixel as
/// [`write_span`] does, the item read to break the tie.
#[cfg(target_arch = "x86_64")]
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn write_span_avx2(
    avx2: occult_core::simd::Avx2,
    vp: &Viewport,
    t: &TriSetup,
    row_depth: f32,
    xa: u32,
    depth: &mut [f32],
    items: &mut [ItemId],
    mode: RasterMode,
) -> u64 {
    use occult_core::simd::{F32x8, I32x8, M32x8};
    let n = depth.len();
    let items = &mut items[..n];
    let splat = |v: f32| F32x8::splat(avx2, v);
    let lanes = SpanLanes {
        avx2,
        vp,
        t,
        row_depth,
        xa,
        mode,
        rd: splat(row_depth),
        dzdx: splat(t.dzdx),
        zmin: splat(t.zmin),
        zmax: splat(t.zmax),
        far: splat(vp.far_depth),
        // Lane k of group i is pixel xa + i + k, at offset (xa - px0) + i + k from the box's
        // corner: below 2^24, as a frame's width is, so the conversion is exact.
        offsets: I32x8::lane_index(avx2).wrapping_add(I32x8::splat(avx2, (xa - t.px0 as u32) as i32)),
    };
    let mut written = 0u64;
    let mut i = 0;
    while i + 8 <= n {
        written += lanes.group(i, i + 8, None, depth, items);
        i += 8;
    }
    if i < n {
        let valid = M32x8::from_bits(avx2, (1 << (n - i)) - 1);
        written += lanes.group(i, n, Some(valid), depth, items);
    }
    written
}

/// One span's constants in lanes ([`write_span_avx2`]).
#[cfg(target_arch = "x86_64")]
struct SpanLanes<'a> {
    avx2: occult_core::simd::Avx2,
    vp: &'a Viewport,
    t: &'a TriSetup,
    row_depth: f32,
    xa: u32,
    mode: RasterMode,
    rd: occult_core::simd::F32x8,
    dzdx: occult_core::simd::F32x8,
    zmin: occult_core::simd::F32x8,
    zmax: occult_core::simd::F32x8,
    far: occult_core::simd::F32x8,
    offsets: occult_core::simd::I32x8,
}

#[cfg(target_arch = "x86_64")]
impl SpanLanes<'_> {
    /// Writes the group of pixels `i..end` of the span: eight, or fewer at its end, whose
    /// lanes are then `valid`; returns the fragments written.
    #[inline(always)]
    fn group(
        &self,
        i: usize,
        end: usize,
        valid: Option<occult_core::simd::M32x8>,
        depth: &mut [f32],
        items: &mut [ItemId],
    ) -> u64 {
        use occult_core::simd::{F32x8, I32x8};
        let x = self.offsets.wrapping_add(I32x8::splat(self.avx2, i as i32)).to_f32();
        let z = self.zmax.min(self.zmin.max(self.rd + self.dzdx * x));
        let (stored, front) = match valid {
            None => {
                let whole: &[f32; 8] = depth[i..end].try_into().expect("eight pixels");
                (F32x8::load(self.avx2, whole), z.ge(self.far))
            }
            // SAFETY: the set lanes are pixels i..end of the span, inside `depth`.
            Some(m) => (
                unsafe { F32x8::load_masked(self.avx2, depth.as_ptr().add(i), m) },
                z.ge(self.far).and(m),
            ),
        };
        let (t, mode) = (self.t, self.mode);
        if mode == RasterMode::Full && front.and(z.eq(stored)).bits() != 0 {
            let (depth, items) = (&mut depth[i..end], &mut items[i..end]);
            return write_pixels(self.vp, t, self.row_depth, self.xa + i as u32, depth, items, mode);
        }
        let keep = front.and(z.gt(stored));
        let bits = keep.bits();
        if bits == 0 {
            return 0;
        }
        match valid {
            None => {
                let whole: &mut [f32; 8] = (&mut depth[i..end]).try_into().expect("eight pixels");
                F32x8::select(keep, z, stored).store(whole);
            }
            // SAFETY: the set lanes of `keep` are lanes of `valid`, inside the span.
            Some(_) => unsafe { z.store_masked(depth.as_mut_ptr().add(i), keep) },
        }
        if mode == RasterMode::Full {
            // SAFETY: the set lanes of `keep` are pixels of i..end, inside `items`.
            unsafe { keep.store_u64(items.as_mut_ptr().add(i), t.item) };
        }
        u64::from(bits.count_ones())
    }
}

/// Depth of a triangle at the centre of pixel `(px0, y)`.
#[inline(always)]
pub(super) fn row_depth(t: &TriSetup, y: u32) -> f32 {
    t.zc + t.dzdy * (y - t.py0 as u32) as f32
}

/// Depth of a triangle at the centre of pixel `(x, y)`: the one formula every path uses.
#[inline(always)]
pub(super) fn depth_at(t: &TriSetup, row_depth: f32, x: u32) -> f32 {
    let z = row_depth + t.dzdx * (x - t.px0 as u32) as f32;
    let z = if z < t.zmin { t.zmin } else { z };
    if z > t.zmax {
        t.zmax
    } else {
        z
    }
}

/// The edge functions of `t` at the centre of pixel `(x0, y0)`, with their steps per pixel
/// right and down. Edge i runs from corner i to corner i+1; E(p) = A·px + B·py + C >= 0
/// inside, exactly, with the top-left rule folded in.
#[inline(always)]
pub(super) fn edge_functions(t: &TriSetup, x0: u32, y0: u32) -> ([i64; 3], [i64; 3], [i64; 3]) {
    let (cx, cy) = (x0 as i64 * SUB + HALF, y0 as i64 * SUB + HALF);
    let mut row = [0i64; 3];
    let mut step_x = [0i64; 3];
    let mut step_y = [0i64; 3];
    for i in 0..3 {
        let j = (i + 1) % 3;
        let (xi, yi) = (t.x[i] as i64, t.y[i] as i64);
        let ea = yi - t.y[j] as i64;
        let eb = t.x[j] as i64 - xi;
        // Top-left rule: a centre on the edge counts only for left (A > 0) or top
        // (A = 0, B > 0) edges; other edges need E > 0, i.e. E - 1 >= 0 in integers.
        let bias = -(((ea < 0) | ((ea == 0) & (eb <= 0))) as i64);
        row[i] = ea * (cx - xi) + eb * (cy - yi) + bias;
        step_x[i] = ea * SUB;
        step_y[i] = eb * SUB;
    }
    (row, step_x, step_y)
}

/// The pixel box of `t` within the inclusive pixel rectangle `rect` (inclusive), `None` when
/// they do not meet.
#[inline(always)]
pub(super) fn box_in(t: &TriSetup, rect: [u32; 4]) -> Option<[u32; 4]> {
    let x0 = (t.px0 as u32).max(rect[0]);
    let y0 = (t.py0 as u32).max(rect[1]);
    let x1 = (t.px1 as u32).min(rect[2]);
    let y1 = (t.py1 as u32).min(rect[3]);
    if x0 > x1 || y0 > y1 {
        None
    } else {
        Some([x0, y0, x1, y1])
    }
}

/// The pixels `lo..=hi` of a row, narrowed to those where every edge function (`row` at pixel
/// 0, growing by `step_x` per pixel) is `>= 0`, each edge solved for its bound by a division
/// (empty: `lo > hi`).
#[inline(always)]
pub(super) fn solve_span(row: [i64; 3], step_x: [i64; 3], mut lo: i64, mut hi: i64) -> (i64, i64) {
    for k in 0..3 {
        let (e, s) = (row[k], step_x[k]);
        if s > 0 {
            lo = lo.max(if e >= 0 { 0 } else { (-e + s - 1) / s });
        } else if s < 0 {
            hi = hi.min(if e < 0 { -1 } else { e / -s });
        } else if e < 0 {
            hi = -1;
        }
    }
    (lo, hi)
}

/// Reciprocals of a triangle's edge steps per pixel right, for [`solve_span_with`] (0 where a
/// step is 0: that edge is not solved for).
#[inline(always)]
pub(super) fn span_reciprocals(step_x: [i64; 3]) -> [f64; 3] {
    step_x.map(|s| if s == 0 { 0.0 } else { 1.0 / s as f64 })
}

/// [`solve_span`] without its divisions (the scan's cost on long rows of large triangles):
/// each bound is estimated with a reciprocal from [`span_reciprocals`], then moved to the
/// exact one by integer evaluations of the edge function, so the span is the same (tested).
#[inline(always)]
pub(super) fn solve_span_with(row: [i64; 3], step_x: [i64; 3], inv: [f64; 3], mut lo: i64, mut hi: i64) -> (i64, i64) {
    for k in 0..3 {
        let (e, s) = (row[k], step_x[k]);
        if s > 0 {
            if e < 0 {
                // The least q with e + s·q >= 0.
                let mut q = (-(e as f64) * inv[k]).ceil() as i64;
                while e + s * q < 0 {
                    q += 1;
                }
                while q > 0 && e + s * (q - 1) >= 0 {
                    q -= 1;
                }
                lo = lo.max(q);
            }
        } else if s < 0 {
            if e < 0 {
                hi = -1;
            } else {
                // The greatest q with e + s·q >= 0.
                let mut q = (-(e as f64) * inv[k]).floor() as i64;
                while e + s * q < 0 {
                    q -= 1;
                }
                while e + s * (q + 1) >= 0 {
                    q += 1;
                }
                hi = hi.min(q);
            }
        } else if e < 0 {
            hi = -1;
        }
    }
    (lo, hi)
}

/// Scans triangle `t` inside the inclusive pixel rectangle `rect`; returns fragments written.
///
/// # Safety
/// No other thread may access the pixels of `rect` in `target` during the call.
#[inline(always)]
pub(super) unsafe fn scan_triangle<const AVX2: bool>(
    vp: &Viewport,
    t: &TriSetup,
    rect: [u32; 4],
    target: &FrameTarget<'_>,
    mode: RasterMode,
) -> u64 {
    let Some([x0, y0, x1, y1]) = box_in(t, rect) else {
        return 0;
    };
    let (mut row, step_x, step_y) = edge_functions(t, x0, y0);
    if (t.extent as u32) < MASKED && x1 - x0 < SMALL && y1 - y0 < SMALL {
        let edges = SmallCover::Edges {
            row: row.map(|e| e as i32),
            step_x: step_x.map(|e| e as i32),
            step_y: step_y.map(|e| e as i32),
        };
        // SAFETY: forwarded from the caller.
        return unsafe { scan_small::<AVX2>(vp, t, [x0, y0, x1, y1], edges, target, mode) };
    }
    let mut written = 0;
    let width = x1 - x0 + 1;
    // Boxes up to MASKED pixels keep edge functions within i32 (see `scan_small`): find each
    // row's span from 8-pixel inside masks. Larger ones solve for the span with divisions,
    // which only pay off on long rows.
    let masked = (t.extent as u32) < MASKED;
    let sx = [step_x[0] as i32, step_x[1] as i32, step_x[2] as i32];
    let inv = if masked { [0.0; 3] } else { span_reciprocals(step_x) };
    for y in y0..=y1 {
        let (mut lo, mut hi) = (0i64, width as i64 - 1);
        if masked {
            // The covered pixels of a row of a triangle are contiguous.
            let (mut first, mut last) = (i64::MAX, -1i64);
            let mut base = 0u32;
            while base < width {
                let r = [
                    row[0] as i32 + sx[0] * base as i32,
                    row[1] as i32 + sx[1] * base as i32,
                    row[2] as i32 + sx[2] * base as i32,
                ];
                let bits = row_mask_in::<AVX2>(r, sx);
                let bits = bits
                    & if width - base >= SMALL {
                        0xff
                    } else {
                        (1u64 << (width - base)) - 1
                    };
                if bits != 0 {
                    first = first.min(base as i64 + bits.trailing_zeros() as i64);
                    last = base as i64 + 63 - bits.leading_zeros() as i64;
                } else if last >= 0 {
                    break;
                }
                base += SMALL;
            }
            lo = first;
            hi = last;
        } else {
            (lo, hi) = solve_span_with(row, step_x, inv, lo, hi);
        }
        if lo <= hi {
            let row_depth = row_depth(t, y);
            let (xa, xb) = (x0 + lo as u32, x0 + hi as u32);
            let base = y as usize * target.width;
            if y + 2 <= y1 {
                // The span two rows down starts near this one's: fetch it ahead (each row is
                // a new stream to the hardware prefetcher, its first lines a wait each).
                prefetch(target, base + 2 * target.width + xa as usize);
                prefetch(target, base + 2 * target.width + xb as usize);
            }
            // SAFETY: the span lies in `rect` (inside the frame), owned by this task.
            let (depth, items) = unsafe {
                (
                    std::slice::from_raw_parts_mut(target.depth.add(base + xa as usize), (xb - xa + 1) as usize),
                    std::slice::from_raw_parts_mut(target.items.add(base + xa as usize), (xb - xa + 1) as usize),
                )
            };
            written += write_span_in::<AVX2>(vp, t, row_depth, xa, depth, items, mode);
        }
        row[0] += step_y[0];
        row[1] += step_y[1];
        row[2] += step_y[2];
    }
    written
}
