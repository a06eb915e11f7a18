//! [`F32x8`]: eight `f32` lanes.

use super::{Avx2, F32x4, F64x4, I32x8, M32x8};
use std::arch::x86_64::*;

/// Eight `f32` lanes in one AVX2 register. Every operation is one instruction (or the short
/// fixed sequence its doc names), inlined into the caller (which should itself be compiled for
/// AVX2, e.g. a kernel of [`isa_dispatch!`](crate::isa_dispatch)). Arithmetic (`+ - * /`, and
/// `-` as a sign flip) rounds each lane as the scalar operation does, and nothing is ever
/// contracted, so a lane holds the scalar expression's bits.
#[derive(Clone, Copy, Debug)]
pub struct F32x8(pub(super) __m256);

super::float_ops!(F32x8: _mm256_add_ps, _mm256_sub_ps, _mm256_mul_ps, _mm256_div_ps, _mm256_xor_ps, _mm256_set1_ps);

impl F32x8 {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(_: Avx2, v: f32) -> Self {
        // SAFETY: the token proves AVX2.
        Self(unsafe { _mm256_set1_ps(v) })
    }

    /// Every lane +0.0.
    #[inline(always)]
    pub fn zero(_: Avx2) -> Self {
        // SAFETY: the token proves AVX2.
        Self(unsafe { _mm256_setzero_ps() })
    }

    /// Lane `i` is `src[i]` (one unaligned load).
    #[inline(always)]
    pub fn load(_: Avx2, src: &[f32; 8]) -> Self {
        // SAFETY: the token proves AVX2; `src` holds the 32 bytes read.
        Self(unsafe { _mm256_loadu_ps(src.as_ptr()) })
    }

    /// Writes lane `i` to `dst[i]` (one unaligned store).
    #[inline(always)]
    pub fn store(self, dst: &mut [f32; 8]) {
        // SAFETY: a lane value exists only where AVX2 was proven (its token); `dst` holds the
        // 32 bytes written.
        unsafe { _mm256_storeu_ps(dst.as_mut_ptr(), self.0) }
    }

    /// Lane `i` is `*src.add(i)` where `m` is set, +0.0 elsewhere (one masked load: the
    /// lanes not set are not read and cannot fault).
    ///
    /// # Safety
    /// `src.add(i)` must be valid for reads for every lane `i` set in `m`.
    #[inline(always)]
    pub unsafe fn load_masked(_: Avx2, src: *const f32, m: M32x8) -> Self {
        // SAFETY: the token proves AVX2; the caller vouches for the lanes read.
        Self(unsafe { _mm256_maskload_ps(src, m.0) })
    }

    /// Writes lane `i` to `*dst.add(i)` for every lane `i` set in `m`, nothing elsewhere (one
    /// masked store).
    ///
    /// # Safety
    /// `dst.add(i)` must be valid for writes for every lane `i` set in `m`.
    #[inline(always)]
    pub unsafe fn store_masked(self, dst: *mut f32, m: M32x8) {
        // SAFETY: a lane value exists only where AVX2 was proven (its token); the caller
        // vouches for the lanes written.
        unsafe { _mm256_maskstore_ps(dst, m.0, self.0) }
    }

