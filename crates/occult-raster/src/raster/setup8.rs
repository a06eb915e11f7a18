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
#[cfg(target_arch = "x86_64")]
use occult_core::simd::{Avx2, F32x4, F32x8, F64x4, I32x8, M32x8, M64x4};
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
    // SAFETY: the caller vouches for AVX2.
    let avx2 = unsafe { Avx2::new_unchecked() };
    const SHIFT: i32 = SUBPIXEL_BITS as i32;
    let n = batch.len;
    batch.len = 0;
    if n == 0 {
        return;
    }
    let in_batch = (1u32 << n) - 1;
    // Corner c of the eight lanes, from eight 16-byte vertices.
    let corner = |c: usize| {
        let [x, y, z, code] = I32x8::from_rows(avx2, as_rows(&batch.corners[c]));
        (x, y, z.to_f32_bits(), code)
    };
    let (x0, y0, z0, c0) = corner(0);
    let (x1, y1, z1, c1) = corner(1);
    let (x2, y2, z2, c2) = corner(2);
    let splat = |v: i32| I32x8::splat(avx2, v);
    let zero = I32x8::zero(avx2);
    let any = |c: I32x8, flags: u32| c.and(splat(flags as i32)).gt(zero).bits();
    let all_codes = c0.and(c1).and(c2);
    let any_codes = c0.or(c1).or(c2);
    let rejected = any(all_codes, OUT_OF_VIEW) | any(any_codes, NOT_FINITE);
    let clipped = in_batch & !rejected & any(any_codes, NEEDS_CLIP);
    let mut live = in_batch & !rejected & !clipped;

    // Pixel boxes: centres (i + 1/2) inside [min, max] of the snapped corners.
    let min3 = |a: I32x8, b, c| a.min(b).min(c);
    let max3 = |a: I32x8, b, c| a.max(b).max(c);
    let (minx, maxx) = (min3(x0, x1, x2), max3(x0, x1, x2));
    let (miny, maxy) = (min3(y0, y1, y2), max3(y0, y1, y2));
    let shift = |v: I32x8, add: i64| v.wrapping_add(splat(add as i32)).shr::<SHIFT>();
    let px0 = shift(minx, SUB - 1 - HALF).max(zero);
    let py0 = shift(miny, SUB - 1 - HALF).max(zero);
    let px1 = shift(maxx, -HALF).min(splat(vp.width as i32 - 1));
    let py1 = shift(maxy, -HALF).min(splat(vp.height as i32 - 1));
    live &= !px0.gt(px1).or(py0.gt(py1)).bits();
    if live == 0 && clipped == 0 {
        return;
    }
    let l = &mut batch.lanes;
    l.px0 = px0.to_array();
    l.py0 = py0.to_array();
    l.py1 = py1.to_array();
    // Every lane, without a branch on which are live (a loop over the live ones mispredicts
    // its exit): a dead lane's hint names pixel (0, 0).
    let on = M32x8::from_bits(avx2, live);
    let (xs, ys) = (px0.keep(on).to_array(), py0.keep(on).to_array());
    let two_rows = live & py1.gt(py0).bits();
    for k in 0..LANES {
        out.will_touch(xs[k] as u32, ys[k] as u32, two_rows & (1 << k) != 0);
    }

    // Area, exact in f64 halves: |coordinates| < 2^24, so products < 2^50.
    let (dx1, dy1) = (x1.wrapping_sub(x0), y1.wrapping_sub(y0));
    let (dx2, dy2) = (x2.wrapping_sub(x0), y2.wrapping_sub(y0));
    let (area_lo, area_hi) = (
        area(dx1.low_f64(), dy1.low_f64(), dx2.low_f64(), dy2.low_f64()),
        area(dx1.high_f64(), dy1.high_f64(), dx2.high_f64(), dy2.high_f64()),
    );
    let zd = F64x4::zero(avx2);
    let signs = |lo: M64x4, hi: M64x4| lo.bits() | (hi.bits() << 4);
    let negative = signs(area_lo.lt(zd), area_hi.lt(zd));
    let positive = signs(area_lo.gt(zd), area_hi.gt(zd));
    // Zero areas fail both.
    live &= negative | if vp.cull_backfaces { 0 } else { positive };

    // Orient counter-clockwise on screen (negative area) triangles like the others: swap 1, 2.
    let swap = M32x8::from_bits(avx2, negative);
    let (x1, x2) = (I32x8::select(swap, x2, x1), I32x8::select(swap, x1, x2));
    let (y1, y2) = (I32x8::select(swap, y2, y1), I32x8::select(swap, y1, y2));
    let (z1, z2) = (F32x8::select(swap, z2, z1), F32x8::select(swap, z1, z2));
    let (area_lo, area_hi) = (area_lo.abs(), area_hi.abs());

    // Depth range, as `min_f32` / `max_f32` (the instructions' own operand rule).
    let zmin = z0.min(z1).min(z2);
    let zmax = z0.max(z1).max(z2);
    live &= !zmax.lt(F32x8::splat(avx2, vp.far_depth)).bits();

    // Lanes whose box the small scan takes, with their edge functions in `l`; those of them
    // whose box is at most `TINY × TINY`, with their mask of covered centres in `l`; and
    // those of these that cover no centre.
    let mut small = 0;
    let mut tiny = 0;
    let mut uncovered = 0;
    if live != 0 {
        // Depth plane in pixel units relative to corner 0, in f64, anchored at the centre of
        // pixel (px0, py0): the scalar expression, operation for operation.
        let (dz1, dz2) = (z1 - z0, z2 - z0);
        let (dx1, dy1) = (x1.wrapping_sub(x0), y1.wrapping_sub(y0));
        let (dx2, dy2) = (x2.wrapping_sub(x0), y2.wrapping_sub(y0));
        let (zc_lo, dzdx_lo, dzdy_lo) = plane(
            avx2,
            area_lo,
            [dx1.low_f64(), dy1.low_f64(), dx2.low_f64(), dy2.low_f64()],
            [dz1.low_f64(), dz2.low_f64(), z0.low_f64()],
            [px0.low_f64(), py0.low_f64(), x0.low_f64(), y0.low_f64()],
        );
        let (zc_hi, dzdx_hi, dzdy_hi) = plane(
            avx2,
            area_hi,
            [dx1.high_f64(), dy1.high_f64(), dx2.high_f64(), dy2.high_f64()],
            [dz1.high_f64(), dz2.high_f64(), z0.high_f64()],
            [px0.high_f64(), py0.high_f64(), x0.high_f64(), y0.high_f64()],
        );
        l.zc = F32x8::from_halves(zc_lo, zc_hi).to_array();
        l.dzdx = F32x8::from_halves(dzdx_lo, dzdx_hi).to_array();
        l.dzdy = F32x8::from_halves(dzdy_lo, dzdy_hi).to_array();
        l.zmin = zmin.to_array();
        l.zmax = zmax.to_array();
        let extent = maxx
            .wrapping_sub(minx)
            .max(maxy.wrapping_sub(miny))
            .shr::<SHIFT>()
            .wrapping_add(splat(1));
        let extent = extent.min(splat(u16::MAX as i32));
        l.extent = extent.to_array();
        l.px1 = px1.to_array();
        let (xs, ys) = ([x0, x1, x2], [y0, y1, y2]);
        for c in 0..3 {
            l.x[c] = xs[c].to_array();
            l.y[c] = ys[c].to_array();
        }
        // Edge functions at the centre of pixel (px0, py0), for the small scan: exact in i32
        // for boxes it takes (see `scan_small`); other lanes are not read.
        // The box's width and height less one pixel.
        let (w, h) = (px1.wrapping_sub(px0), py1.wrapping_sub(py0));
        let small_box = splat(SMALL as i32);
        small = if S::TAKES_EDGES { live } else { 0 }
            & splat(MASKED as i32).gt(extent).bits()
            & small_box.gt(w).bits()
            & small_box.gt(h).bits();
        // Edge functions at the first centre and their steps, kept for the masks below.
        let (mut rows, mut sxs, mut sys) = ([zero; 3], [zero; 3], [zero; 3]);
        if small != 0 {
            let centre = |p: I32x8| p.shl::<SHIFT>().wrapping_add(splat(HALF as i32));
            let (cx, cy) = (centre(px0), centre(py0));
            for i in 0..3 {
                let j = (i + 1) % 3;
                let ea = ys[i].wrapping_sub(ys[j]);
                let eb = xs[j].wrapping_sub(xs[i]);
                // Top-left rule as in `scan_triangle`: -1 unless A > 0, or A = 0 and B > 0.
                let bias = ea.lt(zero).or(ea.eq(zero).and_not(eb.gt(zero))).to_i32x8();
                rows[i] = ea
                    .wrapping_mul(cx.wrapping_sub(xs[i]))
                    .wrapping_add(eb.wrapping_mul(cy.wrapping_sub(ys[i])))
                    .wrapping_add(bias);
                sxs[i] = ea.shl::<SHIFT>();
                sys[i] = eb.shl::<SHIFT>();
                l.row[i] = rows[i].to_array();
                l.step_x[i] = sxs[i].to_array();
                l.step_y[i] = sys[i].to_array();
            }
            let tiny_box = splat(TINY as i32);
            tiny = small & tiny_box.gt(w).bits() & tiny_box.gt(h).bits();
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
                    let out = e[0].or(e[1]).or(e[2]);
                    let bit = splat(1 << (j * SMALL + i));
                    inside = inside.or(bit.and_not(out.shr::<31>()));
                    for k in 0..3 {
                        e[k] = e[k].wrapping_add(sxs[k]);
                    }
                }
                for k in 0..3 {
                    row[k] = row[k].wrapping_add(sys[k]);
                }
            }
            // Only the centres inside the box: (1 << (w + 1)) - 1 per row, for its h + 1 rows.
            let one = splat(1);
            let columns = one.shl_var(w.wrapping_add(one)).wrapping_sub(one);
            let mut valid = columns;
            for j in 1..TINY {
                let has_row = h.gt(splat(j as i32 - 1));
                let shifted = columns.shl_var(splat((j * SMALL) as i32));
                valid = valid.or(shifted.keep(has_row));
            }
            let mask = inside.and(valid);
            l.mask = mask.to_array();
            uncovered = tiny & mask.eq(zero).bits();
        }
    }
    // In stream order: the set-up lanes, and the clipped ones through the scalar path.
    out.count_uncovered(uncovered.count_ones());
    if S::COUNTS_LANES {
        // The lanes about to be scanned (clipped ones count themselves) and their box.
        let scanned = live & !uncovered;
        let on = M32x8::from_bits(avx2, scanned);
        // Boxes lie in the frame (no lane is negative): unsigned, u32::MAX stands for no lane
        // in a minimum and 0 in a maximum, as in `EMPTY_RECT`.
        let least = |v: I32x8| v.or((!on).to_i32x8()).reduce_min_u32();
        let most = |v: I32x8| v.keep(on).reduce_max() as u32;
        out.count_lanes(scanned.count_ones(), [least(px0), least(py0), most(px1), most(py1)]);
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
/// The processor must support AVX2.
///
/// # Panics
/// When `positions` or `out` holds fewer than eight entries.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn project8_avx2(vp: &Viewport, m: &Mat4, positions: &[Vec3], out: &mut [ProjVertex]) {
    // SAFETY: the caller vouches for AVX2.
    let avx2 = unsafe { Avx2::new_unchecked() };
    let (Some(positions), Some(out)) = (positions.first_chunk::<LANES>(), out.first_chunk_mut::<LANES>()) else {
        panic!("eight positions and room for eight projected vertices");
    };
    // SAFETY: `Vec3` is three `f32` without padding (size asserted below), so eight of them
    // are 24 floats in the layout of `[[f32; 3]; 8]`, with the same alignment.
    let points = unsafe { &*positions.as_ptr().cast::<[[f32; 3]; LANES]>() };
    let [x, y, z] = F32x8::deinterleave3(avx2, points);
    let splat = |v: f32| F32x8::splat(avx2, v);
    let one = splat(1.0);
    let row = |r: usize| {
        let c = |axis: Vec4| splat(axis[r]);
        c(m.x_axis) * x + c(m.y_axis) * y + c(m.z_axis) * z + c(m.w_axis) * one
    };
    let (cx, cy, cz, cw) = (row(0), row(1), row(2), row(3));
    let inf = splat(f32::INFINITY);
    let finite = |v: F32x8| v.abs().lt(inf);
    let flag = |mask: M32x8, f: u32| I32x8::splat(avx2, f as i32).keep(mask);
    let beyond = |k: usize| splat(vp.band_ndc[k]) * cw;
    let mut code = flag(cx.lt(beyond(0)), OUT_LEFT)
        .or(flag(cx.gt(beyond(1)), OUT_RIGHT))
        .or(flag(cy.lt(beyond(2)), OUT_BOTTOM).or(flag(cy.gt(beyond(3)), OUT_TOP)));
    let near = cz.gt(cw).or(cw.le(F32x8::zero(avx2)));
    code = code.or(flag(near, OUT_NEAR | NEEDS_CLIP));
    let guard = cx
        .abs()
        .gt(splat(vp.guard_x) * cw)
        .or(cy.abs().gt(splat(vp.guard_y) * cw));
    code = code.or(flag(guard, NEEDS_CLIP));
    let inv_w = one / cw;
    let half = splat(0.5);
    let sx = (cx * inv_w * half + half) * splat(vp.fwidth);
    let sy = (half - cy * inv_w * half) * splat(vp.fheight);
    let zs = cz * inv_w;
    let sub = splat(SUB as f32);
    let (px, py) = ((sx * sub).round_to_i32(), (sy * sub).round_to_i32());
    // Lanes that keep a position: finite clip coordinates, no clipping, a finite projection.
    let clip_finite = finite(cx).and(finite(cy)).and(finite(cz).and(finite(cw)));
    let needs_clip = code.and(I32x8::splat(avx2, NEEDS_CLIP as i32)).gt(I32x8::zero(avx2));
    let projected = finite(sx).and(finite(sy)).and(finite(zs));
    let keep = clip_finite.and(projected).and_not(needs_clip);
    // Not finite: the code alone; needing clipping: the codes, no position.
    let not_finite = (!clip_finite).or((!projected).and_not(needs_clip));
    let code = I32x8::select(not_finite, I32x8::splat(avx2, NOT_FINITE as i32), code);
    // Eight (x, y, z, code) records.
    I32x8::to_rows(
        [px.keep(keep), py.keep(keep), zs.to_bits().keep(keep), code],
        as_rows_mut(out),
    );
}

