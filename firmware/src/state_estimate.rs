//! The state estimate: what the vehicle's sensors and estimator hand to both tasks.

use crate::Real;
use qp::real::all_finite;

/// Vehicle state as measured/estimated at one instant (SI units). Serde derives carry
/// it in the simulator's sensor frame ([`crate::link::SensorFrame`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StateEstimate<T> {
    /// Time of the measurement, µs since start.
    pub stamp_us: u64,
    /// Global X position of the centre of gravity, m.
    pub x_m: T,
    /// Global Y position of the centre of gravity, m.
    pub y_m: T,
    /// Yaw angle, rad (counter-clockwise, not wrapped).
    pub psi_rad: T,
    /// Longitudinal speed in the vehicle frame, m/s.
    pub vx_mps: T,
    /// Lateral speed in the vehicle frame (positive to the left), m/s.
    pub vy_mps: T,
    /// Yaw rate, rad/s.
    pub yaw_rate_radps: T,
    /// Front steering angle currently applied, rad.
    pub delta_rad: T,
    /// The four wheels' circumferential speeds `ω·r_eff` `[fl, fr, rl, rr]`, m/s
    /// (an ABS system's wheel-speed sensors). Not finite: not measured (the
    /// friction check then reads slip from the acceleration alone); not part of
    /// [`StateEstimate::is_finite`].
    pub wheel_speed_mps: [T; 4],
    /// The accelerometer's specific force along the car's `x` axis, m/s²
    /// (positive forward): the acceleration plus `g·sin γ` on a road of grade
    /// `γ` (uphill positive), what an IMU reads. Not finite: not measured (the
    /// friction check and the longitudinal estimator then read the
    /// acceleration from the speed); not part of [`StateEstimate::is_finite`].
    pub specific_force_x_mps2: T,
}

impl<T: Real> Default for StateEstimate<T> {
    /// [`StateEstimate::zeroed`].
    fn default() -> Self {
        Self::zeroed()
    }
}

impl<T: Real> StateEstimate<T> {
    /// An all-zero estimate at time 0, its wheel speeds and specific force not
    /// measured (NaN); a valid `const` initialiser.
    pub const fn zeroed() -> Self {
        Self {
            stamp_us: 0,
            x_m: T::ZERO,
            y_m: T::ZERO,
            psi_rad: T::ZERO,
            vx_mps: T::ZERO,
            vy_mps: T::ZERO,
            yaw_rate_radps: T::ZERO,
            delta_rad: T::ZERO,
            wheel_speed_mps: [T::NAN; 4],
            specific_force_x_mps2: T::NAN,
        }
    }

    /// The estimate of a control period that has none, stamped `stamp_us` (µs):
    /// every quantity NaN. Both tasks refuse it (the control task applies the safe
    /// actuation, fault `NonFiniteEstimate`; the plan task does not plan): the
    /// dropout policy. The ECU runs a period whose sensor frame it refused on it,
    /// and the simulator's `dropout-nan` fault delivers it.
    pub fn unavailable(stamp_us: u64) -> Self {
        let nan = T::from_f64(f64::NAN);
        Self {
            stamp_us,
            x_m: nan,
            y_m: nan,
            psi_rad: nan,
            vx_mps: nan,
            vy_mps: nan,
            yaw_rate_radps: nan,
            delta_rad: nan,
            wheel_speed_mps: [nan; 4],
            specific_force_x_mps2: nan,
        }
    }

    /// Speed over ground `V = sqrt(vx² + vy²)`, m/s, signed by `vx`.
    pub fn speed_mps(&self) -> T {
        let v = self.vx_mps.hypot(self.vy_mps);
        if self.vx_mps < T::ZERO {
            -v
        } else {
            v
        }
    }

    /// True when every field but the wheel speeds and the specific force is
    /// finite (NaN and ±∞ are refused by the tasks; [`all_finite`]: no branch
    /// per field).
    pub fn is_finite(&self) -> bool {
        all_finite([
            self.x_m,
            self.y_m,
            self.psi_rad,
            self.vx_mps,
            self.vy_mps,
            self.yaw_rate_radps,
            self.delta_rad,
        ])
    }
}
