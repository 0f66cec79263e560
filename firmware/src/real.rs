//! The scalar type of the planning and control maths.
//!
//! The ECU computes in `f32` (the Cortex-M4F FPU is single precision; `f64` there
//! is software-emulated and an order of magnitude slower). The host can run the
//! same code in `f64` to measure what single precision costs in accuracy. Every
//! algorithm of this crate is generic over [`Real`]; its transcendental functions
//! come from `libm` (deterministic, bit-identical on every target).

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
    libm::sqrtf,
    libm::fabsf,
    libm::sinf,
    libm::cosf,
    libm::sincosf,
    libm::tanf,
    libm::atanf,
    libm::atan2f,
    libm::asinf,
    libm::hypotf,
    libm::floorf
);
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
