//! Kinematic bicycle model of the paper (its Equation 1), with `ṡ = V`.

use crate::Real;

/// Geometry of the kinematic bicycle (the front and rear wheels lumped on the axis).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BicycleGeometry<T> {
    /// Distance from the centre of gravity to the front axle `l_f`, m.
    pub l_f_m: T,
    /// Distance from the centre of gravity to the rear axle `l_r`, m.
    pub l_r_m: T,
}

impl<T: Real> BicycleGeometry<T> {
    /// Wheelbase `l_f + l_r`, m.
    pub fn wheelbase_m(&self) -> T {
        self.l_f_m + self.l_r_m
    }

    /// Slip angle at the centre of gravity `β(δ) = atan(tan δ · l_r/(l_f+l_r))`, rad.
    pub fn beta_rad(&self, delta_rad: T) -> T {
        (delta_rad.tan() * self.l_r_m / self.wheelbase_m()).atan()
    }
}