    /// Lane `i` is `v[i]`.
    #[inline(always)]
    pub fn from_array(_: Avx2, v: [f32; 8]) -> Self {
        // SAFETY: the token proves AVX2.
        Self(unsafe { _mm256_setr_ps(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7]) })
    }

    /// Lanes 0..4 from `low`, 4..8 from `high`.
    #[inline(always)]
    pub fn from_halves(low: F32x4, high: F32x4) -> Self {
        // SAFETY: a lane value exists only where AVX2 was proven (its token).
        Self(unsafe { _mm256_set_m128(high.0, low.0) })
    }

    /// The `x`, `y` and `z` lanes of eight points: lane `k` of result `a` is `p[k][a]` (six
    /// 16-byte loads and five shuffles).
    #[inline(always)]
    pub fn deinterleave3(_: Avx2, p: &[[f32; 3]; 8]) -> [Self; 3] {
        let base: *const f32 = p.as_ptr().cast();
        // SAFETY: the token proves AVX2; `[[f32; 3]; 8]` is 24 floats without padding, and
        // each load reads the 4 floats from an offset of at most 20, inside them (unaligned
        // loads are allowed).
        unsafe {
            let pair = |lo: usize, hi: usize| _mm256_loadu2_m128(base.add(hi), base.add(lo));
            let m03 = pair(0, 12); // x0 y0 z0 x1 | x4 y4 z4 x5
            let m14 = pair(4, 16); // y1 z1 x2 y2 | y5 z5 x6 y6
            let m25 = pair(8, 20); // z2 x3 y3 z3 | z6 x7 y7 z7
            let xy = _mm256_shuffle_ps::<0b10_01_11_10>(m14, m25); // x2 y2 x3 y3 | x6 y6 x7 y7
            let yz = _mm256_shuffle_ps::<0b01_00_10_01>(m03, m14); // y0 z0 y1 z1 | y4 z4 y5 z5
            [
                Self(_mm256_shuffle_ps::<0b10_00_11_00>(m03, xy)),
                Self(_mm256_shuffle_ps::<0b11_01_10_00>(yz, xy)),
                Self(_mm256_shuffle_ps::<0b11_00_11_01>(yz, m25)),
            ]
        }
    }

    /// Lane `i` is `*base.offset(offsets[i])` where `m` is set, +0.0 where it is not (one
    /// masked gather).
    ///
    /// # Safety
    /// For every lane set in `m`, `base.offset(offsets[i])` must be valid for a read of an
    /// `f32`. Lanes not set are not read.
    #[inline(always)]
    pub unsafe fn gather_masked(_: Avx2, base: *const f32, offsets: I32x8, m: M32x8) -> Self {
        // SAFETY: the token proves AVX2; the caller vouches for the addresses of set lanes,
        // the only ones read.
        Self(unsafe { _mm256_mask_i32gather_ps::<4>(_mm256_setzero_ps(), base, offsets.0, _mm256_castsi256_ps(m.0)) })
    }

    /// The lanes as an array.
    #[inline(always)]
    pub fn to_array(self) -> [f32; 8] {
        // SAFETY: `__m256` and `[f32; 8]` have the same size, and every bit pattern is valid
        // for both.
        unsafe { std::mem::transmute(self.0) }
    }

    /// The lanes' bits (as `f32::to_bits`, no instruction).
    #[inline(always)]
    pub fn to_bits(self) -> I32x8 {
        // SAFETY: a lane value exists only where AVX2 was proven (its token).
        I32x8(unsafe { _mm256_castps_si256(self.0) })
    }

    /// Lanes with the bits `v` (as `f32::from_bits`, no instruction).
    #[inline(always)]
    pub fn from_bits(v: I32x8) -> Self {
        // SAFETY: as in `to_bits`.
        Self(unsafe { _mm256_castsi256_ps(v.0) })
    }

    /// Lane-wise `if self < o { self } else { o }`: the instruction's rule, which gives `o`
    /// where either is NaN or both are zero (glam's `Vec3::min`, not `f32::min`).
    #[inline(always)]
    pub fn min(self, o: Self) -> Self {
        // SAFETY: as in `to_bits`.
        Self(unsafe { _mm256_min_ps(self.0, o.0) })
    }

    /// Lane-wise `if self > o { self } else { o }` (the rule of [`F32x8::min`]).
    #[inline(always)]
    pub fn max(self, o: Self) -> Self {
        // SAFETY: as in `to_bits`.
        Self(unsafe { _mm256_max_ps(self.0, o.0) })
    }

    /// Lane-wise absolute value (the sign bit cleared).
    #[inline(always)]
    pub fn abs(self) -> Self {
        // SAFETY: as in `to_bits`.
        Self(unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0) })
    }

    /// Lane-wise `f32::is_nan`.
    #[inline(always)]
    pub fn is_nan(self) -> M32x8 {
        // SAFETY: as in `to_bits`.
        M32x8(unsafe { _mm256_castps_si256(_mm256_cmp_ps::<_CMP_UNORD_Q>(self.0, self.0)) })
    }

    /// Lane-wise `==` (false where either is NaN).
    #[inline(always)]
    pub fn eq(self, o: Self) -> M32x8 {
        // SAFETY: as in `to_bits`.
        M32x8(unsafe { _mm256_castps_si256(_mm256_cmp_ps::<_CMP_EQ_OQ>(self.0, o.0)) })
    }

    /// Lane-wise `<` (false where either is NaN).
    #[inline(always)]
    pub fn lt(self, o: Self) -> M32x8 {
        // SAFETY: as in `to_bits`.
        M32x8(unsafe { _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LT_OQ>(self.0, o.0)) })
    }

    /// Lane-wise `<=` (false where either is NaN).
    #[inline(always)]
    pub fn le(self, o: Self) -> M32x8 {
        // SAFETY: as in `to_bits`.
        M32x8(unsafe { _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LE_OQ>(self.0, o.0)) })
    }

    /// Lane-wise `>` (false where either is NaN).
    #[inline(always)]
    pub fn gt(self, o: Self) -> M32x8 {
        // SAFETY: as in `to_bits`.
        M32x8(unsafe { _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GT_OQ>(self.0, o.0)) })
    }

    /// Lane-wise `>=` (false where either is NaN).
    #[inline(always)]
    pub fn ge(self, o: Self) -> M32x8 {
        // SAFETY: as in `to_bits`.
        M32x8(unsafe { _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GE_OQ>(self.0, o.0)) })
    }

    /// Lane-wise `if m { t } else { f }`.
    #[inline(always)]
    pub fn select(m: M32x8, t: Self, f: Self) -> Self {
        // SAFETY: as in `to_bits`.
        Self(unsafe { _mm256_blendv_ps(f.0, t.0, _mm256_castsi256_ps(m.0)) })
    }

    /// The lanes where `m` is set, +0.0 in the others (a bitwise and).
    #[inline(always)]
    pub fn keep(self, m: M32x8) -> Self {
        // SAFETY: as in `to_bits`.
        Self(unsafe { _mm256_and_ps(self.0, _mm256_castsi256_ps(m.0)) })
    }

    /// Lane `i` is lane `index[i] & 7` of `self` (one cross-lane permute).
    #[inline(always)]
    pub fn permute(self, index: I32x8) -> Self {
        // SAFETY: as in `to_bits`.
        Self(unsafe { _mm256_permutevar8x32_ps(self.0, index.0) })
    }

    /// Lane-wise conversion to `i32` in the current rounding mode (to nearest, ties to even,
    /// unless changed); NaN and values out of range give `i32::MIN`.
    #[inline(always)]
    pub fn round_to_i32(self) -> I32x8 {
        // SAFETY: as in `to_bits`.
        I32x8(unsafe { _mm256_cvtps_epi32(self.0) })
    }

    /// Lanes 0..4 as `f64` (exact).
    #[inline(always)]
    pub fn low_f64(self) -> F64x4 {
        // SAFETY: as in `to_bits`.
        F64x4(unsafe { _mm256_cvtps_pd(_mm256_castps256_ps128(self.0)) })
    }

    /// Lanes 4..8 as `f64` (exact).
    #[inline(always)]
    pub fn high_f64(self) -> F64x4 {
        // SAFETY: as in `to_bits`.
        F64x4(unsafe { _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(self.0)) })
    }
}

