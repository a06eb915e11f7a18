//! Row kernels of the N-buffer build (§2 "Construction"), compiled once per instruction set.
//!
//! The same Rust code is compiled for the baseline target and, chosen at run time, with AVX2
//! (and AVX-512BW where the CPU has it): the kernels are integer `min` / `max` over 16-bit keys
//! and bit manipulation of f32 depths, so every instruction set gives bit-identical levels
//! (held by tests against the baseline path). The instruction set is [`occult_core::simd`]'s,
//! detected once; its `isa_dispatch!` writes the `#[target_feature]` wrappers. The only
//! `unsafe` left here is a prefetch hint.

use super::{order_bits, Extremum, Key};

/// The instruction sets the kernels are compiled for (see [`occult_core::simd`]).
pub(super) use occult_core::simd::Isa;

occult_core::isa_dispatch! {
    /// Level 0 of one row: the storage key of each depth ([`Extremum::key_of`]), NaN read as
    /// `unknown` (the key of the variant's worst case).
    pub(super) fn keys_row(ext: Extremum, out: &mut [Key], src: &[f32], unknown: Key) -> ();
    baseline => keys_row_kernel,
    avx512("avx512f,avx512bw") => keys_row_kernel,
    avx2("avx2") => keys_row_kernel,
}

occult_core::isa_dispatch! {
    /// One row of level `i + 1` from rows `y` (`a`) and `y + step` (`b`) of level `i`
    /// (`step = 2^i`): the extremum of `a[x], a[x + step], b[x], b[x + step]`, the neighbours
    /// at `x + step ≥ width` skipped. `b` is `None` on the last `step` rows (no row below).
    pub(super) fn combine(ext: Extremum, out: &mut [Key], a: &[Key], b: Option<&[Key]>, step: usize) -> ();
    baseline => combine_kernel,
    avx512("avx512f,avx512bw") => combine_kernel,
    avx2("avx2") => combine_kernel,
}

#[inline(always)]
fn keys_row_kernel(ext: Extremum, out: &mut [Key], src: &[f32], unknown: Key) {
    // Branch-free forms of `Extremum::key_of` (one loop per variant, so each vectorizes).
    match ext {
        Extremum::Min => {
            for (o, &s) in out.iter_mut().zip(src) {
                let k = (order_bits_branchless(s) >> 16) as Key;
                *o = if s.is_nan() { unknown } else { k };
            }
        }
        Extremum::Max => {
            for (o, &s) in out.iter_mut().zip(src) {
                let k = (order_bits_branchless(s).saturating_add(0xffff) >> 16) as Key;
                *o = if s.is_nan() { unknown } else { k };
            }
        }
    }
}

/// [`order_bits`] without a branch: negative floats have every bit flipped, others the sign set.
#[inline(always)]
fn order_bits_branchless(f: f32) -> u32 {
    let b = f.to_bits();
    let flip = ((b as i32) >> 31) as u32 | 0x8000_0000;
    let o = b ^ flip;
    debug_assert!(f.is_nan() || o == order_bits(f));
    o
}

#[inline(always)]
fn combine_kernel(ext: Extremum, out: &mut [Key], a: &[Key], b: Option<&[Key]>, step: usize) {
    match (ext, b) {
        (Extremum::Min, Some(b)) => combine2(out, a, b, step, Key::min),
        (Extremum::Max, Some(b)) => combine2(out, a, b, step, Key::max),
        (Extremum::Min, None) => combine1(out, a, step, Key::min),
        (Extremum::Max, None) => combine1(out, a, step, Key::max),
    }
}

#[inline(always)]
fn combine2(out: &mut [Key], a: &[Key], b: &[Key], step: usize, f: impl Fn(Key, Key) -> Key) {
    let w = out.len();
    let (a, b) = (&a[..w], &b[..w]);
    let inner = w.saturating_sub(step);
    let (out_in, out_edge) = out.split_at_mut(inner);
    for ((((o, &a0), &a1), &b0), &b1) in out_in
        .iter_mut()
        .zip(a)
        .zip(&a[w - inner..])
        .zip(b)
        .zip(&b[w - inner..])
    {
        *o = f(f(a0, a1), f(b0, b1));
    }
    for ((o, &a0), &b0) in out_edge.iter_mut().zip(&a[inner..]).zip(&b[inner..]) {
        *o = f(a0, b0);
    }
}

