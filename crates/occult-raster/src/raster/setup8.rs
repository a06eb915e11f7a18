//! Triangle setup eight at a time (AVX2): the same operations as [`super::setup_snapped`],
//! one triangle per lane.
//!
//! Whole-mesh, index-list and range draws alike collect their projected corners into a
//! [`Batch`] (list and range corners projected in lanes too, by [`project8_avx2`]);
//! [`setup8_avx2`] then rejects, orients and bounds the eight triangles and fixes their depth
//! planes in lanes, and hands the survivors to the sink in stream order, those that need
//! clipping through the scalar path in their place (so that even the count of fragments
//! written, which depends on order, is the scalar path's). For triangles the small scan takes
//! (box at most 8 × 8 pixels, corners within [`MASKED`] pixels), it also derives the three
//! edge functions at the first pixel centre in i32 lanes: the direct sink's scan starts from
//! them; for the tile-binned sink, whose scan clips to a tile and re-derives them, they are
//! not computed. For boxes of at most [`TINY`] × [`TINY`] pixels it goes on to the mask of
//! covered centres, in lanes too: the scan then has no row loop to run, and triangles that
//! cover no centre (a quarter of those set up on the `terrain` anchor view) are only counted.
//!
//! Every value equals the scalar setup's bit for bit (tested on random and degenerate
//! batches): integer parts are exact in 32-bit lanes (snapped coordinates stay below 2^24),
//! the area is exact in f64 (products below 2^50), and the depth plane runs the scalar f64
//! expression lane by lane, in the same order, without contraction. Triangles that need
//! clipping leave the batch for the scalar path.

use super::{
    clip_and_setup, Draw, ProjVertex, SetupSink, SmallCover, TriSetup, Viewport, HALF, MASKED, NEEDS_CLIP, NOT_FINITE,
    OUT_BOTTOM, OUT_LEFT, OUT_NEAR, OUT_OF_VIEW, OUT_RIGHT, OUT_TOP, SMALL, SUB, SUBPIXEL_BITS, TINY,
};
use occult_core::{ItemId, Mat4, Vec3, Vec4};

/// Lanes of a batch.
pub(super) const LANES: usize = 8;

/// Up to eight triangles of a draw stream, in stream order, waiting for the 8-lane setup.
pub(super) struct Batch {
    /// `corners[c][k]`: corner `c` of the triangle in lane `k`, as projected.
    corners: [[ProjVertex; LANES]; 3],
    /// The draw of each lane and its item, `first_item` plus the triangle's index in the
    /// draw's mesh: a triangle that needs clipping is transformed again from its corners there.
    draw: [u32; LANES],
    item: [ItemId; LANES],
    len: usize,
    /// Where [`setup8_avx2`] spills its lanes: kept with the batch, so that it is not cleared
    /// for every eight triangles (a call reads only lanes it wrote itself).
    lanes: Lanes,
}

impl Batch {
    pub(super) fn new() -> Self {
        Self {
            corners: [[ProjVertex::default(); LANES]; 3],
            draw: [0; LANES],
            item: [0; LANES],
            len: 0,
            lanes: Lanes::default(),
        }
    }

    /// Appends a triangle. The batch must not be full (callers set a full batch up before the
    /// next push): in release builds a push into a full one would overwrite lane 0.
    #[inline(always)]
    pub(super) fn push(&mut self, v: [&ProjVertex; 3], draw: usize, item: ItemId) {
        debug_assert!(self.len < LANES, "a full batch is set up before the next push");
        // The mask only spares the bounds checks: a full batch never takes a push.
        let k = self.len % LANES;
        for (corners, v) in self.corners.iter_mut().zip(v) {
            // SAFETY: SSE2 is part of every x86_64 processor (this module is x86_64 only);
            // both pointers name a `ProjVertex`, `repr(C)` with four 4-byte fields and no
            // padding (size asserted), so the 16 bytes read are initialized and any 16 bytes
            // are a valid value; unaligned access is allowed. One vector move instead of the
            // field-wise copy the compiler emits.
            unsafe {
                use std::arch::x86_64::{__m128i, _mm_loadu_si128, _mm_storeu_si128};
                let dst: *mut __m128i = (&raw mut corners[k]).cast();
                _mm_storeu_si128(dst, _mm_loadu_si128((v as *const ProjVertex).cast()));
            }
        }
        self.draw[k] = draw as u32;
        self.item[k] = item;
        self.len = k + 1;
    }

    #[inline(always)]
    pub(super) fn is_full(&self) -> bool {
        self.len == LANES
    }
}

/// The lanes of a set-up batch, spilled for the per-triangle hand-over.
#[repr(C, align(32))]
#[derive(Default)]
struct Lanes {
    x: [[i32; LANES]; 3],
    y: [[i32; LANES]; 3],
    px0: [i32; LANES],
    py0: [i32; LANES],
    px1: [i32; LANES],
    py1: [i32; LANES],
    extent: [i32; LANES],
    zc: [f32; LANES],
    dzdx: [f32; LANES],
    dzdy: [f32; LANES],
    zmin: [f32; LANES],
    zmax: [f32; LANES],
    row: [[i32; LANES]; 3],
    step_x: [[i32; LANES]; 3],
    step_y: [[i32; LANES]; 3],
    mask: [i32; LANES],
}