#[cfg(test)]
mod tests {
    use super::super::Isa;
    use super::*;

    const A: [f32; 8] = [1.5, -0.0, 0.0, f32::NAN, -3.25, f32::INFINITY, 1e-40, 7.0];
    const B: [f32; 8] = [0.1, 0.0, -0.0, 2.0, f32::NAN, -1e30, 3.0, 7.0];

    /// The same bits, or both NaN (a NaN's sign and payload depend on whether the compiler
    /// folded the scalar operation).
    fn same(a: [f32; 8], b: [f32; 8]) -> bool {
        a.iter()
            .zip(&b)
            .all(|(x, y)| x.to_bits() == y.to_bits() || x.is_nan() && y.is_nan())
    }

    #[test]
    fn lanes_match_scalar_arithmetic() {
        let Some(avx2) = Isa::detected().avx2() else {
            eprintln!("note: no AVX2 here; nothing to compare");
            return;
        };
        let (a, b) = (F32x8::from_array(avx2, A), F32x8::from_array(avx2, B));
        let want = |f: fn(f32, f32) -> f32| std::array::from_fn::<f32, 8, _>(|i| f(A[i], B[i]));
        let bits = |f: fn(f32, f32) -> bool| (0..8).fold(0, |m, i| m | ((f(A[i], B[i]) as u32) << i));
        assert!(same((a + b).to_array(), want(|x, y| x + y)));
        assert!(same((a - b).to_array(), want(|x, y| x - y)));
        assert!(same((a * b).to_array(), want(|x, y| x * y)));
        assert!(same((a / b).to_array(), want(|x, y| x / y)));
        assert!(same((-a).to_array(), A.map(|x| -x)));
        assert!(same(a.abs().to_array(), A.map(f32::abs)));
        assert!(same(a.min(b).to_array(), want(|x, y| if x < y { x } else { y })));
        assert!(same(a.max(b).to_array(), want(|x, y| if x > y { x } else { y })));
        assert_eq!(a.is_nan().bits(), bits(|x, _| x.is_nan()));
        assert_eq!(a.eq(b).bits(), bits(|x, y| x == y));
        assert_eq!(a.lt(b).bits(), bits(|x, y| x < y));
        assert_eq!(a.le(b).bits(), bits(|x, y| x <= y));
        assert_eq!(a.gt(b).bits(), bits(|x, y| x > y));
        assert_eq!(a.ge(b).bits(), bits(|x, y| x >= y));
        let m = M32x8::from_bits(avx2, 0b0110_1001);
        let on = |i: usize| 0b0110_1001 & (1 << i) != 0;
        let chosen = std::array::from_fn(|i| if on(i) { A[i] } else { B[i] });
        assert!(same(F32x8::select(m, a, b).to_array(), chosen));
        assert!(same(
            a.keep(m).to_array(),
            std::array::from_fn(|i| if on(i) { A[i] } else { 0.0 })
        ));
        let index = I32x8::from_array(avx2, [7, 0, 3, 3, 9, 1, 6, 2]);
        let permuted = std::array::from_fn(|i| A[[7, 0, 3, 3, 1, 1, 6, 2][i]]);
        assert!(same(a.permute(index).to_array(), permuted));
        assert_eq!(
            F32x8::from_bits(a.to_bits()).to_bits().to_array(),
            A.map(|x| x.to_bits() as i32)
        );
        assert!(same(F32x8::zero(avx2).to_array(), [0.0; 8]));
        assert!(same(F32x8::splat(avx2, -2.5).to_array(), [-2.5; 8]));
        let low = F32x4::from_array(avx2, [1.0, 2.0, 3.0, 4.0]);
        let high = F32x4::from_array(avx2, [5.0, 6.0, 7.0, 8.0]);
        assert!(same(
            F32x8::from_halves(low, high).to_array(),
            [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]
        ));
        let wide = |v: [f32; 4]| v.map(|x| f64::from(x).to_bits());
        assert_eq!(a.low_f64().to_array().map(f64::to_bits), wide([A[0], A[1], A[2], A[3]]));
        assert_eq!(
            a.high_f64().to_array().map(f64::to_bits),
            wide([A[4], A[5], A[6], A[7]])
        );
    }

