//! Lane masks: the results of lane comparisons, every lane all ones (true) or all zeros
//! (false), as the comparison instructions write them.

use super::Avx2;
use std::arch::x86_64::*;

/// Eight 32-bit lane flags in one AVX2 register (each lane all ones or all zeros): what the
/// comparisons of [`I32x8`](super::I32x8) and [`F32x8`](super::F32x8) return, and what their
/// `select` and `keep` take.
#[derive(Clone, Copy, Debug)]
pub struct M32x8(pub(super) __m256i);

impl M32x8 {
    /// Lane `i` set where bit `i` of `bits` is (bits from 8 up are ignored).
    #[inline(always)]
    pub fn from_bits(_: Avx2, bits: u32) -> Self {
        // SAFETY: the token proves AVX2.
        unsafe {
            let lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            Self(_mm256_cmpeq_epi32(
                _mm256_and_si256(_mm256_set1_epi32(bits as i32), lane_bit),
                lane_bit,
            ))
        }
    }

    /// Lane `i` at bit `i` (the sign bit of each lane).
    #[inline(always)]
    pub fn bits(self) -> u32 {
        // SAFETY: a lane value exists only where AVX2 was proven (its token).
        unsafe { _mm256_movemask_ps(_mm256_castsi256_ps(self.0)) as u32 }
    }

    /// Set where both are.
    #[inline(always)]
    pub fn and(self, o: Self) -> Self {
        Self(self.to_i32x8().and(o.to_i32x8()).0)
    }

    /// Set where either is.
    #[inline(always)]
    pub fn or(self, o: Self) -> Self {
        Self(self.to_i32x8().or(o.to_i32x8()).0)
    }

    /// Set where `self` is and `o` is not (one `andnot` instruction).
    #[inline(always)]
    pub fn and_not(self, o: Self) -> Self {
        Self(self.to_i32x8().and_not(o.to_i32x8()).0)
    }

    /// Writes `v` to `*dst.add(i)` for every lane `i` set, nothing elsewhere (two masked
    /// stores of four 64-bit lanes).
    ///
    /// # Safety
    /// `dst.add(i)` must be valid for writes for every lane `i` set.
    #[inline(always)]
    pub unsafe fn store_u64(self, dst: *mut u64, v: u64) {
        // SAFETY: a lane value exists only where AVX2 was proven (its token); the caller
        // vouches for the lanes written. Each 32-bit flag widened by sign extension is the
        // 64-bit lane's flag.
        unsafe {
            let value = _mm256_set1_epi64x(v as i64);
            let low = _mm256_cvtepi32_epi64(_mm256_castsi256_si128(self.0));
            let high = _mm256_cvtepi32_epi64(_mm256_extracti128_si256::<1>(self.0));
            _mm256_maskstore_epi64(dst.cast(), low, value);
            _mm256_maskstore_epi64(dst.add(4).cast(), high, value);
        }
    }

    /// The flags as integers: -1 where set, 0 elsewhere (no instruction).
    #[inline(always)]
    pub fn to_i32x8(self) -> super::I32x8 {
        super::I32x8(self.0)
    }
}

/// Set where `self` is not (an exclusive or with all ones).
impl std::ops::Not for M32x8 {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        // SAFETY: a lane value exists only where AVX2 was proven (its token).
        Self(unsafe { _mm256_xor_si256(self.0, _mm256_set1_epi32(-1)) })
    }
}

/// Four 32-bit lane flags in one SSE register (each lane all ones or all zeros).
#[derive(Clone, Copy, Debug)]
pub struct M32x4(pub(super) __m128i);

impl M32x4 {
    /// Lane `i` set where bit `i` of `bits` is (bits from 4 up are ignored).
    #[inline(always)]
    pub fn from_bits(_: Avx2, bits: u32) -> Self {
        // SAFETY: the token proves AVX2, which includes SSE2.
        unsafe {
            let lane_bit = _mm_setr_epi32(1, 2, 4, 8);
            Self(_mm_cmpeq_epi32(
                _mm_and_si128(_mm_set1_epi32(bits as i32), lane_bit),
                lane_bit,
            ))
        }
    }

    /// Lane `i` at bit `i` (the sign bit of each lane).
    #[inline(always)]
    pub fn bits(self) -> u32 {
        // SAFETY: a lane value exists only where AVX2 was proven (its token).
        unsafe { _mm_movemask_ps(_mm_castsi128_ps(self.0)) as u32 }
    }
}

/// Four 64-bit lane flags in one AVX2 register: what the comparisons of
/// [`F64x4`](super::F64x4) return.
#[derive(Clone, Copy, Debug)]
pub struct M64x4(pub(super) __m256d);

impl M64x4 {
    /// Lane `i` at bit `i` (the sign bit of each lane).
    #[inline(always)]
    pub fn bits(self) -> u32 {
        // SAFETY: a lane value exists only where AVX2 was proven (its token).
        unsafe { _mm256_movemask_pd(self.0) as u32 }
    }
}

#[cfg(test)]
mod tests {
    use super::super::Isa;
    use super::*;

    #[test]
    fn masks_match_scalar_logic() {
        let Some(avx2) = Isa::detected().avx2() else {
            eprintln!("note: no AVX2 here; nothing to compare");
            return;
        };
        for (a, b) in [(0u32, 0u32), (0xff, 0x0f), (0xa5, 0x3c), (0x1_23, 0xf0)] {
            let (ma, mb) = (M32x8::from_bits(avx2, a), M32x8::from_bits(avx2, b));
            let (a, b) = (a & 0xff, b & 0xff);
            assert_eq!(ma.bits(), a);
            assert_eq!(ma.and(mb).bits(), a & b);
            assert_eq!(ma.or(mb).bits(), a | b);
            assert_eq!(ma.and_not(mb).bits(), a & !b);
            assert_eq!((!ma).bits(), !a & 0xff);
            let ints = ma.to_i32x8().to_array();
            assert!((0..8).all(|i| ints[i] == if a & (1 << i) != 0 { -1 } else { 0 }));
            assert_eq!(M32x4::from_bits(avx2, a).bits(), a & 0xf);
        }
    }
}