#[inline(always)]
fn combine1(out: &mut [Key], a: &[Key], step: usize, f: impl Fn(Key, Key) -> Key) {
    let w = out.len();
    let a = &a[..w];
    let inner = w.saturating_sub(step);
    let (out_in, out_edge) = out.split_at_mut(inner);
    for ((o, &a0), &a1) in out_in.iter_mut().zip(a).zip(&a[w - inner..]) {
        *o = f(a0, a1);
    }
    out_edge.copy_from_slice(&a[inner..]);
}

/// Asks the CPU to bring the cache line of `keys[index]` into the caches (a hint: no effect on
/// results, nothing when the index is out of range or the target has no prefetch).
#[inline(always)]
pub(super) fn prefetch(keys: &[Key], index: usize) {
    if let Some(k) = keys.get(index) {
        occult_core::simd::prefetch(k as *const Key);
    }
}

/// Rectangles whose covers [`cover_block`] computes at once (one AVX-512 register of `u32`).
pub(super) const LANES: usize = 16;

/// What [`cover_block`] needs of the map: its size, its level count, and where the whole map's
/// extremum is kept. Valid only when every index into the levels fits in a `u32`.
#[derive(Clone, Copy, Debug)]
pub(super) struct CoverMap {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) level_count: u32,
    /// Index of the key past the levels (`level_count × width × height`).
    pub(super) whole_index: u32,
}

occult_core::isa_dispatch! {
    /// The four key indices of the Fig. 3 cover of each of `rects` (as
    /// `NBuffer::four_indices`), lane by lane: `idx[j][k]` is the `j`-th lookup of rectangle
    /// `k`, `lookups[k]` its lookup count, 0 for an empty rectangle (whose indices then point
    /// to the whole map's extremum, a valid index never read).
    pub(super) fn cover_block(
        map: &CoverMap,
        rects: &[crate::PixelRect; LANES],
        idx: &mut [[u32; LANES]; 4],
        lookups: &mut [u32; LANES],
    ) -> ();
    baseline => cover_block_kernel,
    avx512("avx512f,avx512bw,avx512cd,bmi1,lzcnt") => cover_block_kernel,
    avx2("avx2,bmi1,lzcnt") => cover_block_kernel,
}

/// The cover of `NBuffer::four_indices` written lane-wise without branches (selects and
/// wrapping 32-bit arithmetic, so that the loop vectorizes); the values of lanes that a select
/// discards may wrap and are never used.
#[inline(always)]
fn cover_block_kernel(
    map: &CoverMap,
    rects: &[crate::PixelRect; LANES],
    idx: &mut [[u32; LANES]; 4],
    lookups: &mut [u32; LANES],
) {
    let (w, h) = (map.width, map.height);
    let n_px = w.wrapping_mul(h);
    for k in 0..LANES {
        let r = rects[k];
        let (x0, y0) = (r.x0, r.y0);
        let x1 = r.x1.min(w);
        let y1 = r.y1.min(h);
        let empty = x0 >= x1 || y0 >= y1;
        let dx = x1.wrapping_sub(x0);
        let dy = y1.wrapping_sub(y0);
        let m = if empty { 1 } else { dx.max(dy) };
        // ⌈log2 m⌉ (0 for m = 1).
        let n = 32 - (m - 1).leading_zeros();
        let half = (1u32 << n.saturating_sub(1)) & 0u32.wrapping_sub(u32::from(n != 0));
        let quarter = half >> 1;
        let row4 = dx > half && dy <= quarter;
        let col4 = dy > half && dx <= quarter;
        let four = row4 | col4;
        let level = n.saturating_sub(1).wrapping_sub(u32::from(four));
        let s = 1u32 << (level & 31);
        let ex = x1.saturating_sub(s).max(x0).wrapping_sub(x0);
        let ey = y1.saturating_sub(s).max(y0).wrapping_sub(y0).wrapping_mul(w);
        let along = if row4 { s } else { w << (level & 31) };
        let a = if four { along } else { ex };
        let b = if four { along << 1 } else { ey };
        let base = level
            .wrapping_mul(n_px)
            .wrapping_add(y0.wrapping_mul(w))
            .wrapping_add(x0);
        let inside = level < map.level_count && !empty;
        let whole = map.whole_index;
        idx[0][k] = if inside { base } else { whole };
        idx[1][k] = if inside { base.wrapping_add(a) } else { whole };
        idx[2][k] = if inside { base.wrapping_add(b) } else { whole };
        idx[3][k] = if inside {
            base.wrapping_add(ex).wrapping_add(ey)
        } else {
            whole
        };
        lookups[k] = if empty {
            0
        } else if n == 0 || !inside {
            1
        } else {
            4
        };
    }
}