    #[test]
    fn rounding_matches_the_scalar_snap() {
        let Some(avx2) = Isa::detected().avx2() else {
            eprintln!("note: no AVX2 here; nothing to compare");
            return;
        };
        let v = [0.5, 1.5, 2.5, -0.5, -1.5, 3.7, -1e10, f32::NAN];
        let want = v.map(|x: f32| {
            if x.is_nan() || x.abs() >= 2147483648.0 {
                i32::MIN
            } else {
                x.round_ties_even() as i32
            }
        });
        assert_eq!(F32x8::from_array(avx2, v).round_to_i32().to_array(), want);
    }

    #[test]
    fn loads_and_gathers_pick_the_right_floats() {
        let Some(avx2) = Isa::detected().avx2() else {
            eprintln!("note: no AVX2 here; nothing to compare");
            return;
        };
        let p: [[f32; 3]; 8] = std::array::from_fn(|k| std::array::from_fn(|a| (10 * k + a) as f32));
        for (a, lanes) in F32x8::deinterleave3(avx2, &p).iter().enumerate() {
            assert_eq!(lanes.to_array(), std::array::from_fn(|k| p[k][a]));
        }
        let floats: Vec<f32> = (0..64).map(|i| i as f32 * 0.5).collect();
        let offsets = [3, 60, 0, 17, 1000, 8, 63, -5];
        // Lanes 4 and 7 would read outside: they are off.
        let on = 0b0110_1111;
        // SAFETY: every set lane's offset lies inside `floats`.
        let got = unsafe {
            F32x8::gather_masked(
                avx2,
                floats.as_ptr(),
                I32x8::from_array(avx2, offsets),
                M32x8::from_bits(avx2, on),
            )
        };
        let want = std::array::from_fn(|i| {
            if on & (1 << i) != 0 {
                floats[offsets[i] as usize]
            } else {
                0.0
            }
        });
        assert!(same(got.to_array(), want));
    }