/// Sets up the batch's triangles and hands them to `out` (see the module doc), then empties it.
///
/// # Safety
/// The processor must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn setup8_avx2<S: SetupSink>(vp: &Viewport, draws: &[Draw<'_>], batch: &mut Batch, out: &mut S) {
    use std::arch::x86_64::*;

    let n = batch.len;
    batch.len = 0;
    if n == 0 {
        return;
    }
    let in_batch = (1u32 << n) - 1;
    // Corner c of the eight lanes, from eight 16-byte vertices: a 4 × 4 transpose per half.
    let corner = |c: usize| {
        let v = &batch.corners[c];
        let load = |k: usize| _mm_loadu_si128((&raw const v[k]).cast());
        let pair = |a: usize, b: usize| _mm256_inserti128_si256::<1>(_mm256_castsi128_si256(load(a)), load(b));
        let (t0, t1, t2, t3) = (pair(0, 4), pair(1, 5), pair(2, 6), pair(3, 7));
        let (u0, u1) = (_mm256_unpacklo_epi32(t0, t1), _mm256_unpackhi_epi32(t0, t1));
        let (u2, u3) = (_mm256_unpacklo_epi32(t2, t3), _mm256_unpackhi_epi32(t2, t3));
        (
            _mm256_unpacklo_epi64(u0, u2),
            _mm256_unpackhi_epi64(u0, u2),
            _mm256_castsi256_ps(_mm256_unpacklo_epi64(u1, u3)),
            _mm256_unpackhi_epi64(u1, u3),
        )
    };
    let (x0, y0, z0, c0) = corner(0);
    let (x1, y1, z1, c1) = corner(1);
    let (x2, y2, z2, c2) = corner(2);
    let zero = _mm256_setzero_si256();
    let bits = |m: __m256i| _mm256_movemask_ps(_mm256_castsi256_ps(m)) as u32;
    let any = |c: __m256i, flags: u32| {
        bits(_mm256_cmpgt_epi32(
            _mm256_and_si256(c, _mm256_set1_epi32(flags as i32)),
            zero,
        ))
    };
    let all_codes = _mm256_and_si256(_mm256_and_si256(c0, c1), c2);
    let any_codes = _mm256_or_si256(_mm256_or_si256(c0, c1), c2);
    let rejected = any(all_codes, OUT_OF_VIEW) | any(any_codes, NOT_FINITE);
    let clipped = in_batch & !rejected & any(any_codes, NEEDS_CLIP);
    let mut live = in_batch & !rejected & !clipped;

    // Pixel boxes: centres (i + 1/2) inside [min, max] of the snapped corners.
    let min3 = |a, b, c| _mm256_min_epi32(_mm256_min_epi32(a, b), c);
    let max3 = |a, b, c| _mm256_max_epi32(_mm256_max_epi32(a, b), c);
    let (minx, maxx) = (min3(x0, x1, x2), max3(x0, x1, x2));
    let (miny, maxy) = (min3(y0, y1, y2), max3(y0, y1, y2));
    let shift = |v: __m256i, add: i64| {
        _mm256_srai_epi32::<{ SUBPIXEL_BITS as i32 }>(_mm256_add_epi32(v, _mm256_set1_epi32(add as i32)))
    };
    let px0 = _mm256_max_epi32(shift(minx, SUB - 1 - HALF), zero);
    let py0 = _mm256_max_epi32(shift(miny, SUB - 1 - HALF), zero);
    let px1 = _mm256_min_epi32(shift(maxx, -HALF), _mm256_set1_epi32(vp.width as i32 - 1));
    let py1 = _mm256_min_epi32(shift(maxy, -HALF), _mm256_set1_epi32(vp.height as i32 - 1));
    live &= !bits(_mm256_or_si256(
        _mm256_cmpgt_epi32(px0, px1),
        _mm256_cmpgt_epi32(py0, py1),
    ));
    if live == 0 && clipped == 0 {
        return;
    }
    let l = &mut batch.lanes;
    let store = |dst: &mut [i32; LANES], v: __m256i| _mm256_storeu_si256(dst.as_mut_ptr().cast(), v);
    store(&mut l.px0, px0);
    store(&mut l.py0, py0);
    store(&mut l.py1, py1);
    // Every lane, without a branch on which are live (a loop over the live ones mispredicts
    // its exit): a dead lane's hint names pixel (0, 0).
    let on = lane_mask(live);
    let (hint_x, hint_y) = (_mm256_and_si256(px0, on), _mm256_and_si256(py0, on));
    let two_rows = live & bits(_mm256_cmpgt_epi32(py1, py0));
    let (mut xs, mut ys) = ([0i32; LANES], [0i32; LANES]);
    store(&mut xs, hint_x);
    store(&mut ys, hint_y);
    for k in 0..LANES {
        out.will_touch(xs[k] as u32, ys[k] as u32, two_rows & (1 << k) != 0);
    }

    // Area, exact in f64 halves: |coordinates| < 2^24, so products < 2^50.
    let (dx1, dy1) = (_mm256_sub_epi32(x1, x0), _mm256_sub_epi32(y1, y0));
    let (dx2, dy2) = (_mm256_sub_epi32(x2, x0), _mm256_sub_epi32(y2, y0));
    let (area_lo, area_hi) = (
        area(lo_pd(dx1), lo_pd(dy1), lo_pd(dx2), lo_pd(dy2)),
        area(hi_pd(dx1), hi_pd(dy1), hi_pd(dx2), hi_pd(dy2)),
    );
    let zd = _mm256_setzero_pd();
    let signs = |lo: __m256d, hi: __m256d| (_mm256_movemask_pd(lo) | (_mm256_movemask_pd(hi) << 4)) as u32;
    let negative = signs(
        _mm256_cmp_pd::<_CMP_LT_OQ>(area_lo, zd),
        _mm256_cmp_pd::<_CMP_LT_OQ>(area_hi, zd),
    );
    let positive = signs(
        _mm256_cmp_pd::<_CMP_GT_OQ>(area_lo, zd),
        _mm256_cmp_pd::<_CMP_GT_OQ>(area_hi, zd),
    );
    // Zero areas fail both.
    live &= negative | if vp.cull_backfaces { 0 } else { positive };

    // Orient counter-clockwise on screen (negative area) triangles like the others: swap 1, 2.
    let swap = lane_mask(negative);
    let swap_ps = _mm256_castsi256_ps(swap);
    let (x1, x2) = (_mm256_blendv_epi8(x1, x2, swap), _mm256_blendv_epi8(x2, x1, swap));
    let (y1, y2) = (_mm256_blendv_epi8(y1, y2, swap), _mm256_blendv_epi8(y2, y1, swap));
    let (z1, z2) = (_mm256_blendv_ps(z1, z2, swap_ps), _mm256_blendv_ps(z2, z1, swap_ps));
    let abs = _mm256_set1_pd(-0.0);
    let (area_lo, area_hi) = (_mm256_andnot_pd(abs, area_lo), _mm256_andnot_pd(abs, area_hi));

    // Depth range, as `min_f32` / `max_f32` (the instructions' own operand rule).
    let zmin = _mm256_min_ps(_mm256_min_ps(z0, z1), z2);
    let zmax = _mm256_max_ps(_mm256_max_ps(z0, z1), z2);
    live &= !(_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(zmax, _mm256_set1_ps(vp.far_depth))) as u32);

    // Lanes whose box the small scan takes, with their edge functions in `l`; those of them
    // whose box is at most `TINY × TINY`, with their mask of covered centres in `l`; and
    // those of these that cover no centre.
    let mut small = 0;
    let mut tiny = 0;
    let mut uncovered = 0;
    if live != 0 {
        // Depth plane in pixel units relative to corner 0, in f64, anchored at the centre of
        // pixel (px0, py0): the scalar expression, operation for operation.
        let (dz1, dz2) = (_mm256_sub_ps(z1, z0), _mm256_sub_ps(z2, z0));
        let (dx1, dy1) = (_mm256_sub_epi32(x1, x0), _mm256_sub_epi32(y1, y0));
        let (dx2, dy2) = (_mm256_sub_epi32(x2, x0), _mm256_sub_epi32(y2, y0));
        let (zc_lo, dzdx_lo, dzdy_lo) = plane(
            area_lo,
            [lo_pd(dx1), lo_pd(dy1), lo_pd(dx2), lo_pd(dy2)],
            [lo_ps(dz1), lo_ps(dz2), lo_ps(z0)],
            [lo_pd(px0), lo_pd(py0), lo_pd(x0), lo_pd(y0)],
        );
        let (zc_hi, dzdx_hi, dzdy_hi) = plane(
            area_hi,
            [hi_pd(dx1), hi_pd(dy1), hi_pd(dx2), hi_pd(dy2)],
            [hi_ps(dz1), hi_ps(dz2), hi_ps(z0)],
            [hi_pd(px0), hi_pd(py0), hi_pd(x0), hi_pd(y0)],
        );
        let store_ps = |dst: &mut [f32; LANES], v: __m256| _mm256_storeu_ps(dst.as_mut_ptr(), v);
        store_ps(&mut l.zc, _mm256_set_m128(zc_hi, zc_lo));
        store_ps(&mut l.dzdx, _mm256_set_m128(dzdx_hi, dzdx_lo));
        store_ps(&mut l.dzdy, _mm256_set_m128(dzdy_hi, dzdy_lo));
        store_ps(&mut l.zmin, zmin);
        store_ps(&mut l.zmax, zmax);
        let extent = _mm256_add_epi32(
            _mm256_srai_epi32::<{ SUBPIXEL_BITS as i32 }>(_mm256_max_epi32(
                _mm256_sub_epi32(maxx, minx),
                _mm256_sub_epi32(maxy, miny),
            )),
            _mm256_set1_epi32(1),
        );
        let extent = _mm256_min_epi32(extent, _mm256_set1_epi32(u16::MAX as i32));
        store(&mut l.extent, extent);
        store(&mut l.px1, px1);
        let (xs, ys) = ([x0, x1, x2], [y0, y1, y2]);
        for c in 0..3 {
            store(&mut l.x[c], xs[c]);
            store(&mut l.y[c], ys[c]);
        }
        // Edge functions at the centre of pixel (px0, py0), for the small scan: exact in i32
        // for boxes it takes (see `scan_small`); other lanes are not read.
        // The box's width and height less one pixel.
        let (w, h) = (_mm256_sub_epi32(px1, px0), _mm256_sub_epi32(py1, py0));
        let small_box = _mm256_set1_epi32(SMALL as i32);
        small = if S::TAKES_EDGES { live } else { 0 }
            & bits(_mm256_cmpgt_epi32(_mm256_set1_epi32(MASKED as i32), extent))
            & bits(_mm256_cmpgt_epi32(small_box, w))
            & bits(_mm256_cmpgt_epi32(small_box, h));
        // Edge functions at the first centre and their steps, kept for the masks below.
        let (mut rows, mut sxs, mut sys) = ([zero; 3], [zero; 3], [zero; 3]);
        if small != 0 {
            let centre = |p: __m256i| {
                _mm256_add_epi32(
                    _mm256_slli_epi32::<{ SUBPIXEL_BITS as i32 }>(p),
                    _mm256_set1_epi32(HALF as i32),
                )
            };
            let (cx, cy) = (centre(px0), centre(py0));
            for i in 0..3 {
                let j = (i + 1) % 3;
                let ea = _mm256_sub_epi32(ys[i], ys[j]);
                let eb = _mm256_sub_epi32(xs[j], xs[i]);
                // Top-left rule as in `scan_triangle`: -1 unless A > 0, or A = 0 and B > 0.
                let bias = _mm256_or_si256(
                    _mm256_cmpgt_epi32(zero, ea),
                    _mm256_andnot_si256(_mm256_cmpgt_epi32(eb, zero), _mm256_cmpeq_epi32(ea, zero)),
                );
                rows[i] = _mm256_add_epi32(
                    _mm256_add_epi32(
                        _mm256_mullo_epi32(ea, _mm256_sub_epi32(cx, xs[i])),
                        _mm256_mullo_epi32(eb, _mm256_sub_epi32(cy, ys[i])),
                    ),
                    bias,
                );
                sxs[i] = _mm256_slli_epi32::<{ SUBPIXEL_BITS as i32 }>(ea);
                sys[i] = _mm256_slli_epi32::<{ SUBPIXEL_BITS as i32 }>(eb);
                store(&mut l.row[i], rows[i]);
                store(&mut l.step_x[i], sxs[i]);
                store(&mut l.step_y[i], sys[i]);
            }
            let tiny_box = _mm256_set1_epi32(TINY as i32);
            tiny = small & bits(_mm256_cmpgt_epi32(tiny_box, w)) & bits(_mm256_cmpgt_epi32(tiny_box, h));
        }
        if tiny != 0 {
            // Inside bits of the first 4 × 4 centres of each box, bit `8·j + i` for centre
            // (i, j) from the box's corner as in `scan_small`'s mask (a set sign bit in an
            // edge function means outside); exact in i32 as the small scan's own masks are:
            // these centres lie in its block.
            let mut inside = zero;
            let mut row = rows;
            for j in 0..TINY {
                let mut e = row;
                for i in 0..TINY {
                    let out = _mm256_or_si256(_mm256_or_si256(e[0], e[1]), e[2]);
                    let bit = _mm256_set1_epi32(1 << (j * SMALL + i));
                    inside = _mm256_or_si256(inside, _mm256_andnot_si256(_mm256_srai_epi32::<31>(out), bit));
                    for k in 0..3 {
                        e[k] = _mm256_add_epi32(e[k], sxs[k]);
                    }
                }
                for k in 0..3 {
                    row[k] = _mm256_add_epi32(row[k], sys[k]);
                }
            }
            // Only the centres inside the box: (1 << (w + 1)) - 1 per row, for its h + 1 rows.
            let one = _mm256_set1_epi32(1);
            let columns = _mm256_sub_epi32(_mm256_sllv_epi32(one, _mm256_add_epi32(w, one)), one);
            let mut valid = columns;
            for j in 1..TINY {
                let has_row = _mm256_cmpgt_epi32(h, _mm256_set1_epi32(j as i32 - 1));
                let shifted = _mm256_sllv_epi32(columns, _mm256_set1_epi32((j * SMALL) as i32));
                valid = _mm256_or_si256(valid, _mm256_and_si256(has_row, shifted));
            }
            let mask = _mm256_and_si256(inside, valid);
            store(&mut l.mask, mask);
            uncovered = tiny & bits(_mm256_cmpeq_epi32(mask, zero));
        }
    }
    // In stream order: the set-up lanes, and the clipped ones through the scalar path.
    out.count_uncovered(uncovered.count_ones());
    if S::COUNTS_LANES {
        // The lanes about to be scanned (clipped ones count themselves) and their box.
        let scanned = live & !uncovered;
        let on = lane_mask(scanned);
        // Boxes lie in the frame (no lane is negative): unsigned, u32::MAX stands for no lane
        // in a minimum and 0 in a maximum, as in `EMPTY_RECT`.
        let least = |v: __m256i| {
            let v = _mm256_or_si256(v, _mm256_xor_si256(on, _mm256_set1_epi32(-1)));
            let v = _mm256_min_epu32(v, _mm256_permute2x128_si256::<0x01>(v, v));
            let v = _mm256_min_epu32(v, _mm256_shuffle_epi32::<0b01_00_11_10>(v));
            _mm256_extract_epi32::<0>(_mm256_min_epu32(v, _mm256_shuffle_epi32::<0b10_11_00_01>(v)))
        };
        let most = |v: __m256i| {
            let v = _mm256_and_si256(v, on);
            let v = _mm256_max_epi32(v, _mm256_permute2x128_si256::<0x01>(v, v));
            let v = _mm256_max_epi32(v, _mm256_shuffle_epi32::<0b01_00_11_10>(v));
            _mm256_extract_epi32::<0>(_mm256_max_epi32(v, _mm256_shuffle_epi32::<0b10_11_00_01>(v)))
        };
        out.count_lanes(
            scanned.count_ones(),
            [least(px0) as u32, least(py0) as u32, most(px1) as u32, most(py1) as u32],
        );
    }
    let mut m = (live | clipped) & !uncovered;
    while m != 0 {
        let k = m.trailing_zeros() as usize;
        m &= m - 1;
        if clipped & (1 << k) != 0 {
            let d = &draws[batch.draw[k] as usize];
            let pos = d.mesh.positions();
            let triangle = (batch.item[k] - d.first_item) as usize;
            let corners = d.mesh.triangles()[triangle].map(|i| pos[i as usize]);
            clip_and_setup(vp, &d.clip_from_object, corners, batch.item[k], out);
            continue;
        }
        let t = TriSetup {
            x: [l.x[0][k], l.x[1][k], l.x[2][k]],
            y: [l.y[0][k], l.y[1][k], l.y[2][k]],
            px0: l.px0[k] as u16,
            py0: l.py0[k] as u16,
            px1: l.px1[k] as u16,
            py1: l.py1[k] as u16,
            zc: l.zc[k],
            dzdx: l.dzdx[k],
            dzdy: l.dzdy[k],
            zmin: l.zmin[k],
            zmax: l.zmax[k],
            extent: l.extent[k] as u16,
            front: negative & (1 << k) != 0,
            item: batch.item[k],
        };
        if small & (1 << k) != 0 {
            let cover = if tiny & (1 << k) != 0 {
                SmallCover::Mask(l.mask[k] as u32)
            } else {
                SmallCover::Edges {
                    row: [l.row[0][k], l.row[1][k], l.row[2][k]],
                    step_x: [l.step_x[0][k], l.step_x[1][k], l.step_x[2][k]],
                    step_y: [l.step_y[0][k], l.step_y[1][k], l.step_y[2][k]],
                }
            };
            out.push_small(vp, t, cover);
        } else {
            out.push_lane(vp, t);
        }
    }
}

