//! The one SIMD module: the instruction set, detected once; the macro that compiles a kernel
//! once per instruction set and dispatches to it; and safe lane types.
//!
//! - [`Isa`] names an instruction-set level. A level above [`Isa::Baseline`] can only be had
//!   from [`Isa::detected`] (or [`Isa::available`]), which found every feature of that level on
//!   this processor; the detection runs once per process and is cached.
//! - [`isa_dispatch!`](crate::isa_dispatch) writes, for a kernel, a function that takes an
//!   [`Isa`] and runs the kernel compiled with `#[target_feature]` for the widest level the
//!   [`Isa`] reaches among those listed (the scalar kernel otherwise). The same Rust code is
//!   compiled for each level, and Rust never contracts floating-point operations, so every
//!   level gives the bits of the scalar one; callers' tests hold them to that.
//! - The lane types hold lanes in one register: [`I32x8`], [`F32x8`], [`F64x4`] and
//!   [`F32x4`], with the masks their comparisons give ([`M32x8`], [`M64x4`], [`M32x4`]). Each
//!   value is made (directly or from another lane value) with an [`Avx2`] token, which proves
//!   the processor has AVX2, so that their operations are safe. Each operation is one
//!   instruction (or a short fixed sequence, as its doc says), and each type's tests hold it
//!   to the scalar arithmetic it stands for, bit for bit.
//!
//! A kernel that wants the instructions of a level must be `#[inline(always)]` (or small
//! enough to be inlined) into the `#[target_feature]` wrapper the macro writes: it is the
//! wrapper that is compiled for the level. The lane operations are `#[inline(always)]` for the
//! same reason: inside such a kernel each becomes its instruction; outside one (in a test, say)
//! they still compute the same lanes, through calls.

#[cfg(target_arch = "x86_64")]
mod f32x4;
#[cfg(target_arch = "x86_64")]
mod f32x8;
#[cfg(target_arch = "x86_64")]
mod f64x4;
#[cfg(target_arch = "x86_64")]
mod i32x8;
#[cfg(target_arch = "x86_64")]
mod mask;

#[cfg(target_arch = "x86_64")]
pub use f32x4::F32x4;
#[cfg(target_arch = "x86_64")]
pub use f32x8::F32x8;
#[cfg(target_arch = "x86_64")]
pub use f64x4::F64x4;
#[cfg(target_arch = "x86_64")]
pub use i32x8::I32x8;
#[cfg(target_arch = "x86_64")]
pub use mask::{M32x4, M32x8, M64x4};
use std::sync::OnceLock;

/// An instruction-set level of the hot loops, ordered from narrowest to widest.
///
/// The levels above [`Isa::Baseline`] cannot be built outside this crate: a value of them
/// proves that the processor has every feature of the level (see [`Isa::detected`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Isa {
    /// Whatever the compilation target guarantees (SSE2 on x86-64).
    Baseline,
    /// AVX2 with BMI1, BMI2, LZCNT and POPCNT (every AVX2 processor has them).
    #[cfg(target_arch = "x86_64")]
    #[non_exhaustive]
    Avx2,
    /// AVX-512 F, BW and CD, on top of [`Isa::Avx2`].
    #[cfg(target_arch = "x86_64")]
    #[non_exhaustive]
    Avx512,
}

impl Isa {
    /// The widest level this processor has, detected on the first call and cached.
    pub fn detected() -> Self {
        static DETECTED: OnceLock<Isa> = OnceLock::new();
        *DETECTED.get_or_init(Self::detect)
    }

    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            let avx2 = is_x86_feature_detected!("avx2")
                && is_x86_feature_detected!("bmi1")
                && is_x86_feature_detected!("bmi2")
                && is_x86_feature_detected!("lzcnt")
                && is_x86_feature_detected!("popcnt");
            if avx2
                && is_x86_feature_detected!("avx512f")
                && is_x86_feature_detected!("avx512bw")
                && is_x86_feature_detected!("avx512cd")
            {
                return Isa::Avx512;
            }
            if avx2 {
                return Isa::Avx2;
            }
        }
        Isa::Baseline
    }

    /// [`Isa::detected`] when `simd` is true, [`Isa::Baseline`] when it is false (a switch that
    /// forces the baseline path, as configurations offer).
    pub fn select(simd: bool) -> Self {
        if simd {
            Self::detected()
        } else {
            Isa::Baseline
        }
    }

    /// Every level this processor can run, narrowest first (for tests: each must give the
    /// baseline's results).
    pub fn available() -> Vec<Self> {
        let all = [
            Isa::Baseline,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512,
        ];
        let top = Self::detected();
        all.into_iter().filter(|&l| l <= top).collect()
    }

    /// Whether this level includes [`Isa::Avx2`]'s features.
    #[inline]
    pub fn has_avx2(self) -> bool {
        match self {
            Isa::Baseline => false,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 | Isa::Avx512 => true,
        }
    }

    /// Whether this level includes [`Isa::Avx512`]'s features.
    #[inline]
    pub fn has_avx512(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => true,
            _ => false,
        }
    }

    /// The token that AVX2 lane types need, where this level has AVX2.
    #[inline]
    pub fn avx2(self) -> Option<Avx2> {
        self.has_avx2().then_some(Avx2(()))
    }

    /// The level's name: `"baseline"`, `"avx2"` or `"avx512"`.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Baseline => "baseline",
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => "avx2",
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => "avx512",
        }
    }
}