    /// Masked loads and stores touch the set lanes only (the others may lie outside memory
    /// held, as at a span's end); the conversion rounds as `as f32` does.
    #[test]
    fn masked_loads_and_stores_touch_the_set_lanes_only() {
        let Some(avx2) = Isa::detected().avx2() else {
            eprintln!("note: no AVX2 here; nothing to compare");
            return;
        };
        let on = 0b0000_0111;
        let m = M32x8::from_bits(avx2, on);
        let held = [1.5f32, -2.0, 3.25];
        // SAFETY: the three set lanes read `held`.
        let got = unsafe { F32x8::load_masked(avx2, held.as_ptr(), m) };
        assert!(same(got.to_array(), [1.5, -2.0, 3.25, 0.0, 0.0, 0.0, 0.0, 0.0]));
        let mut whole = [0.0f32; 8];
        F32x8::from_array(avx2, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]).store(&mut whole);
        assert!(same(
            F32x8::load(avx2, &whole).to_array(),
            [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]
        ));
        let mut out = [9.0f32; 3];
        // SAFETY: the three set lanes write `out`.
        unsafe { F32x8::splat(avx2, 4.0).store_masked(out.as_mut_ptr(), m) };
        assert_eq!(out, [4.0; 3]);
        let mut items = [7u64; 8];
        // SAFETY: every lane lies in `items`.
        unsafe { M32x8::from_bits(avx2, 0b1001_0010).store_u64(items.as_mut_ptr(), u64::MAX - 1) };
        let want: [u64; 8] = std::array::from_fn(|i| if 0b1001_0010 & (1 << i) != 0 { u64::MAX - 1 } else { 7 });
        assert_eq!(items, want);
        let ints = [0, -1, 16_777_217, i32::MAX, i32::MIN, 3, -16_777_219, 12_345];
        assert!(same(
            I32x8::from_array(avx2, ints).to_f32().to_array(),
            ints.map(|i| i as f32)
        ));
    }
}
