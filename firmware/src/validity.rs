//! Validity limit of the kinematic bicycle model: `δ_max(V)`.
//!
//! The kinematic model holds while the lateral acceleration stays under
//! `a_y,lim = 0.5·μ·g` (the paper's Section II, after Polack et al. 2017). A steady
//! turn of radius `R` needs the kinematic steering (the paper's Equation 2)
//!
//! ```text
//! δ_th(R) = atan((l_f/l_r + 1) · tan(asin(l_r / R)))
//! ```
//!
//! and at speed `V` the radius at the limit is `R = V²/a_y,lim`, so
//!
//! ```text
//! δ_max(V) = atan((l_f/l_r + 1) · tan(asin(a_y,lim · l_r / V²)))
//! ```
//!
//! Below `V = sqrt(a_y,lim · l_r)` the `asin` argument exceeds 1: there the
//! kinematic model allows any steering and the mechanical limit applies. The
//! result never exceeds the mechanical limit.

// `!(a > b)` is meant: it is also true when `a` is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::bicycle::BicycleGeometry;
use crate::Real;

/// Parameters of the validity limit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidityLimit<T> {
    /// Bicycle geometry (`l_f`, `l_r`), m.
    pub geometry: BicycleGeometry<T>,
    /// Road friction coefficient `μ`, dimensionless (1 on dry asphalt).
    pub mu: T,
    /// Fraction of `μ·g` allowed as lateral acceleration (the paper's 0.5).
    pub ay_fraction: T,
    /// Mechanical steering limit of the front wheels, rad (positive).
    pub delta_mech_max_rad: T,
}

impl<T: Real> ValidityLimit<T> {
    /// Largest lateral acceleration the plan may demand, `ay_fraction·μ·g`, m/s².
    pub fn ay_limit_mps2(&self) -> T {
        self.ay_fraction * self.mu * T::lit(crate::G)
    }

    /// `δ_max(V)`, rad, at speed `v_mps` (m/s; its sign is ignored).
    pub fn delta_max_rad(&self, v_mps: T) -> T {
        self.delta_max_and_slope(v_mps).0
    }

    /// `δ_max(V)`, rad, and its derivative `dδ_max/dV`, rad per m/s (0 where the
    /// mechanical limit applies), at `|v_mps|`.
    pub fn delta_max_and_slope(&self, v_mps: T) -> (T, T) {
        let v = v_mps.abs();
        let k = self.ay_limit_mps2() * self.geometry.l_r_m;
        let v2 = v * v;
        // asin argument; at or above 1 (or at V = 0) the model allows any steering.
        if !(v2 > k) {
            return (self.delta_mech_max_rad, T::ZERO);
        }
        let a = k / v2;
        let c = self.geometry.wheelbase_m() / self.geometry.l_r_m;
        let one_minus_a2 = T::ONE - a * a;
        let root = one_minus_a2.sqrt();
        let tan_gamma = a / root; // tan(asin a)
        let delta = (c * tan_gamma).atan();
        if delta >= self.delta_mech_max_rad {
            return (self.delta_mech_max_rad, T::ZERO);
        }
        // d/dV: dδ/dt · dt/da · da/dV, t = tan(asin a), dt/da = (1 - a²)^(-3/2).
        let d_delta_d_t = c / (T::ONE + c * c * tan_gamma * tan_gamma);
        let d_t_d_a = T::ONE / (one_minus_a2 * root);
        let d_a_d_v = -T::TWO * a / v;
        (delta, d_delta_d_t * d_t_d_a * d_a_d_v)
    }
}

/// Kinematic steering `δ_th` that holds a steady turn of radius `radius_m` (m),
/// the paper's Equation 2, rad. `None` when `radius_m < l_r` (no such turn).
pub fn kinematic_steering_for_radius<T: Real>(
    geometry: &BicycleGeometry<T>,
    radius_m: T,
) -> Option<T> {
    let r = radius_m.abs();
    if !(r >= geometry.l_r_m) || !r.is_finite() {
        return None;
    }
    let gamma = (geometry.l_r_m / r).asin();
    let c = geometry.wheelbase_m() / geometry.l_r_m;
    Some((c * gamma.tan()).atan())
}

