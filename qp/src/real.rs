//! The scalar type of the planning and control maths.
//!
//! The ECU computes in `f32` (the Cortex-M4F FPU is single precision; `f64` there
//! is software-emulated and an order of magnitude slower). The host can run the
//! same code in `f64` to measure what single precision costs in accuracy. The QP solver
//! here and every algorithm of `firmware` are generic over [`Real`].
//!
//! Transcendental functions are deterministic, bit-identical on every target, and
//! in single precision they never touch `f64`: `libm`'s `sinf`, `cosf`, `tanf`,
//! `asinf` and `hypotf` evaluate their kernels in `f64`, which the M4F emulates in
//! software (about 1,200 instructions per `sinf`, and it links `__aeabi_d*`). For
//! `f32` those five are computed here, in `f32` only ([`f32_math`]: Cody–Waite range
//! reduction and the Cephes single-precision minimax polynomials, within 2·10⁻⁷ of
//! the exact value for `|x| ≤ 8192`); `atanf` and `atan2f` come from `libm`, which
//! computes them in `f32`; `floor` is `libm::floorf`'s result bit for bit from the
//! FPU's conversion to an integer ([`f32_math::floor`]). `f64` uses `libm`
//! throughout.
//!
//! The square root is IEEE 754's correctly rounded one on every target, so it is
//! bit-identical everywhere: on the Cortex-M4F it is the FPU's `VSQRT.F32` (one
//! instruction, 14 cycles; [`f32_math::sqrt`]), elsewhere `libm::sqrtf` (about 48
//! instructions of integer code on the M4F).

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// A floating-point scalar: `f32` on the ECU, `f32` or `f64` on the host.
///
/// Literals enter through [`Real::lit`] (exact for `f32` literals in both types).
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialEq
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
    + Send
    + Sync
    + 'static
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// 2.
    const TWO: Self;
    /// 0.5.
    const HALF: Self;
    /// π.
    const PI: Self;
    /// Machine epsilon (distance from 1 to the next representable value).
    const EPSILON: Self;
    /// +∞.
    const INFINITY: Self;
    /// −∞ (a const, for `const fn` initialisers where `-INFINITY` is not available).
    const NEG_INFINITY: Self;
    /// Largest finite value.
    const MAX: Self;
    /// Not a number (a const, for `const fn` initialisers: a value not measured).
    const NAN: Self;

    /// Converts an `f32` literal or value.
    fn lit(v: f32) -> Self;
    /// Converts from `f64` (rounds to nearest for `f32`).
    fn from_f64(v: f64) -> Self;
    /// Converts to `f64` (exact).
    fn to_f64(self) -> f64;
    /// Converts to `f32` (rounds to nearest for `f64`).
    fn to_f32(self) -> f32;
    /// Converts a count.
    fn from_usize(n: usize) -> Self;

    /// Square root (NaN below zero).
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Sine of an angle in radians.
    fn sin(self) -> Self;
    /// Cosine of an angle in radians.
    fn cos(self) -> Self;
    /// Sine and cosine of an angle in radians, computed together.
    fn sin_cos(self) -> (Self, Self);
    /// Tangent of an angle in radians.
    fn tan(self) -> Self;
    /// Arc tangent, in radians, in `[-π/2, π/2]`.
    fn atan(self) -> Self;
    /// Four-quadrant arc tangent of `self / x`, in radians, in `[-π, π]`.
    fn atan2(self, x: Self) -> Self;
    /// Arc sine, in radians (NaN outside `[-1, 1]`).
    fn asin(self) -> Self;
    /// `sqrt(self² + y²)` without undue overflow.
    fn hypot(self, y: Self) -> Self;
    /// Rounds towards −∞.
    fn floor(self) -> Self;
    /// True unless NaN or ±∞.
    fn is_finite(self) -> bool;

    /// The smaller of two values (the non-NaN one if one is NaN).
    #[inline]
    fn min(self, other: Self) -> Self {
        if other < self || self.partial_cmp(&self).is_none() {
            other
        } else {
            self
        }
    }
    /// The larger of two values (the non-NaN one if one is NaN).
    #[inline]
    fn max(self, other: Self) -> Self {
        if other > self || self.partial_cmp(&self).is_none() {
            other
        } else {
            self
        }
    }
    /// `self` limited to `[lo, hi]` (requires `lo <= hi`).
    #[inline]
    fn clamp(self, lo: Self, hi: Self) -> Self {
        self.max(lo).min(hi)
    }
    /// `self²`.
    #[inline]
    fn sq(self) -> Self {
        self * self
    }
    /// −1, 0 or +1 as the sign of `self` (0 for ±0 and NaN).
    #[inline]
    fn signum0(self) -> Self {
        if self > Self::ZERO {
            Self::ONE
        } else if self < Self::ZERO {
            -Self::ONE
        } else {
            Self::ZERO
        }
    }
}

