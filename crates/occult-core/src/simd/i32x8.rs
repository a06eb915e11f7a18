//! [`I32x8`]: eight `i32` lanes.

use super::{Avx2, F32x8, F64x4, M32x8};
use std::arch::x86_64::*;

/// Eight `i32` lanes in one AVX2 register. Every operation is one AVX2 instruction (or the
/// short fixed sequence its doc names), inlined into the caller (which should itself be
/// compiled for AVX2, e.g. a kernel of [`isa_dispatch!`](crate::isa_dispatch), for the
/// instructions to be inlined too). Arithmetic wraps, as the instructions do.
#[derive(Clone, Copy, Debug)]
pub struct I32x8(pub(super) __m256i);

impl I32x8 {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(_: Avx2, v: i32) -> Self {
        // SAFETY: the token proves AVX2.
        Self(unsafe { _mm256_set1_epi32(v) })
    }

    /// Every lane 0.
    #[inline(always)]
    pub fn zero(_: Avx2) -> Self {
        // SAFETY: the token proves AVX2.
        Self(unsafe { _mm256_setzero_si256() })
    }

    /// Lane `i` is `v[i]`.
    #[inline(always)]
    pub fn from_array(_: Avx2, v: [i32; 8]) -> Self {
        // SAFETY: the token proves AVX2.
        Self(unsafe { _mm256_setr_epi32(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7]) })
    }

    /// Lanes `0, 1, …, 7`.
    #[inline(always)]
    pub fn lane_index(avx2: Avx2) -> Self {
        Self::from_array(avx2, [0, 1, 2, 3, 4, 5, 6, 7])
    }

    /// Column `c` of eight 4-lane rows: lane `k` of result `c` is `rows[k][c]` (two 16-byte
    /// loads per register and a 4 × 4 transpose in each 128-bit half).
    #[inline(always)]
    pub fn from_rows(_: Avx2, rows: &[[i32; 4]; 8]) -> [Self; 4] {
        // SAFETY: the token proves AVX2; each load reads one row, 16 bytes inside `rows`
        // (unaligned loads are allowed).
        unsafe {
            let load = |k: usize| _mm_loadu_si128(rows[k].as_ptr().cast());
            let pair = |a: usize, b: usize| _mm256_inserti128_si256::<1>(_mm256_castsi128_si256(load(a)), load(b));
            let (t0, t1, t2, t3) = (pair(0, 4), pair(1, 5), pair(2, 6), pair(3, 7));
            let (u0, u1) = (_mm256_unpacklo_epi32(t0, t1), _mm256_unpackhi_epi32(t0, t1));
            let (u2, u3) = (_mm256_unpacklo_epi32(t2, t3), _mm256_unpackhi_epi32(t2, t3));
            [
                Self(_mm256_unpacklo_epi64(u0, u2)),
                Self(_mm256_unpackhi_epi64(u0, u2)),
                Self(_mm256_unpacklo_epi64(u1, u3)),
                Self(_mm256_unpackhi_epi64(u1, u3)),
            ]
        }
    }

    /// The inverse of [`I32x8::from_rows`]: `rows[k][c]` becomes lane `k` of `columns[c]`
    /// (a 4 × 4 transpose in each 128-bit half and four 32-byte stores).
    #[inline(always)]
    pub fn to_rows(columns: [Self; 4], rows: &mut [[i32; 4]; 8]) {
        let [Self(a), Self(b), Self(c), Self(d)] = columns;
        // SAFETY: a lane value exists only where AVX2 was proven (its token); each store
        // writes two rows, 32 bytes inside `rows` (unaligned stores are allowed).
        unsafe {
            let (t0, t1) = (_mm256_unpacklo_epi32(a, b), _mm256_unpackhi_epi32(a, b));
            let (t2, t3) = (_mm256_unpacklo_epi32(c, d), _mm256_unpackhi_epi32(c, d));
            let (v0, v1) = (_mm256_unpacklo_epi64(t0, t2), _mm256_unpackhi_epi64(t0, t2));
            let (v2, v3) = (_mm256_unpacklo_epi64(t1, t3), _mm256_unpackhi_epi64(t1, t3));
            let dst: *mut __m256i = rows.as_mut_ptr().cast();
            _mm256_storeu_si256(dst, _mm256_permute2x128_si256::<0x20>(v0, v1));
            _mm256_storeu_si256(dst.add(1), _mm256_permute2x128_si256::<0x20>(v2, v3));
            _mm256_storeu_si256(dst.add(2), _mm256_permute2x128_si256::<0x31>(v0, v1));
            _mm256_storeu_si256(dst.add(3), _mm256_permute2x128_si256::<0x31>(v2, v3));
        }
    }

    /// Lane-wise wrapping sum.
    #[inline(always)]
    pub fn wrapping_add(self, o: Self) -> Self {
        // SAFETY: a lane value exists only where AVX2 was proven (its token).
        Self(unsafe { _mm256_add_epi32(self.0, o.0) })
    }

    /// Lane-wise wrapping difference.
    #[inline(always)]
    pub fn wrapping_sub(self, o: Self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_sub_epi32(self.0, o.0) })
    }

    /// Lane-wise wrapping product (the low 32 bits).
    #[inline(always)]
    pub fn wrapping_mul(self, o: Self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_mullo_epi32(self.0, o.0) })
    }

    /// Lane-wise minimum.
    #[inline(always)]
    pub fn min(self, o: Self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_min_epi32(self.0, o.0) })
    }

    /// Lane-wise maximum.
    #[inline(always)]
    pub fn max(self, o: Self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_max_epi32(self.0, o.0) })
    }

    /// Lane-wise minimum of the lanes read as `u32`.
    #[inline(always)]
    pub fn min_u32(self, o: Self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_min_epu32(self.0, o.0) })
    }

    /// The least lane read as `u32` (three minima over lane permutations and an extract).
    #[inline(always)]
    pub fn reduce_min_u32(self) -> u32 {
        // SAFETY: as in `wrapping_add`.
        self.reduce(|a, b| unsafe { _mm256_min_epu32(a, b) }) as u32
    }

    /// The greatest lane (three maxima over lane permutations and an extract).
    #[inline(always)]
    pub fn reduce_max(self) -> i32 {
        // SAFETY: as in `wrapping_add`.
        self.reduce(|a, b| unsafe { _mm256_max_epi32(a, b) })
    }

    /// `op` (associative and commutative) over the eight lanes: three steps, each combining
    /// every lane with another (halves, pairs, neighbours swapped), then lane 0.
    #[inline(always)]
    fn reduce(self, op: impl Fn(__m256i, __m256i) -> __m256i) -> i32 {
        // SAFETY: as in `wrapping_add`.
        unsafe {
            let v = op(self.0, _mm256_permute2x128_si256::<0x01>(self.0, self.0));
            let v = op(v, _mm256_shuffle_epi32::<0b01_00_11_10>(v));
            _mm256_extract_epi32::<0>(op(v, _mm256_shuffle_epi32::<0b10_11_00_01>(v)))
        }
    }

    /// Lane-wise bitwise and.
    #[inline(always)]
    pub fn and(self, o: Self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_and_si256(self.0, o.0) })
    }

    /// Lane-wise bitwise or.
    #[inline(always)]
    pub fn or(self, o: Self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_or_si256(self.0, o.0) })
    }

    /// Lane-wise `self & !o` (one `andnot` instruction).
    #[inline(always)]
    pub fn and_not(self, o: Self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_andnot_si256(o.0, self.0) })
    }

    /// The lanes where `m` is set, 0 in the others (a bitwise and).
    #[inline(always)]
    pub fn keep(self, m: M32x8) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_and_si256(self.0, m.0) })
    }

    /// Lane-wise `if m { t } else { f }` (a byte blend: the mask's lanes are whole).
    #[inline(always)]
    pub fn select(m: M32x8, t: Self, f: Self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_blendv_epi8(f.0, t.0, m.0) })
    }

    /// Lane-wise `>> N`, arithmetic (sign-filling, as on `i32`); `N` in `0..32`.
    #[inline(always)]
    pub fn shr<const N: i32>(self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_srai_epi32::<N>(self.0) })
    }

    /// Lane-wise `<< N`; `N` in `0..32`.
    #[inline(always)]
    pub fn shl<const N: i32>(self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_slli_epi32::<N>(self.0) })
    }

    /// Lane-wise `self << n` with the count of each lane read as `u32`; counts of 32 and more
    /// give 0 (unlike `i32::wrapping_shl`).
    #[inline(always)]
    pub fn shl_var(self, n: Self) -> Self {
        // SAFETY: as in `wrapping_add`.
        Self(unsafe { _mm256_sllv_epi32(self.0, n.0) })
    }

    /// Lane-wise `==`.
    #[inline(always)]
    pub fn eq(self, o: Self) -> M32x8 {
        // SAFETY: as in `wrapping_add`.
        M32x8(unsafe { _mm256_cmpeq_epi32(self.0, o.0) })
    }

    /// Lane-wise `>`.
    #[inline(always)]
    pub fn gt(self, o: Self) -> M32x8 {
        // SAFETY: as in `wrapping_add`.
        M32x8(unsafe { _mm256_cmpgt_epi32(self.0, o.0) })
    }

    /// Lane-wise `<` (`o > self`).
    #[inline(always)]
    pub fn lt(self, o: Self) -> M32x8 {
        o.gt(self)
    }

    /// The sign bit of each lane, lane `i` at bit `i`.
    #[inline(always)]
    pub fn sign_mask(self) -> u32 {
        // SAFETY: as in `wrapping_add`.
        unsafe { _mm256_movemask_ps(_mm256_castsi256_ps(self.0)) as u32 }
    }

    /// Lanes 0..4 as `f64` (exact).
    #[inline(always)]
    pub fn low_f64(self) -> F64x4 {
        // SAFETY: as in `wrapping_add`.
        F64x4(unsafe { _mm256_cvtepi32_pd(_mm256_castsi256_si128(self.0)) })
    }

    /// Lanes 4..8 as `f64` (exact).
    #[inline(always)]
    pub fn high_f64(self) -> F64x4 {
        // SAFETY: as in `wrapping_add`.
        F64x4(unsafe { _mm256_cvtepi32_pd(_mm256_extracti128_si256::<1>(self.0)) })
    }

    /// Lane-wise conversion to `f32`, rounding to nearest as `i32 as f32` does (exact below
    /// 2^24 in magnitude).
    #[inline(always)]
    pub fn to_f32(self) -> F32x8 {
        // SAFETY: as in `wrapping_add`.
        F32x8(unsafe { _mm256_cvtepi32_ps(self.0) })
    }

    /// The lanes' bits as `f32` lanes (no instruction; see [`F32x8::to_bits`]).
    #[inline(always)]
    pub fn to_f32_bits(self) -> F32x8 {
        F32x8::from_bits(self)
    }

    /// The lanes as an array.
    #[inline(always)]
    pub fn to_array(self) -> [i32; 8] {
        // SAFETY: `__m256i` and `[i32; 8]` have the same size, and every bit pattern is valid
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
        let a = [i32::MAX, -1, 0, 7, i32::MIN, 3, -9, 100];
        let b = [2, 3, -4, 5, 6, -7, 8, 9];
        let (la, lb) = (I32x8::from_array(avx2, a), I32x8::from_array(avx2, b));
        let want = |f: fn(i32, i32) -> i32| std::array::from_fn::<i32, 8, _>(|i| f(a[i], b[i]));
        let bits = |f: fn(i32, i32) -> bool| (0..8).fold(0, |m, i| m | ((f(a[i], b[i]) as u32) << i));
        assert_eq!(la.wrapping_add(lb).to_array(), want(i32::wrapping_add));
        assert_eq!(la.wrapping_sub(lb).to_array(), want(i32::wrapping_sub));
        assert_eq!(la.wrapping_mul(lb).to_array(), want(i32::wrapping_mul));
        assert_eq!(la.min(lb).to_array(), want(i32::min));
        assert_eq!(la.max(lb).to_array(), want(i32::max));
        assert_eq!(la.min_u32(lb).to_array(), want(|x, y| (x as u32).min(y as u32) as i32));
        assert_eq!(la.and(lb).to_array(), want(|x, y| x & y));
        assert_eq!(la.or(lb).to_array(), want(|x, y| x | y));
        assert_eq!(la.and_not(lb).to_array(), want(|x, y| x & !y));
        assert_eq!(la.shr::<3>().to_array(), a.map(|x| x >> 3));
        assert_eq!(la.shl::<8>().to_array(), a.map(|x| x << 8));
        let counts = [0, 1, 31, 32, 40, 5, -1, 8];
        let shifted = la.shl_var(I32x8::from_array(avx2, counts)).to_array();
        assert_eq!(
            shifted,
            std::array::from_fn(|i| (a[i] as u32).checked_shl(counts[i] as u32).unwrap_or(0) as i32)
        );
        assert_eq!(la.eq(lb).bits(), bits(|x, y| x == y));
        assert_eq!(la.eq(la).bits(), 0xff);
        assert_eq!(la.gt(lb).bits(), bits(|x, y| x > y));
        assert_eq!(la.lt(lb).bits(), bits(|x, y| x < y));
        let signs = (0..8).fold(0, |m, i| m | (((a[i] < 0) as u32) << i));
        assert_eq!(la.sign_mask(), signs);
        let m = M32x8::from_bits(avx2, 0b1010_0110);
        let on = |i: usize| 0b1010_0110 & (1 << i) != 0;
        assert_eq!(
            la.keep(m).to_array(),
            std::array::from_fn(|i| if on(i) { a[i] } else { 0 })
        );
        assert_eq!(
            I32x8::select(m, la, lb).to_array(),
            std::array::from_fn(|i| if on(i) { a[i] } else { b[i] })
        );
        assert_eq!(
            la.reduce_min_u32(),
            a.iter().map(|&x| x as u32).min().expect("eight lanes are not empty")
        );
        assert_eq!(la.reduce_max(), i32::MAX);
        assert_eq!(lb.reduce_max(), 9);
        assert_eq!(la.low_f64().to_array(), [a[0], a[1], a[2], a[3]].map(f64::from));
        assert_eq!(la.high_f64().to_array(), [a[4], a[5], a[6], a[7]].map(f64::from));
        assert_eq!(la.to_f32_bits().to_bits().to_array(), a);
        assert_eq!(I32x8::splat(avx2, -3).to_array(), [-3; 8]);
        assert_eq!(I32x8::zero(avx2).to_array(), [0; 8]);
        assert_eq!(I32x8::lane_index(avx2).to_array(), [0, 1, 2, 3, 4, 5, 6, 7]);
    }

    #[test]
    fn rows_transpose_both_ways() {
        let Some(avx2) = Isa::detected().avx2() else {
            eprintln!("note: no AVX2 here; nothing to compare");
            return;
        };
        let rows: [[i32; 4]; 8] = std::array::from_fn(|k| std::array::from_fn(|c| 10 * k as i32 + c as i32));
        let columns = I32x8::from_rows(avx2, &rows);
        for (c, column) in columns.iter().enumerate() {
            assert_eq!(column.to_array(), std::array::from_fn(|k| rows[k][c]));
        }
        let mut back = [[0; 4]; 8];
        I32x8::to_rows(columns, &mut back);
        assert_eq!(back, rows);
    }
}