/// Projects eight positions as [`Viewport::project`] does each, bit for bit: the clip-space
/// product in glam's order (`((x·c0 + y·c1) + z·c2) + 1·c3`), the same comparisons for the
/// outcodes, and the snap as a conversion of `256·s` (exact in f32) rounding to nearest even,
/// which is what the scalar `snap` computes in f64.
///
/// # Safety
/// The processor must support AVX2; `positions` and `out` hold at least eight entries.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn project8_avx2(vp: &Viewport, m: &Mat4, positions: &[Vec3], out: &mut [ProjVertex]) {
    use std::arch::x86_64::*;
    assert!(positions.len() >= LANES && out.len() >= LANES);
    // Eight (x, y, z) as three vectors of x, y and z: six 4-float loads and five shuffles,
    // a third less time than three gathers. `Vec3` is three `f32` without padding, so vertex
    // k's coordinates are floats 3k..3k + 3 of the slice, and all 24 read lie in it.
    let base: *const f32 = positions.as_ptr().cast();
    let pair = |lo: usize, hi: usize| _mm256_loadu2_m128(base.add(hi), base.add(lo));
    let m03 = pair(0, 12); // x0 y0 z0 x1 | x4 y4 z4 x5
    let m14 = pair(4, 16); // y1 z1 x2 y2 | y5 z5 x6 y6
    let m25 = pair(8, 20); // z2 x3 y3 z3 | z6 x7 y7 z7
    let xy = _mm256_shuffle_ps::<0b10_01_11_10>(m14, m25); // x2 y2 x3 y3 | x6 y6 x7 y7
    let yz = _mm256_shuffle_ps::<0b01_00_10_01>(m03, m14); // y0 z0 y1 z1 | y4 z4 y5 z5
    let x = _mm256_shuffle_ps::<0b10_00_11_00>(m03, xy);
    let y = _mm256_shuffle_ps::<0b11_01_10_00>(yz, xy);
    let z = _mm256_shuffle_ps::<0b11_00_11_01>(yz, m25);
    let one = _mm256_set1_ps(1.0);
    let row = |r: usize| {
        let c = |axis: Vec4| _mm256_set1_ps(axis[r]);
        _mm256_add_ps(
            _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(c(m.x_axis), x), _mm256_mul_ps(c(m.y_axis), y)),
                _mm256_mul_ps(c(m.z_axis), z),
            ),
            _mm256_mul_ps(c(m.w_axis), one),
        )
    };
    let (cx, cy, cz, cw) = (row(0), row(1), row(2), row(3));
    let sign = _mm256_set1_ps(-0.0);
    let inf = _mm256_set1_ps(f32::INFINITY);
    let finite = |v: __m256| _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_andnot_ps(sign, v), inf);
    let flag = |mask: __m256, f: u32| _mm256_and_si256(_mm256_castps_si256(mask), _mm256_set1_epi32(f as i32));
    let neg_w = _mm256_xor_ps(cw, sign);
    let mut code = _mm256_or_si256(
        _mm256_or_si256(
            flag(_mm256_cmp_ps::<_CMP_LT_OQ>(cx, neg_w), OUT_LEFT),
            flag(_mm256_cmp_ps::<_CMP_GT_OQ>(cx, cw), OUT_RIGHT),
        ),
        _mm256_or_si256(
            flag(_mm256_cmp_ps::<_CMP_LT_OQ>(cy, neg_w), OUT_BOTTOM),
            flag(_mm256_cmp_ps::<_CMP_GT_OQ>(cy, cw), OUT_TOP),
        ),
    );
    let near = _mm256_or_ps(
        _mm256_cmp_ps::<_CMP_GT_OQ>(cz, cw),
        _mm256_cmp_ps::<_CMP_LE_OQ>(cw, _mm256_setzero_ps()),
    );
    code = _mm256_or_si256(code, flag(near, OUT_NEAR | NEEDS_CLIP));
    let guard = _mm256_or_ps(
        _mm256_cmp_ps::<_CMP_GT_OQ>(
            _mm256_andnot_ps(sign, cx),
            _mm256_mul_ps(_mm256_set1_ps(vp.guard_x), cw),
        ),
        _mm256_cmp_ps::<_CMP_GT_OQ>(
            _mm256_andnot_ps(sign, cy),
            _mm256_mul_ps(_mm256_set1_ps(vp.guard_y), cw),
        ),
    );
    code = _mm256_or_si256(code, flag(guard, NEEDS_CLIP));
    let inv_w = _mm256_div_ps(one, cw);
    let half = _mm256_set1_ps(0.5);
    let sx = _mm256_mul_ps(
        _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(cx, inv_w), half), half),
        _mm256_set1_ps(vp.fwidth),
    );
    let sy = _mm256_mul_ps(
        _mm256_sub_ps(half, _mm256_mul_ps(_mm256_mul_ps(cy, inv_w), half)),
        _mm256_set1_ps(vp.fheight),
    );
    let zs = _mm256_mul_ps(cz, inv_w);
    let sub = _mm256_set1_ps(SUB as f32);
    let (px, py) = (
        _mm256_cvtps_epi32(_mm256_mul_ps(sx, sub)),
        _mm256_cvtps_epi32(_mm256_mul_ps(sy, sub)),
    );
    // Lanes that keep a position: finite clip coordinates, no clipping, a finite projection.
    let clip_finite = _mm256_and_ps(
        _mm256_and_ps(finite(cx), finite(cy)),
        _mm256_and_ps(finite(cz), finite(cw)),
    );
    let needs_clip = _mm256_cmpgt_epi32(flag(_mm256_castsi256_ps(code), NEEDS_CLIP), _mm256_setzero_si256());
    let projected = _mm256_and_ps(_mm256_and_ps(finite(sx), finite(sy)), finite(zs));
    let keep = _mm256_andnot_si256(needs_clip, _mm256_castps_si256(_mm256_and_ps(clip_finite, projected)));
    // Not finite: the code alone; needing clipping: the codes, no position.
    let not_finite = _mm256_castps_si256(_mm256_or_ps(
        _mm256_xor_ps(clip_finite, _mm256_castsi256_ps(_mm256_set1_epi32(-1))),
        _mm256_andnot_ps(
            _mm256_castsi256_ps(needs_clip),
            _mm256_xor_ps(projected, _mm256_castsi256_ps(_mm256_set1_epi32(-1))),
        ),
    ));
    let code = _mm256_blendv_epi8(code, _mm256_set1_epi32(NOT_FINITE as i32), not_finite);
    let px = _mm256_and_si256(px, keep);
    let py = _mm256_and_si256(py, keep);
    let zs = _mm256_castsi256_ps(_mm256_and_si256(_mm256_castps_si256(zs), keep));
    // Eight (x, y, z, code) records: a 4 × 4 transpose per half.
    let zi = _mm256_castps_si256(zs);
    let (t0, t1) = (_mm256_unpacklo_epi32(px, py), _mm256_unpackhi_epi32(px, py));
    let (t2, t3) = (_mm256_unpacklo_epi32(zi, code), _mm256_unpackhi_epi32(zi, code));
    let (v0, v1) = (_mm256_unpacklo_epi64(t0, t2), _mm256_unpackhi_epi64(t0, t2));
    let (v2, v3) = (_mm256_unpacklo_epi64(t1, t3), _mm256_unpackhi_epi64(t1, t3));
    let dst: *mut __m256i = out.as_mut_ptr().cast();
    _mm256_storeu_si256(dst, _mm256_permute2x128_si256::<0x20>(v0, v1));
    _mm256_storeu_si256(dst.add(1), _mm256_permute2x128_si256::<0x20>(v2, v3));
    _mm256_storeu_si256(dst.add(2), _mm256_permute2x128_si256::<0x31>(v0, v1));
    _mm256_storeu_si256(dst.add(3), _mm256_permute2x128_si256::<0x31>(v2, v3));
}