macro_rules! impl_real {
    ($t:ty, $sqrt:path, $abs:path, $sin:path, $cos:path, $sincos:path, $tan:path, $atan:path,
     $atan2:path, $asin:path, $hypot:path, $floor:path) => {
        impl Real for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const TWO: Self = 2.0;
            const HALF: Self = 0.5;
            const PI: Self = core::f64::consts::PI as $t;
            const EPSILON: Self = <$t>::EPSILON;
            const INFINITY: Self = <$t>::INFINITY;
            const NEG_INFINITY: Self = <$t>::NEG_INFINITY;
            const MAX: Self = <$t>::MAX;
            const NAN: Self = <$t>::NAN;

            #[inline]
            fn lit(v: f32) -> Self {
                v as $t
            }
            #[inline]
            fn from_f64(v: f64) -> Self {
                v as $t
            }
            #[inline]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline]
            fn to_f32(self) -> f32 {
                self as f32
            }
            #[inline]
            fn from_usize(n: usize) -> Self {
                n as $t
            }
            #[inline]
            fn sqrt(self) -> Self {
                $sqrt(self)
            }
            #[inline]
            fn abs(self) -> Self {
                $abs(self)
            }
            #[inline]
            fn sin(self) -> Self {
                $sin(self)
            }
            #[inline]
            fn cos(self) -> Self {
                $cos(self)
            }
            #[inline]
            fn sin_cos(self) -> (Self, Self) {
                $sincos(self)
            }
            #[inline]
            fn tan(self) -> Self {
                $tan(self)
            }
            #[inline]
            fn atan(self) -> Self {
                $atan(self)
            }
            #[inline]
            fn atan2(self, x: Self) -> Self {
                $atan2(self, x)
            }
            #[inline]
            fn asin(self) -> Self {
                $asin(self)
            }
            #[inline]
            fn hypot(self, y: Self) -> Self {
                $hypot(self, y)
            }
            #[inline]
            fn floor(self) -> Self {
                $floor(self)
            }
            #[inline]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
        }
    };
}

impl_real!(
    f32,
    f32_math::sqrt,
    libm::fabsf,
    f32_math::sin,
    f32_math::cos,
    f32_math::sin_cos,
    f32_math::tan,
    libm::atanf,
    libm::atan2f,
    f32_math::asin,
    f32_math::hypot,
    f32_math::floor
);

/// `Σ xᵢ·0`: ±0 when every value is finite, NaN otherwise (`x·0` is ±0 for a finite
/// `x`, NaN for NaN and ±∞, and a sum of zeros is zero, so no finite values are
/// refused by an overflowing sum). One multiplication and one addition per value,
/// no branch; to sum over several groups, or as [`all_finite`].
#[inline(always)]
pub fn finite_probe<T: Real, const N: usize>(values: [T; N]) -> T {
    let Some((&first, rest)) = values.split_first() else {
        return T::ZERO;
    };
    // N − 1 trips, a constant: the compiler unrolls them (no loop is left to bound).
    let mut acc = first * T::ZERO;
    for &v in rest {
        acc += v * T::ZERO;
    }
    acc
}