// `project8_avx2` reads eight `Vec3` as 24 floats.
const _: () = assert!(std::mem::size_of::<Vec3>() == 12);

/// Eight projected vertices as rows of four 32-bit fields, the layout the lane transposes read.
#[inline(always)]
fn as_rows(v: &[ProjVertex; LANES]) -> &[[i32; 4]; LANES] {
    // SAFETY: `ProjVertex` is `repr(C)` with four 4-byte fields and no padding (size
    // asserted), so it has the size and alignment of `[i32; 4]`, and any field's bits are a
    // valid `i32`.
    unsafe { &*v.as_ptr().cast() }
}

/// [`as_rows`], to write.
#[inline(always)]
fn as_rows_mut(v: &mut [ProjVertex; LANES]) -> &mut [[i32; 4]; LANES] {
    // SAFETY: as in `as_rows`; and any 32 bits are a valid value of each field (`i32`, `f32`,
    // `u32`), so whatever is written leaves valid vertices.
    unsafe { &mut *v.as_mut_ptr().cast() }
}

/// `(x1 - x0)(y2 - y0) - (x2 - x0)(y1 - y0)` from the differences `[dx1, dy1, dx2, dy2]`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn area(dx1: F64x4, dy1: F64x4, dx2: F64x4, dy2: F64x4) -> F64x4 {
    dx1 * dy2 - dx2 * dy1
}