/// All bits set in the lanes whose bit is set in `mask`, none in the others.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn lane_mask(mask: u32) -> std::arch::x86_64::__m256i {
    use std::arch::x86_64::*;
    let lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(mask as i32), lane_bit), lane_bit)
}

/// Lanes 0..4 of eight i32 as f64.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn lo_pd(v: std::arch::x86_64::__m256i) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    _mm256_cvtepi32_pd(_mm256_castsi256_si128(v))
}

/// Lanes 4..8 of eight i32 as f64.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn hi_pd(v: std::arch::x86_64::__m256i) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    _mm256_cvtepi32_pd(_mm256_extracti128_si256::<1>(v))
}

/// Lanes 0..4 of eight f32 as f64.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn lo_ps(v: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    _mm256_cvtps_pd(_mm256_castps256_ps128(v))
}

/// Lanes 4..8 of eight f32 as f64.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn hi_ps(v: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v))
}

/// `(x1 - x0)(y2 - y0) - (x2 - x0)(y1 - y0)` from the differences `[dx1, dy1, dx2, dy2]`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn area(
    dx1: std::arch::x86_64::__m256d,
    dy1: std::arch::x86_64::__m256d,
    dx2: std::arch::x86_64::__m256d,
    dy2: std::arch::x86_64::__m256d,
) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    _mm256_sub_pd(_mm256_mul_pd(dx1, dy2), _mm256_mul_pd(dx2, dy1))
}