/// True when every value is finite ([`finite_probe`]: no branch per value).
#[inline(always)]
pub fn all_finite<T: Real, const N: usize>(values: [T; N]) -> bool {
    finite_probe(values) == T::ZERO
}

/// The smaller of `a` and `b`, both finite: a plain comparison, without
/// [`Real::min`]'s care for NaN (its two compares, flag transfers and conditional
/// moves cost the control task's budget, which has values finite by construction).
#[inline(always)]
pub fn smaller<T: Real>(a: T, b: T) -> T {
    if b < a {
        b
    } else {
        a
    }
}

/// The larger of `a` and `b`, both finite (as [`smaller`]).
#[inline(always)]
pub fn larger<T: Real>(a: T, b: T) -> T {
    if b > a {
        b
    } else {
        a
    }
}

/// [`Real::max`]`(x, lo)` for a bound `lo` that is not NaN (a NaN `x` gives
/// `lo`, as there), with one comparison: `Real::max` takes two, caring for a NaN
/// in either argument.
#[inline(always)]
pub fn at_least<T: Real>(x: T, lo: T) -> T {
    // `x >= lo` is false for a NaN `x`.
    if x >= lo {
        x
    } else {
        lo
    }
}

/// [`Real::min`]`(x, hi)` for a bound `hi` that is not NaN (a NaN `x` gives
/// `hi`), with one comparison ([`at_least`]).
#[inline(always)]
pub fn at_most<T: Real>(x: T, hi: T) -> T {
    if x <= hi {
        x
    } else {
        hi
    }
}

/// [`Real::clamp`]`(x, lo, hi)` for bounds that are not NaN, `lo <= hi` (a NaN
/// `x` gives `lo`, as there), with one comparison per bound where `Real::clamp`
/// takes two ([`at_least`], [`at_most`]). The same value, bit for bit.
#[inline(always)]
pub fn clamp_within<T: Real>(x: T, lo: T, hi: T) -> T {
    at_most(at_least(x, lo), hi)
}

/// Single-precision sine, cosine, tangent, arc sine and hypotenuse computed in
/// `f32` only (no `f64` arithmetic, so no software double precision on the M4F).
///
/// Range reduction: `x = j·π/4 + z`, `|z| ≤ π/4`, with `π/4` split in three parts
/// (Cody–Waite), exact enough for `|x| ≤ 8192`; beyond, results stay finite and
/// bounded but lose accuracy. Kernels: the Cephes library's single-precision
/// minimax polynomials (`sinf.c`, `tanf.c`, `asinf.c`, S. L. Moshier). Cost on the
/// M4F: a few tens of FPU instructions each.
// The Cephes coefficients are kept as published; `!(a <= b)` is meant (true for NaN).
#[allow(clippy::excessive_precision, clippy::neg_cmp_op_on_partial_ord)]
pub mod f32_math {
    const FOUR_OVER_PI: f32 = 1.273_239_5;
    const DP1: f32 = 0.785_156_25;
    const DP2: f32 = 2.418_756_5e-4;
    const DP3: f32 = 3.774_895e-8;
    const PI_OVER_2: f32 = core::f32::consts::FRAC_PI_2;

    /// `|x| = j·π/4 + z` with `j` even (octant pair, 0..=7 after masking) and `|z| ≤ π/4`.
    #[inline]
    fn reduce(a: f32) -> (f32, u32) {
        let mut j = (a * FOUR_OVER_PI) as u32;
        let mut y = j as f32;
        if j & 1 == 1 {
            j = j.wrapping_add(1);
            y += 1.0;
        }
        let z = ((a - y * DP1) - y * DP2) - y * DP3;
        (z, j & 7)
    }