/// The scalar setup's depth plane in four f64 lanes: `d = [dx1, dy1, dx2, dy2]` (oriented
/// corners minus corner 0, in 1/256 pixel), `z = [z1 - z0, z2 - z0, z0]` (the differences taken
/// in f32, as there), `o = [px0, py0, x0, y0]`; returns `(zc, dzdx, dzdy)` rounded to f32.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn plane(avx2: Avx2, area: F64x4, d: [F64x4; 4], z: [F64x4; 3], o: [F64x4; 4]) -> (F32x4, F32x4, F32x4) {
    let splat = |v: f64| F64x4::splat(avx2, v);
    let sub = splat(SUB as f64);
    let half = splat(0.5);
    let inv = splat(1.0) / (area / splat((SUB * SUB) as f64));
    let (fx1, fy1) = (d[0] / sub, d[1] / sub);
    let (fx2, fy2) = (d[2] / sub, d[3] / sub);
    let [dz1, dz2, z0] = z;
    let dzdx = (dz1 * fy2 - dz2 * fy1) * inv;
    let dzdy = (fx1 * dz2 - fx2 * dz1) * inv;
    let ox = o[0] + half - o[2] / sub;
    let oy = o[1] + half - o[3] / sub;
    let zc = z0 + dzdx * ox + dzdy * oy;
    (zc.to_f32(), dzdx.to_f32(), dzdy.to_f32())
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
            region: [0, 0, width - 1, height - 1],
            band_ndc: [-1.0, 1.0, -1.0, 1.0],
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