/// The scalar setup's depth plane in four f64 lanes: `d = [dx1, dy1, dx2, dy2]` (oriented
/// corners minus corner 0, in 1/256 pixel), `z = [z1 - z0, z2 - z0, z0]` (the differences taken
/// in f32, as there), `o = [px0, py0, x0, y0]`; returns `(zc, dzdx, dzdy)` rounded to f32.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn plane(
    area: std::arch::x86_64::__m256d,
    d: [std::arch::x86_64::__m256d; 4],
    z: [std::arch::x86_64::__m256d; 3],
    o: [std::arch::x86_64::__m256d; 4],
) -> (
    std::arch::x86_64::__m128,
    std::arch::x86_64::__m128,
    std::arch::x86_64::__m128,
) {
    use std::arch::x86_64::*;
    let sub = _mm256_set1_pd(SUB as f64);
    let half = _mm256_set1_pd(0.5);
    let inv = _mm256_div_pd(
        _mm256_set1_pd(1.0),
        _mm256_div_pd(area, _mm256_set1_pd((SUB * SUB) as f64)),
    );
    let (fx1, fy1) = (_mm256_div_pd(d[0], sub), _mm256_div_pd(d[1], sub));
    let (fx2, fy2) = (_mm256_div_pd(d[2], sub), _mm256_div_pd(d[3], sub));
    let [dz1, dz2, z0] = z;
    let dzdx = _mm256_mul_pd(_mm256_sub_pd(_mm256_mul_pd(dz1, fy2), _mm256_mul_pd(dz2, fy1)), inv);
    let dzdy = _mm256_mul_pd(_mm256_sub_pd(_mm256_mul_pd(fx1, dz2), _mm256_mul_pd(fx2, dz1)), inv);
    let ox = _mm256_sub_pd(_mm256_add_pd(o[0], half), _mm256_div_pd(o[2], sub));
    let oy = _mm256_sub_pd(_mm256_add_pd(o[1], half), _mm256_div_pd(o[3], sub));
    let zc = _mm256_add_pd(_mm256_add_pd(z0, _mm256_mul_pd(dzdx, ox)), _mm256_mul_pd(dzdy, oy));
    (_mm256_cvtpd_ps(zc), _mm256_cvtpd_ps(dzdx), _mm256_cvtpd_ps(dzdy))
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::super::{
        edge_functions, row_mask, setup_triangle, DrawTriangles, OUT_BOTTOM, OUT_LEFT, OUT_NEAR, OUT_RIGHT, OUT_TOP,
    };
    use super::*;
    use occult_core::{Affine3A, Camera, Mesh, Vec3, View};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    /// A set-up record as comparable bits, and how the small scan was to find its centres.
    type Entry = (ItemId, [u64; 16], Option<SmallCover>);

    #[derive(Default)]
    struct Recorder {
        records: Vec<Entry>,
        uncovered: usize,
        /// Boxes of the triangles handed over as lanes (`push_lane`, `push_small`), and what
        /// `count_lanes` reported for them.
        lane_boxes: Vec<[u32; 4]>,
        lanes_counted: Vec<(u32, [u32; 4])>,
    }

    fn key(t: &TriSetup) -> [u64; 16] {
        let f = |v: f32| v.to_bits() as u64;
        let i = |v: i32| v as u32 as u64;
        [
            i(t.x[0]),
            i(t.x[1]),
            i(t.x[2]),
            i(t.y[0]),
            i(t.y[1]),
            i(t.y[2]),
            (t.px0 as u64) | (t.py0 as u64) << 16 | (t.px1 as u64) << 32 | (t.py1 as u64) << 48,
            f(t.zc),
            f(t.dzdx),
            f(t.dzdy),
            f(t.zmin),
            f(t.zmax),
            t.extent as u64,
            t.front as u64,
            t.item,
            0,
        ]
    }

    fn bounds(t: &TriSetup) -> [u32; 4] {
        [t.px0, t.py0, t.px1, t.py1].map(u32::from)
    }

    impl SetupSink for Recorder {
        const TAKES_EDGES: bool = true;
        const COUNTS_LANES: bool = true;

        fn push(&mut self, _vp: &Viewport, t: TriSetup) {
            self.records.push((t.item, key(&t), None));
        }
        fn push_lane(&mut self, vp: &Viewport, t: TriSetup) {
            self.lane_boxes.push(bounds(&t));
            self.push(vp, t);
        }
        fn push_small(&mut self, _vp: &Viewport, t: TriSetup, cover: SmallCover) {
            self.lane_boxes.push(bounds(&t));
            self.records.push((t.item, key(&t), Some(cover)));
        }
        fn count_lanes(&mut self, n: u32, bounds: [u32; 4]) {
            self.lanes_counted.push((n, bounds));
        }
        fn count_uncovered(&mut self, n: u32) {
            self.uncovered += n as usize;
        }
        fn uncount(&mut self, _n: u32) {
            // Pieces of clipped triangles are compared as records, one each.
        }
    }

    fn viewport(rng: &mut Pcg64Mcg) -> Viewport {
        let (width, height) = if rng.random_bool(0.1) {
            (rng.random_range(1..=16384), rng.random_range(1..=16384))
        } else {
            (rng.random_range(1..2000), rng.random_range(1..1200))
        };
        Viewport {
            width,
            height,
            fwidth: width as f32,
            fheight: height as f32,
            guard_x: 2.0 * super::super::GUARD_PIXELS / width as f32 - 1.0,
            guard_y: 2.0 * super::super::GUARD_PIXELS / height as f32 - 1.0,
            far_depth: [0.0, 0.25, -1.0][rng.random_range(0..3)],
            tile_size: 64,
            tile_shift: 6,
            tiles_x: width.div_ceil(64),
            tiles_y: height.div_ceil(64),
            cull_backfaces: rng.random_bool(0.3),
        }
    }

    /// Random corners as a projection could produce them: tiny to guard-band-sized
    /// triangles, shared and signed-zero depths, every kind of outcode.
    fn corners(rng: &mut Pcg64Mcg, vp: &Viewport) -> [ProjVertex; 3] {
        const LIMIT: i32 = 1 << 23;
        let spread = [300, 300, 1500, 3000, 40_000, LIMIT][rng.random_range(0..6)];
        let cx = rng.random_range(-30_000..(vp.width as i32 + 100) * 256);
        let cy = rng.random_range(-30_000..(vp.height as i32 + 100) * 256);
        let z_shared = rng.random_range(-0.5f32..1.5);
        let mut v = [ProjVertex::default(); 3];
        for p in &mut v {
            p.x = (cx + rng.random_range(-spread..=spread)).clamp(-LIMIT, LIMIT);
            p.y = (cy + rng.random_range(-spread..=spread)).clamp(-LIMIT, LIMIT);
            p.z = match rng.random_range(0..6) {
                0 => 0.0,
                1 => -0.0,
                2 => z_shared,
                3 => 1.0,
                _ => rng.random_range(-0.5f32..1.5),
            };
            p.code = match rng.random_range(0..20) {
                0 => OUT_LEFT,
                1 => OUT_RIGHT | OUT_TOP,
                2 => OUT_BOTTOM,
                3 => OUT_NEAR | NEEDS_CLIP,
                4 => NEEDS_CLIP,
                5 => NOT_FINITE,
                _ => 0,
            };
        }
        // Degenerate shapes: repeated corners and collinear ones.
        match rng.random_range(0..12) {
            0 => v[1] = v[0],
            1 => {
                v[2].x = 2 * v[1].x - v[0].x;
                v[2].y = 2 * v[1].y - v[0].y;
            }
            _ => {}
        }
        v
    }

    #[test]
    fn eight_lane_setup_matches_the_scalar_one() {
        if !occult_core::simd::Isa::detected().has_avx2() {
            eprintln!("no AVX2 on this processor: the 8-lane setup is not exercised");
            return;
        }
        let mut rng = Pcg64Mcg::seed_from_u64(11);
        // Triangles needing clipping are transformed again from a mesh, on both paths.
        let positions: Vec<Vec3> = (0..64)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-9.0..9.0),
                    rng.random_range(-9.0..9.0),
                    rng.random_range(-9.0..9.0),
                )
            })
            .collect();
        let triangles: Vec<[u32; 3]> = (0..512).map(|_| [0; 3].map(|_| rng.random_range(0..64u32))).collect();
        let mesh = Mesh::new(positions, triangles).expect("64 finite positions, indices in range");
        const FIRST_ITEM: ItemId = 1000;
        let draws = [Draw {
            mesh: &mesh,
            triangles: DrawTriangles::All,
            clip_from_object: View::new(Camera::look_at(Vec3::new(0.0, 2.0, 10.0), Vec3::ZERO), 640, 480)
                .expect("a valid camera and size")
                .clip_from_object(&Affine3A::IDENTITY),
            first_item: FIRST_ITEM,
        }];
        let (mut small, mut large, mut clipped, mut tiny, mut uncovered) = (0, 0, 0, 0, 0);
        // One batch for every round, as the draws use it: lanes spilled by a round are
        // still there in the next.
        let mut batch = Batch::new();
        for round in 0..4000 {
            let vp = viewport(&mut rng);
            let n = rng.random_range(1..=LANES);
            let mut scalar = Recorder::default();
            for _ in 0..n {
                let v = corners(&mut rng, &vp);
                // The item names the mesh triangle whose corners a clipped lane is cut from,
                // counted from the draw's first item.
                let triangle = rng.random_range(0..512);
                let item = FIRST_ITEM + triangle as ItemId;
                let indices = mesh.triangles()[triangle];
                batch.push([&v[0], &v[1], &v[2]], 0, item);
                let codes = v.map(|p| p.code);
                if (codes[0] | codes[1] | codes[2]) & (NEEDS_CLIP | NOT_FINITE) == NEEDS_CLIP
                    && codes[0] & codes[1] & codes[2] & OUT_OF_VIEW == 0
                {
                    clipped += 1;
                }
                let corners = || indices.map(|i| mesh.positions()[i as usize]);
                setup_triangle(&vp, v, &draws[0].clip_from_object, corners, item, &mut scalar);
            }
            let mut lanes = Recorder::default();
            // SAFETY: AVX2 was detected above.
            unsafe { setup8_avx2(&vp, &draws, &mut batch, &mut lanes) };
            assert_eq!(batch.len, 0, "the batch is emptied");
            // Same records in the same order (clipped triangles in their place), but for
            // those whose tiny box covers no centre, which are only counted.
            let mut next = lanes.records.iter();
            let mut skipped = 0;
            for s in &scalar.records {
                let b = s.1[6];
                let (px0, py0, px1, py1) = (
                    b as u16 as u32,
                    (b >> 16) as u16 as u32,
                    (b >> 32) as u16 as u32,
                    (b >> 48) as u16 as u32,
                );
                let takes_small = (s.1[12] as u32) < MASKED && px1 - px0 < SMALL && py1 - py0 < SMALL;
                let t = lanes_setup(&s.1);
                let (row, sx, sy) = edge_functions(&t, px0, py0);
                let want_mask = (takes_small && px1 - px0 < TINY && py1 - py0 < TINY).then(|| {
                    // The small scan's own row masks, in its layout.
                    (0..=py1 - py0).fold(0u64, |m, j| {
                        let r = [0, 1, 2].map(|i| (row[i] + j as i64 * sy[i]) as i32);
                        m | (row_mask(r, sx.map(|e| e as i32)) & ((1 << (px1 - px0 + 1)) - 1)) << (j * SMALL)
                    }) as u32
                });
                if takes_small && want_mask == Some(0) {
                    skipped += 1;
                    uncovered += 1;
                    small += 1;
                    continue;
                }
                let l = next
                    .next()
                    .unwrap_or_else(|| panic!("round {round}: item {} missing", s.0));
                assert_eq!(s.1, l.1, "round {round}: record of item {}", s.0);
                match l.2 {
                    Some(cover) => {
                        assert!(takes_small, "round {round}: item {} is not small", s.0);
                        let want = match want_mask {
                            Some(mask) => SmallCover::Mask(mask),
                            None => SmallCover::Edges {
                                row: row.map(|e| e as i32),
                                step_x: sx.map(|e| e as i32),
                                step_y: sy.map(|e| e as i32),
                            },
                        };
                        assert_eq!(cover, want, "round {round}: cover of item {}", s.0);
                        assert!(row.iter().all(|&e| e == e as i32 as i64), "edges fit i32");
                        small += 1;
                        tiny += want_mask.is_some() as usize;
                    }
                    None => large += 1,
                }
            }
            assert!(next.next().is_none(), "round {round}: records beyond the scalar path's");
            assert_eq!(lanes.uncovered, skipped, "round {round}: uncovered triangles counted");
            // The batch's count and box are those of the lanes it handed over.
            let union = |boxes: &mut dyn Iterator<Item = [u32; 4]>| {
                boxes.fold(super::super::EMPTY_RECT, super::super::union_rect)
            };
            let counted: u32 = lanes.lanes_counted.iter().map(|c| c.0).sum();
            assert_eq!(
                (counted as usize, union(&mut lanes.lanes_counted.iter().map(|c| c.1))),
                (lanes.lane_boxes.len(), union(&mut lanes.lane_boxes.iter().copied())),
                "round {round}: lanes counted and their box"
            );
        }
        assert!(tiny > 300 && uncovered > 200, "{tiny} tiny, {uncovered} uncovered");
        assert!(
            small > 1000 && large > 1000 && clipped > 10,
            "{small} small, {large} large, {clipped} clipped"
        );
    }

    #[test]
    fn eight_lane_projection_matches_the_scalar_one() {
        if !occult_core::simd::Isa::detected().has_avx2() {
            eprintln!("no AVX2 on this processor: the 8-lane projection is not exercised");
            return;
        }
        let mut rng = Pcg64Mcg::seed_from_u64(5);
        let special = [
            0.0,
            -0.0,
            f32::NAN,
            f32::INFINITY,
            -f32::INFINITY,
            1.0e-40,
            3.0e38,
            -1.0e30,
        ];
        let mut kinds = [0usize; 4];
        for round in 0..3000 {
            let vp = viewport(&mut rng);
            let eye = Vec3::new(
                rng.random_range(-20.0..20.0),
                rng.random_range(-20.0..20.0),
                rng.random_range(-20.0..20.0),
            );
            let mut camera = Camera::look_at(eye, Vec3::ZERO);
            camera.fov_y_deg = rng.random_range(10.0..120.0);
            camera.near = rng.random_range(0.001..1.0);
            let Ok(view) = View::new(camera, vp.width, vp.height) else {
                continue;
            };
            let mut m = view.clip_from_object(&Affine3A::IDENTITY);
            if round % 50 == 0 {
                // A projection whose w reaches zero and below on the axis.
                m.w_axis.w = 0.0;
            }
            let positions: Vec<Vec3> = (0..LANES)
                .map(|_| {
                    let mut p = Vec3::new(
                        rng.random_range(-30.0..30.0),
                        rng.random_range(-30.0..30.0),
                        rng.random_range(-30.0..30.0),
                    );
                    if rng.random_bool(0.05) {
                        p[rng.random_range(0..3)] = special[rng.random_range(0..special.len())];
                    }
                    if rng.random_bool(0.05) {
                        p = Vec3::ZERO;
                    }
                    p
                })
                .collect();
            let mut lanes = [ProjVertex::default(); LANES];
            // SAFETY: AVX2 was detected above.
            unsafe { project8_avx2(&vp, &m, &positions, &mut lanes) };
            for (p, l) in positions.iter().zip(&lanes) {
                let s = vp.project(&m, *p);
                let bits = |v: &ProjVertex| (v.x, v.y, v.z.to_bits(), v.code);
                assert_eq!(bits(&s), bits(l), "round {round}: {p}");
                kinds[match s.code {
                    c if c & NOT_FINITE != 0 => 0,
                    c if c & NEEDS_CLIP != 0 => 1,
                    0 => 2,
                    _ => 3,
                }] += 1;
            }
        }
        assert!(
            kinds.iter().all(|&k| k > 100),
            "not finite, clipped, inside, outside: {kinds:?}"
        );
    }

    /// The corners of a recorded setup (all [`edge_functions`] reads).
    fn lanes_setup(k: &[u64; 16]) -> TriSetup {
        TriSetup {
            x: [k[0] as u32 as i32, k[1] as u32 as i32, k[2] as u32 as i32],
            y: [k[3] as u32 as i32, k[4] as u32 as i32, k[5] as u32 as i32],
            px0: 0,
            py0: 0,
            px1: 0,
            py1: 0,
            zc: 0.0,
            dzdx: 0.0,
            dzdy: 0.0,
            zmin: 0.0,
            zmax: 0.0,
            extent: 0,
            front: false,
            item: 0,
        }
    }
}