/// Lateral acceleration of the kinematic model at speed `v_mps` (m/s) and steering
/// `delta_rad` (rad): `V²·sin(β(δ))/l_r`, m/s² (positive to the left).
pub fn kinematic_lateral_acceleration<T: Real>(
    geometry: &BicycleGeometry<T>,
    v_mps: T,
    delta_rad: T,
) -> T {
    v_mps * v_mps * geometry.beta_rad(delta_rad).sin() / geometry.l_r_m
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn limit() -> ValidityLimit<f64> {
        ValidityLimit {
            geometry: BicycleGeometry {
                l_f_m: 1.2,
                l_r_m: 1.6,
            },
            mu: 1.0,
            ay_fraction: 0.5,
            delta_mech_max_rad: 0.6,
        }
    }

    #[test]
    fn at_the_limit_the_lateral_acceleration_is_half_mu_g() {
        let l = limit();
        for v in [5.0, 8.0, 12.0, 20.0, 30.0] {
            let d = l.delta_max_rad(v);
            if d < l.delta_mech_max_rad {
                let ay = kinematic_lateral_acceleration(&l.geometry, v, d);
                assert!((ay - l.ay_limit_mps2()).abs() < 1e-9, "v={v}: a_y={ay}");
            }
        }
    }

    #[test]
    fn the_limit_scales_with_mu_and_the_fraction() {
        let g = firmware_g();
        for (mu, fraction) in [(0.5, 0.5), (0.3, 0.5), (1.0, 0.4), (0.8, 0.25)] {
            let l = ValidityLimit {
                mu,
                ay_fraction: fraction,
                ..limit()
            };
            let want = fraction * mu * g;
            assert!((l.ay_limit_mps2() - want).abs() < 1e-12, "μ {mu}");
            // At speed, δ_max holds exactly that lateral acceleration.
            let d = l.delta_max_rad(20.0);
            let ay = kinematic_lateral_acceleration(&l.geometry, 20.0, d);
            assert!((ay - want).abs() < 1e-9, "μ {mu}: a_y {ay} against {want}");
        }
        // Less grip, less steering at the same speed.
        let wet = ValidityLimit { mu: 0.5, ..limit() };
        assert!(wet.delta_max_rad(15.0) < limit().delta_max_rad(15.0));
    }

    fn firmware_g() -> f64 {
        f64::from(crate::G)
    }

    #[test]
    fn defined_at_every_speed_and_capped_by_the_mechanical_limit() {
        let l = limit();
        for v in [0.0, 0.1, 1.0, 2.0, 2.8, 3.0, -10.0, 1e6] {
            let (d, slope) = l.delta_max_and_slope(v);
            assert!(d.is_finite() && slope.is_finite());
            assert!(d > 0.0 && d <= l.delta_mech_max_rad);
        }
        assert_eq!(l.delta_max_rad(0.0), 0.6);
        assert!(l.delta_max_rad(30.0) < l.delta_max_rad(15.0));
    }

    #[test]
    fn slope_matches_finite_differences() {
        let l = limit();
        for v in [6.0, 10.0, 17.0, 28.0] {
            let h = 1e-6;
            let fd = (l.delta_max_rad(v + h) - l.delta_max_rad(v - h)) / (2.0 * h);
            let (_, slope) = l.delta_max_and_slope(v);
            assert!(
                (fd - slope).abs() < 1e-6 * (1.0 + fd.abs()),
                "v={v}: {fd} vs {slope}"
            );
        }
    }

    #[test]
    fn kinematic_steering_inverts_the_turn_radius() {
        let g = BicycleGeometry {
            l_f_m: 1.2,
            l_r_m: 1.6,
        };
        for r in [10.0, 20.0, 80.0] {
            let d = kinematic_steering_for_radius(&g, r).unwrap();
            // R = l_r / sin β
            let back = g.l_r_m / g.beta_rad(d).sin();
            assert!((back - r).abs() < 1e-9);
        }
        assert!(kinematic_steering_for_radius(&g, 1.0).is_none());
        assert!(kinematic_steering_for_radius(&g, f64::NAN).is_none());
    }
}