    #[inline]
    fn sin_kernel(z: f32, zz: f32) -> f32 {
        ((-1.951_529_6e-4 * zz + 8.332_161e-3) * zz - 1.666_665_5e-1) * zz * z + z
    }

    #[inline]
    fn cos_kernel(zz: f32) -> f32 {
        ((2.443_315_7e-5 * zz - 1.388_731_6e-3) * zz + 4.166_664_6e-2) * zz * zz - 0.5 * zz + 1.0
    }

    /// Sine and cosine of `x` (rad), one range reduction.
    pub fn sin_cos(x: f32) -> (f32, f32) {
        if !x.is_finite() {
            return (f32::NAN, f32::NAN);
        }
        let (z, j) = reduce(libm::fabsf(x));
        let zz = z * z;
        let (s, c) = (sin_kernel(z, zz), cos_kernel(zz));
        // Octants 0..7 of |x|: (sin, cos) = (s, c), (c, -s), (-s, -c), (-c, s).
        let (sin_abs, cos) = match j {
            0 | 1 => (s, c),
            2 | 3 => (c, -s),
            4 | 5 => (-s, -c),
            _ => (-c, s),
        };
        (if x < 0.0 { -sin_abs } else { sin_abs }, cos)
    }

    /// Sine of `x` (rad).
    pub fn sin(x: f32) -> f32 {
        sin_cos(x).0
    }

    /// Cosine of `x` (rad).
    pub fn cos(x: f32) -> f32 {
        sin_cos(x).1
    }

    /// Tangent of `x` (rad).
    pub fn tan(x: f32) -> f32 {
        if !x.is_finite() {
            return f32::NAN;
        }
        let a = libm::fabsf(x);
        let (z, j) = reduce(a);
        let zz = z * z;
        let mut y = if a > 1.0e-4 {
            (((((9.385_402e-3 * zz + 3.119_922_3e-3) * zz + 2.443_013_5e-2) * zz + 5.341_128e-2)
                * zz
                + 1.333_88e-1)
                * zz
                + 3.333_315_7e-1)
                * zz
                * z
                + z
        } else {
            z
        };
        if j & 2 != 0 {
            y = -1.0 / y;
        }
        if x < 0.0 {
            -y
        } else {
            y
        }
    }

    /// Arc sine of `x`, rad, in `[−π/2, π/2]`; NaN outside `[−1, 1]`.
    pub fn asin(x: f32) -> f32 {
        let a = libm::fabsf(x);
        if !(a <= 1.0) {
            return f32::NAN;
        }
        if a < 1.0e-4 {
            return x;
        }
        let (z, x2, flip) = if a > 0.5 {
            let z = 0.5 * (1.0 - a);
            (z, sqrt(z), true)
        } else {
            (a * a, a, false)
        };
        let mut r =
            ((((4.216_32e-2 * z + 2.418_131_1e-2) * z + 4.547_002_6e-2) * z + 7.495_300_3e-2) * z
                + 1.666_675_2e-1)
                * z
                * x2
                + x2;
        if flip {
            r = PI_OVER_2 - (r + r);
        }
        if x < 0.0 {
            -r
        } else {
            r
        }
    }

    /// `⌊x⌋`, the same as `libm::floorf` for every `f32` bit for bit: a value of
    /// magnitude 2²³ or more is an integer already (NaN and ±∞ are returned as
    /// they are); below, the conversion to `i32` (`VCVT`, toward zero), one down
    /// for a negative fraction, and the sign of `x` (`⌊−0⌋ = −0`, `⌊−0.5⌋ = −1`).
    /// About a dozen instructions and one branch where `libm::floorf` takes the
    /// bits apart in integer registers.
    pub fn floor(x: f32) -> f32 {
        if !(libm::fabsf(x) < 8_388_608.0) {
            return x;
        }
        let t = x as i32 as f32;
        let f = if t > x { t - 1.0 } else { t };
        libm::copysignf(f, x)
    }