/// Writes `fn NAME(isa: Isa, ARGS) -> RET` that runs a kernel compiled for the widest listed
/// level that `isa` reaches, else the baseline kernel.
///
/// ```
/// # use occult_core::{isa_dispatch, simd::Isa};
/// #[inline(always)]
/// fn sum(v: &[u32]) -> u32 {
///     v.iter().sum()
/// }
/// isa_dispatch! {
///     /// Sum of `v`, in the widest lanes the processor has.
///     fn dispatched_sum(v: &[u32]) -> u32;
///     baseline => sum,
///     avx512("avx512f,avx512bw") => sum,
///     avx2("avx2") => sum,
/// }
/// assert_eq!(dispatched_sum(Isa::detected(), &[1, 2, 3]), 6);
/// ```
///
/// Each listed level (`avx512` or `avx2`, widest first) gets its own
/// `#[target_feature(enable = FEATURES)]` wrapper around its kernel; `FEATURES` must be among
/// the level's (see [`Isa`]). Arguments are written as `name: Type`, and every entry ends with
/// a comma. A safe function takes safe kernels; an `unsafe fn` may take `unsafe` kernels and
/// forwards their contract (which must be the same for all of them) to its callers.
#[macro_export]
macro_rules! isa_dispatch {
    (
        $(#[$attr:meta])*
        $vis:vis fn $name:ident $args:tt -> $ret:ty;
        baseline => $base:expr,
        $($level:ident($features:literal) => $kernel:expr,)*
    ) => {
        $crate::isa_dispatch! { @fn [$(#[$attr])*] [$vis] [] $name $args $args $ret [$($level $features $kernel;)*] $base }
    };
    (
        $(#[$attr:meta])*
        $vis:vis unsafe fn $name:ident $args:tt -> $ret:ty;
        baseline => $base:expr,
        $($level:ident($features:literal) => $kernel:expr,)*
    ) => {
        $crate::isa_dispatch! { @fn [$(#[$attr])*] [$vis] [unsafe] $name $args $args $ret [$($level $features $kernel;)*] $base }
    };
    (@fn [$($attr:tt)*] [$vis:vis] [] $name:ident ($($arg:ident: $ty:ty),* $(,)?) $args:tt $ret:ty
        [$($level:ident $features:literal $kernel:expr;)*] $base:expr) => {
        $($attr)*
        #[inline]
        #[allow(clippy::too_many_arguments)]
        $vis fn $name(isa: $crate::simd::Isa, $($arg: $ty),*) -> $ret {
            $($crate::isa_dispatch! { @arm [] $level $features $kernel, isa, $args $ret })*
            $base($($arg),*)
        }
    };
    (@fn [$($attr:tt)*] [$vis:vis] [unsafe] $name:ident ($($arg:ident: $ty:ty),* $(,)?) $args:tt $ret:ty
        [$($level:ident $features:literal $kernel:expr;)*] $base:expr) => {
        $($attr)*
        #[inline]
        #[allow(clippy::too_many_arguments)]
        $vis unsafe fn $name(isa: $crate::simd::Isa, $($arg: $ty),*) -> $ret {
            $($crate::isa_dispatch! { @arm [unsafe] $level $features $kernel, isa, $args $ret })*
            // SAFETY: forwarded: the caller holds the kernel's contract.
            unsafe { $base($($arg),*) }
        }
    };
    (@arm $unsafe:tt avx2 $($rest:tt)*) => {
        $crate::isa_dispatch! { @wrap $unsafe has_avx2 $($rest)* }
    };
    (@arm $unsafe:tt avx512 $($rest:tt)*) => {
        $crate::isa_dispatch! { @wrap $unsafe has_avx512 $($rest)* }
    };
    (@wrap [] $has:ident $features:literal $kernel:expr, $isa:ident, ($($arg:ident: $ty:ty),* $(,)?) $ret:ty) => {
        #[cfg(target_arch = "x86_64")]
        if $isa.$has() {
            #[target_feature(enable = $features)]
            #[allow(clippy::too_many_arguments)]
            fn wrapper($($arg: $ty),*) -> $ret {
                $kernel($($arg),*)
            }
            // SAFETY: an `Isa` at this level exists only where every feature of the level was
            // detected (`Isa::detected`), and the wrapper's features are among them.
            return unsafe { wrapper($($arg),*) };
        }
    };
    (@wrap [unsafe] $has:ident $features:literal $kernel:expr, $isa:ident, ($($arg:ident: $ty:ty),* $(,)?) $ret:ty) => {
        #[cfg(target_arch = "x86_64")]
        if $isa.$has() {
            #[target_feature(enable = $features)]
            #[allow(clippy::too_many_arguments)]
            unsafe fn wrapper($($arg: $ty),*) -> $ret {
                // SAFETY: forwarded: the dispatcher's caller holds the kernel's contract.
                unsafe { $kernel($($arg),*) }
            }
            // SAFETY: as in the safe form (the features were detected), and the kernel's
            // contract is the dispatcher's caller's.
            return unsafe { wrapper($($arg),*) };
        }
    };
}

/// Proof that the processor has AVX2 (and the rest of [`Isa::Avx2`]): the token the AVX2 lane
/// types are made with. Obtained from [`Isa::avx2`], or unchecked inside code that only runs
/// at that level.
#[derive(Clone, Copy, Debug)]
pub struct Avx2(());

impl Avx2 {
    /// The token, unchecked.
    ///
    /// # Safety
    /// The processor must have AVX2: call this only in code that runs where an [`Isa`] of at
    /// least [`Isa::Avx2`] was obtained.
    #[inline(always)]
    pub unsafe fn new_unchecked() -> Self {
        Avx2(())
    }
}

/// Hints the processor to fetch the cache line holding `x` into every level of its caches;
/// never faults (whatever the address), never changes a result.
#[inline(always)]
pub fn prefetch<T>(x: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint: it reads nothing and never faults.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(x.cast::<i8>());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

/// `+ - * /` and unary `-` (a sign flip) for a float lane type `$t` wrapping one register:
/// each operator is the one instruction named.
#[cfg(target_arch = "x86_64")]
macro_rules! float_ops {
    ($t:ident: $add:ident, $sub:ident, $mul:ident, $div:ident, $xor:ident, $splat:ident) => {
        $crate::simd::float_ops!(@binary $t, Add, add, $add);
        $crate::simd::float_ops!(@binary $t, Sub, sub, $sub);
        $crate::simd::float_ops!(@binary $t, Mul, mul, $mul);
        $crate::simd::float_ops!(@binary $t, Div, div, $div);
        impl std::ops::Neg for $t {
            type Output = Self;
            #[inline(always)]
            fn neg(self) -> Self {
                // SAFETY: a lane value exists only where AVX2 was proven (its token).
                Self(unsafe { $xor(self.0, $splat(-0.0)) })
            }
        }
    };
    (@binary $t:ident, $trait:ident, $method:ident, $intrinsic:ident) => {
        impl std::ops::$trait for $t {
            type Output = Self;
            #[inline(always)]
            fn $method(self, o: Self) -> Self {
                // SAFETY: a lane value exists only where AVX2 was proven (its token).
                Self(unsafe { $intrinsic(self.0, o.0) })
            }
        }
    };
}
#[cfg(target_arch = "x86_64")]
use float_ops;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detection_is_cached_and_levels_nest() {
        let top = Isa::detected();
        assert_eq!(top, Isa::detected());
        assert_eq!(Isa::select(false), Isa::Baseline);
        assert_eq!(Isa::select(true), top);
        let all = Isa::available();
        assert_eq!(all.first(), Some(&Isa::Baseline));
        assert_eq!(all.last(), Some(&top));
        assert!(all.windows(2).all(|w| w[0] < w[1]));
        assert!(!Isa::Baseline.has_avx2() && !Isa::Baseline.has_avx512());
        assert!(top.has_avx2() || !top.has_avx512());
        assert_eq!(Isa::Baseline.name(), "baseline");
    }

    #[inline(always)]
    fn add_one(v: &mut [u32]) -> u32 {
        v.iter_mut().for_each(|x| *x += 1);
        v.len() as u32
    }

    crate::isa_dispatch! {
        /// `add_one` on every level.
        fn add_one_any(v: &mut [u32]) -> u32;
        baseline => add_one,
        avx512("avx512f,avx512bw") => add_one,
        avx2("avx2") => add_one,
    }

    #[test]
    fn every_level_runs_the_kernel() {
        for isa in Isa::available() {
            let mut v = vec![1u32; 37];
            assert_eq!(add_one_any(isa, &mut v), 37, "{isa:?}");
            assert!(v.iter().all(|&x| x == 2), "{isa:?}");
        }
    }
}
