//! [`F32x4`]: four `f32` lanes.

use super::{Avx2, M32x4};
use std::arch::x86_64::*;

/// Four `f32` lanes in one SSE register (made with an [`Avx2`] token like the wider types, so
/// that the two mix freely: see [`F32x8::from_halves`](super::F32x8::from_halves)). Arithmetic
/// as [`F32x8`](super::F32x8)'s: each lane the scalar operation's bits.
#[derive(Clone, Copy, Debug)]
pub struct F32x4(pub(super) __m128);

super::float_ops!(F32x4: _mm_add_ps, _mm_sub_ps, _mm_mul_ps, _mm_div_ps, _mm_xor_ps, _mm_set1_ps);

impl F32x4 {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(_: Avx2, v: f32) -> Self {
        // SAFETY: the token proves AVX2, which includes SSE.
        Self(unsafe { _mm_set1_ps(v) })
    }

    /// Lane `i` is `v[i]`.
    #[inline(always)]
    pub fn from_array(_: Avx2, v: [f32; 4]) -> Self {
        // SAFETY: the token proves AVX2, which includes SSE.
        Self(unsafe { _mm_setr_ps(v[0], v[1], v[2], v[3]) })
    }

    /// Lane-wise `if m { t } else { f }`.
    #[inline(always)]
    pub fn select(m: M32x4, t: Self, f: Self) -> Self {
        // SAFETY: a lane value exists only where AVX2 was proven (its token), and AVX2
        // includes SSE4.1's blend.
        Self(unsafe { _mm_blendv_ps(f.0, t.0, _mm_castsi128_ps(m.0)) })
    }

    /// The lanes as an array.
    #[inline(always)]
    pub fn to_array(self) -> [f32; 4] {
        // SAFETY: `__m128` and `[f32; 4]` have the same size, and every bit pattern is valid
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
        let (x, y) = ([1.5f32, -0.0, 1e-40, 3.0e38], [0.1f32, 0.0, 3.0, 10.0]);
        let (a, b) = (F32x4::from_array(avx2, x), F32x4::from_array(avx2, y));
        let want = |f: fn(f32, f32) -> f32| std::array::from_fn::<u32, 4, _>(|i| f(x[i], y[i]).to_bits());
        let bits = |v: F32x4| v.to_array().map(f32::to_bits);
        assert_eq!(bits(a + b), want(|p, q| p + q));
        assert_eq!(bits(a - b), want(|p, q| p - q));
        assert_eq!(bits(a * b), want(|p, q| p * q));
        assert_eq!(bits(a / b), want(|p, q| p / q));
        assert_eq!(bits(-a), x.map(|p| (-p).to_bits()));
        assert_eq!(bits(F32x4::splat(avx2, 0.5)), [0.5f32.to_bits(); 4]);
        let m = M32x4::from_bits(avx2, 0b0101);
        assert_eq!(bits(F32x4::select(m, a, b)), [x[0], y[1], x[2], y[3]].map(f32::to_bits));
    }
}