    /// `sqrt(x² + y²)`, scaled so that it neither overflows nor underflows early.
    pub fn hypot(x: f32, y: f32) -> f32 {
        let (a, b) = (libm::fabsf(x), libm::fabsf(y));
        if a.is_infinite() || b.is_infinite() {
            return f32::INFINITY;
        }
        let (hi, lo) = if a >= b { (a, b) } else { (b, a) };
        if !(hi > 0.0) {
            // Both zero, or a NaN.
            return hi + lo;
        }
        let r = lo / hi;
        hi * sqrt(1.0 + r * r)
    }

    /// Square root, correctly rounded (IEEE 754): the FPU's `VSQRT.F32` on an ARM
    /// target with hardware floating point, `libm::sqrtf` elsewhere (same bits).
    #[inline]
    pub fn sqrt(x: f32) -> f32 {
        #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
        {
            let bits: u32;
            // SAFETY: the root is computed in `s0`, which the block declares
            // clobbered (a clobber names a register outside the classes stable Rust
            // offers for this target's single-precision FPU, so the operands pass
            // through core registers). It reads and writes no memory, uses no stack
            // and leaves the flags alone (`VSQRT` only sets the FPSCR's cumulative
            // exception bits, which nothing reads).
            #[allow(unsafe_code)]
            unsafe {
                core::arch::asm!(
                    "vmov s0, {i}",
                    "vsqrt.f32 s0, s0",
                    "vmov {o}, s0",
                    i = in(reg) x.to_bits(),
                    o = lateout(reg) bits,
                    out("s0") _,
                    options(pure, nomem, nostack, preserves_flags)
                );
            }
            f32::from_bits(bits)
        }
        #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
        {
            libm::sqrtf(x)
        }
    }
}
impl_real!(
    f64,
    libm::sqrt,
    libm::fabs,
    libm::sin,
    libm::cos,
    libm::sincos,
    libm::tan,
    libm::atan,
    libm::atan2,
    libm::asin,
    libm::hypot,
    libm::floor
);

#[cfg(test)]
mod tests {
    use super::Real;

    #[test]
    fn min_max_ignore_nan_and_order() {
        assert_eq!(Real::min(1.0f32, 2.0), 1.0);
        assert_eq!(Real::max(1.0f64, 2.0), 2.0);
        assert_eq!(Real::min(f32::NAN, 2.0), 2.0);
        assert_eq!(Real::max(3.0f64, f64::NAN), 3.0);
        assert_eq!(Real::clamp(5.0f32, -1.0, 1.0), 1.0);
    }

    /// `at_least`, `at_most` and `clamp_within` give `Real::max`, `Real::min` and
    /// `Real::clamp`'s value bit for bit (zeros' signs, NaN, infinities) for any
    /// `x` and bounds that are not NaN.
    #[test]
    fn one_comparison_bounds_are_the_real_ones_bit_for_bit() {
        use super::{at_least, at_most, clamp_within};
        let xs = [
            f32::NAN,
            f32::NEG_INFINITY,
            -2.0,
            -1.0,
            -0.0,
            0.0,
            0.5,
            1.0,
            3.0,
            f32::INFINITY,
        ];
        let bounds = &xs[1..];
        for &x in &xs {
            for &lo in bounds {
                let max = Real::max(x, lo);
                assert_eq!(at_least(x, lo).to_bits(), max.to_bits(), "{x} {lo}");
                let min = Real::min(x, lo);
                assert_eq!(at_most(x, lo).to_bits(), min.to_bits(), "{x} {lo}");
                for &hi in bounds.iter().filter(|&&hi| hi >= lo) {
                    let c = Real::clamp(x, lo, hi);
                    assert_eq!(clamp_within(x, lo, hi).to_bits(), c.to_bits());
                }
            }
        }
    }

