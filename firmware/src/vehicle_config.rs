//! What the firmware is told about its car: the few vehicle numbers from which the
//! MPC's, the low-level controller's and the obstacle manager's settings derive.
//!
//! The simulator builds one from its vehicle file and the ECU receives the same
//! numbers in its configuration frame ([`crate::link`]); both then derive their
//! settings with the functions below, so the host and the ECU plan with identical
//! settings, bit for bit.

use crate::bicycle::BicycleGeometry;
use crate::friction::FrictionConfig;
use crate::low_level::{LowLevelConfig, LowLevelConfigError};
use crate::mpc::MpcSettings;
use crate::obstacles::ObstacleSettings;
use crate::tasks::ControlTask;
use crate::Real;

/// The car, as the firmware needs it (SI units in each field).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VehicleConfig<T> {
    /// Distance from the centre of gravity to the front axle `l_f`, m, > 0.
    pub l_f_m: T,
    /// Distance from the centre of gravity to the rear axle `l_r`, m, > 0.
    pub l_r_m: T,
    /// Height of the centre of gravity, m, ≥ 0 (brake balance).
    pub cg_height_m: T,
    /// Body width (track plus a tyre), m, > 0.
    pub width_m: T,
    /// Body length, m, > 0.
    pub length_m: T,
    /// Mass, kg, > 0.
    pub mass_kg: T,
    /// Effective wheel radius, m, > 0.
    pub wheel_radius_m: T,
    /// Mechanical steering limit `|δ|`, rad, > 0.
    pub max_steer_rad: T,
}

impl<T: Real> VehicleConfig<T> {
    /// The reference car: the simulator's built-in car (`host-sim/vehicles/default.toml`,
    /// a 1,500 kg C-segment car) as the firmware is told about it; the tests'
    /// fixture, pinned to the simulator's by `tests/tests/reference_car.rs`.
    pub fn reference() -> Self {
        Self {
            l_f_m: T::from_f64(1.1),
            l_r_m: T::from_f64(1.55),
            cg_height_m: T::from_f64(0.55),
            // Track (2 × 0.775 m) plus a tyre width (0.25 m).
            width_m: T::from_f64(1.8),
            // Wheelbase plus 1.8 m of overhangs.
            length_m: T::from_f64(4.45),
            mass_kg: T::from_f64(1500.0),
            wheel_radius_m: T::from_f64(0.3),
            max_steer_rad: T::from_f64(0.6),
        }
    }

    /// True when every field is finite and positive (the height may be 0).
    pub fn is_valid(&self) -> bool {
        let pos = |x: T| x.is_finite() && x > T::ZERO;
        pos(self.l_f_m)
            && pos(self.l_r_m)
            && self.cg_height_m.is_finite()
            && self.cg_height_m >= T::ZERO
            && pos(self.width_m)
            && pos(self.length_m)
            && pos(self.mass_kg)
            && pos(self.wheel_radius_m)
            && pos(self.max_steer_rad)
    }

    /// Wheelbase `l_f + l_r`, m.
    pub fn wheelbase_m(&self) -> T {
        self.l_f_m + self.l_r_m
    }

    /// The bicycle model's geometry: `l_f` and `l_r`, m.
    pub fn geometry(&self) -> BicycleGeometry<T> {
        BicycleGeometry {
            l_f_m: self.l_f_m,
            l_r_m: self.l_r_m,
        }
    }

    /// The MPC's settings: the paper's ([`MpcSettings::paper`]) for this geometry,
    /// steering limit and width, front-wheel drive (the front axle's static share
    /// of the weight on the driven wheels).
    pub fn mpc_settings(&self) -> MpcSettings<T> {
        let mut s = MpcSettings::paper(self.geometry(), self.max_steer_rad, self.width_m);
        s.driven_load_share = self.l_r_m / self.wheelbase_m();
        s
    }

    /// The low-level controller's configuration: [`LowLevelConfig::default`]
    /// with this car's mass, wheel radius and steering limit; actuator limits of
    /// what the tyres transmit at `μ = 1` with a 20 % margin (0.6 g of traction,
    /// 1 g of braking: the friction limit is the road's business); the safe
    /// actuation brakes at 3 m/s²; the brake balance is the front axle's share of
    /// the load when braking at 0.5 g, within `[0.5, 0.9]`.
    pub fn low_level_config(&self) -> LowLevelConfig<T> {
        let mut c = LowLevelConfig::<T>::default();
        let g = T::lit(crate::G);
        let mr = self.mass_kg * self.wheel_radius_m;
        c.mass_kg = self.mass_kg;
        c.wheel_radius_m = self.wheel_radius_m;
        c.max_traction_torque_nm = mr * T::lit(0.6) * g * T::lit(1.2);
        c.max_braking_torque_nm = mr * g * T::lit(1.2);
        c.safe_brake_torque_nm = mr * T::lit(3.0);
        c.steer_limit_rad = self.max_steer_rad;
        let share = (self.l_r_m + T::HALF * self.cg_height_m) / self.wheelbase_m();
        c.brake_front_share = share.clamp(T::HALF, T::lit(0.9));
        c
    }

    /// The friction check's settings ([`FrictionConfig::for_car`]) for this car
    /// planned with the friction `mu_planner`: its mass, wheel radius, the front
    /// axle's static share of the weight (front-wheel drive, as
    /// [`VehicleConfig::mpc_settings`]), `h/L` and `h/t` (the track `t` the width
    /// less 0.25 m), the wheelbase (the front tyres' grip check) and half the
    /// track (the wheels' ground speeds).
    pub fn friction_config(&self, mu_planner: T) -> FrictionConfig<T> {
        let mut c = FrictionConfig::for_car(
            self.mass_kg,
            self.wheel_radius_m,
            self.l_r_m / self.wheelbase_m(),
            self.cg_height_m / self.wheelbase_m(),
            mu_planner,
        );
        // The track: the body width less a tyre (0.25 m), at least half the width.
        let track = (self.width_m - T::lit(0.25)).max(T::HALF * self.width_m);
        c.cg_height_over_track = self.cg_height_m / track;
        c.wheelbase_m = self.wheelbase_m();
        c.half_track_m = T::HALF * track;
        c
    }

    /// The `control` task for this car planned with the friction `mu_planner`:
    /// [`VehicleConfig::low_level_config`] and [`VehicleConfig::friction_config`].
    pub fn control_task(&self, mu_planner: T) -> Result<ControlTask<T>, LowLevelConfigError> {
        ControlTask::with_friction(self.low_level_config(), self.friction_config(mu_planner))
    }

    /// The obstacle manager's settings for a planner friction `mu`
    /// ([`ObstacleSettings::for_vehicle`] at the planner's top speed on `mu`).
    pub fn obstacle_settings(&self, mu: T) -> ObstacleSettings<T> {
        let v_max = self.mpc_settings().velocity.v_max_mps(mu);
        ObstacleSettings::for_vehicle(self.width_m, self.length_m, mu, v_max)
    }
}
