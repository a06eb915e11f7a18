//! [`F64x4`]: four `f64` lanes.

use super::{Avx2, F32x4, M64x4};
use std::arch::x86_64::*;

/// Four `f64` lanes in one AVX2 register. Arithmetic as [`F32x8`](super::F32x8)'s: each lane
/// the scalar operation's bits.
#[derive(Clone, Copy, Debug)]
pub struct F64x4(pub(super) __m256d);

super::float_ops!(F64x4: _mm256_add_pd, _mm256_sub_pd, _mm256_mul_pd, _mm256_div_pd, _mm256_xor_pd, _mm256_set1_pd);

impl F64x4 {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(_: Avx2, v: f64) -> Self {
        // SAFETY: the token proves AVX2.
        Self(unsafe { _mm256_set1_pd(v) })
    }

    /// Every lane +0.0.
    #[inline(always)]
    pub fn zero(_: Avx2) -> Self {
        // SAFETY: the token proves AVX2.
        Self(unsafe { _mm256_setzero_pd() })
    }

    /// Lane `i` is `v[i]`.
    #[inline(always)]
    pub fn from_array(_: Avx2, v: [f64; 4]) -> Self {
        // SAFETY: the token proves AVX2.
        Self(unsafe { _mm256_setr_pd(v[0], v[1], v[2], v[3]) })
    }

    /// Lane-wise absolute value (the sign bit cleared).
    #[inline(always)]
    pub fn abs(self) -> Self {
        // SAFETY: a lane value exists only where AVX2 was proven (its token).
        Self(unsafe { _mm256_andnot_pd(_mm256_set1_pd(-0.0), self.0) })
    }

    /// Lane-wise `<` (false where either is NaN).
    #[inline(always)]
    pub fn lt(self, o: Self) -> M64x4 {
        // SAFETY: as in `abs`.
        M64x4(unsafe { _mm256_cmp_pd::<_CMP_LT_OQ>(self.0, o.0) })
    }

    /// Lane-wise `>` (false where either is NaN).
    #[inline(always)]
    pub fn gt(self, o: Self) -> M64x4 {
        // SAFETY: as in `abs`.
        M64x4(unsafe { _mm256_cmp_pd::<_CMP_GT_OQ>(self.0, o.0) })
    }

    /// Lane-wise `if self < o { self } else { o }`: the instruction's rule, which gives `o`
    /// where either is NaN or both are zero (as [`F32x8::min`](super::F32x8::min)).
    #[inline(always)]
    pub fn min(self, o: Self) -> Self {
        // SAFETY: as in `abs`.
        Self(unsafe { _mm256_min_pd(self.0, o.0) })
    }

    /// Lane-wise `if self > o { self } else { o }` (the rule of [`F64x4::min`]).
    #[inline(always)]
    pub fn max(self, o: Self) -> Self {
        // SAFETY: as in `abs`.
        Self(unsafe { _mm256_max_pd(self.0, o.0) })
    }

    /// Lane-wise `as f32` (rounded to nearest, ties to even, in the default rounding mode).
    #[inline(always)]
    pub fn to_f32(self) -> F32x4 {
        // SAFETY: as in `abs`.
        F32x4(unsafe { _mm256_cvtpd_ps(self.0) })
    }

    /// The lanes as an array.
    #[inline(always)]
    pub fn to_array(self) -> [f64; 4] {
        // SAFETY: `__m256d` and `[f64; 4]` have the same size, and every bit pattern is valid
        // for both.
        unsafe { std::mem::transmute(self.0) }
    }
}

#[cfg(test)]
mod tests {
    use super::super::Isa;
    use super::*;

    #[test]
    fn lanes_match_scalar_arithmetic() {
        let Some(avx2) = Isa::detected().avx2() else {
            eprintln!("note: no AVX2 here; nothing to compare");
            return;
        };
        let (x, y) = ([1.5, -0.0, f64::NAN, 1e300], [0.1, 0.0, 2.0, -1e-300]);
        let (a, b) = (F64x4::from_array(avx2, x), F64x4::from_array(avx2, y));
        // Bits, NaNs as one (a NaN's sign and payload depend on whether the compiler folded
        // the scalar operation).
        let key = |p: f64| if p.is_nan() { f64::NAN.to_bits() } else { p.to_bits() };
        let want = |f: fn(f64, f64) -> f64| std::array::from_fn::<u64, 4, _>(|i| key(f(x[i], y[i])));
        let bits = |v: F64x4| v.to_array().map(key);
        let flags = |f: fn(f64, f64) -> bool| (0..4).fold(0, |m, i| m | ((f(x[i], y[i]) as u32) << i));
        assert_eq!(bits(a + b), want(|p, q| p + q));
        assert_eq!(bits(a - b), want(|p, q| p - q));
        assert_eq!(bits(a * b), want(|p, q| p * q));
        assert_eq!(bits(a / b), want(|p, q| p / q));
        assert_eq!(bits(-a), x.map(|p| key(-p)));
        assert_eq!(bits(a.abs()), x.map(|p| key(p.abs())));
        assert_eq!(bits(a.min(b)), want(|p, q| if p < q { p } else { q }));
        assert_eq!(bits(a.max(b)), want(|p, q| if p > q { p } else { q }));
        // The other way round: `o` wherever either is NaN or both are zero.
        let flip = |f: fn(f64, f64) -> f64| std::array::from_fn::<u64, 4, _>(|i| key(f(y[i], x[i])));
        assert_eq!(bits(b.min(a)), flip(|p, q| if p < q { p } else { q }));
        assert_eq!(bits(b.max(a)), flip(|p, q| if p > q { p } else { q }));
        assert_eq!(a.lt(b).bits(), flags(|p, q| p < q));
        assert_eq!(a.gt(b).bits(), flags(|p, q| p > q));
        let narrow = |p: f32| if p.is_nan() { f32::NAN.to_bits() } else { p.to_bits() };
        assert_eq!(a.to_f32().to_array().map(narrow), x.map(|p| narrow(p as f32)));
        assert_eq!(bits(F64x4::zero(avx2)), [0; 4]);
        assert_eq!(bits(F64x4::splat(avx2, 0.5)), [0.5f64.to_bits(); 4]);
    }
}