    #[test]
    fn f32_math_is_accurate() {
        use super::f32_math;
        let (mut es, mut ec, mut et, mut ea, mut eh) = (0f64, 0f64, 0f64, 0f64, 0f64);
        let mut x = -200.0f32;
        while x < 200.0 {
            let xd = x as f64;
            let (s, c) = f32_math::sin_cos(x);
            es = es.max((s as f64 - xd.sin()).abs());
            ec = ec.max((c as f64 - xd.cos()).abs());
            let t = xd.tan();
            if t.abs() < 50.0 {
                et = et.max((f32_math::tan(x) as f64 - t).abs() / t.abs().max(1.0));
            }
            let u = (x / 200.0) as f64;
            ea = ea.max((f32_math::asin(x / 200.0) as f64 - u.asin()).abs());
            let h = f32_math::hypot(x, 3.0) as f64;
            eh = eh.max((h - xd.hypot(3.0)).abs() / xd.hypot(3.0));
            x += 0.000_731;
        }
        assert!(es < 2e-7 && ec < 2e-7, "sin {es:e} cos {ec:e}");
        assert!(et < 4e-7, "tan {et:e}");
        assert!(ea < 3e-7, "asin {ea:e}");
        assert!(eh < 2e-7, "hypot {eh:e}");
        assert!(f32_math::sin(f32::NAN).is_nan() && f32_math::cos(f32::INFINITY).is_nan());
        assert!(f32_math::asin(1.5).is_nan());
        assert_eq!(f32_math::hypot(0.0, 0.0), 0.0);
        assert_eq!(f32_math::asin(1.0), core::f32::consts::FRAC_PI_2);
    }

    #[test]
    fn all_finite_refuses_any_nan_or_infinity_and_no_overflowing_sum() {
        use super::{all_finite, finite_probe};
        assert!(all_finite([f32::MAX, f32::MAX, -f32::MAX]));
        assert!(all_finite::<f64, 0>([]));
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            for k in 0..3 {
                let mut v = [1.0f32, -2.0, 3.0e38];
                v[k] = bad;
                assert!(!all_finite(v), "{v:?}");
                assert!(finite_probe(v).is_nan());
            }
        }
    }

    #[test]
    fn floor_is_libm_floorf_bit_for_bit() {
        use super::f32_math;
        let same = |x: f32| f32_math::floor(x).to_bits() == libm::floorf(x).to_bits();
        // Every 61st bit pattern (70 M values, both signs, NaNs, subnormals), and
        // every value around the integers and the 2²³ boundary.
        let mut bits: u32 = 0;
        loop {
            let x = f32::from_bits(bits);
            assert!(same(x), "{x:e} ({bits:#010x})");
            match bits.checked_add(61) {
                Some(b) => bits = b,
                None => break,
            }
        }
        for k in -20_000i32..20_000 {
            for x in [k as f32, k as f32 * 419.0 + 0.5, k as f32 * 0.01] {
                for y in [
                    x,
                    -x,
                    f32::from_bits(x.to_bits() + 1),
                    f32::from_bits(x.to_bits().wrapping_sub(1)),
                ] {
                    assert!(same(y), "{y:e}");
                }
            }
        }
        for x in [
            8_388_607.5f32,
            -8_388_607.5,
            8_388_608.0,
            -8_388_608.0,
            0.0,
            -0.0,
            -0.5,
            0.5,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
        ] {
            assert!(same(x), "{x:e}");
        }
        assert!(f32_math::floor(f32::NAN).is_nan());
    }

    #[test]
    fn transcendental_functions_agree_across_precisions() {
        for &x in &[-2.5f32, -0.3, 0.0, 0.7, 1.2] {
            let (s, c) = Real::sin_cos(x);
            assert!((s as f64 - Real::sin(x as f64)).abs() < 1e-6);
            assert!((c as f64 - Real::cos(x as f64)).abs() < 1e-6);
            assert!((Real::atan(x) as f64 - Real::atan(x as f64)).abs() < 1e-6);
        }
    }
}
