//! Vehicle parameters of the 9-DoF plant: built-in defaults, TOML loading and
//! validation with errors that name the offending field.
//!
//! A vehicle file is TOML with every field of [`VehicleParams`] at the top level and
//! the tyre coefficients in a `[tyre]` table (see [`TireParams`]). The commented
//! template `host-sim/vehicles/default.toml` holds exactly the built-in defaults.

use std::path::Path;

use firmware::vehicle_config::VehicleConfig;
use firmware::Real;
use serde::Deserialize;

use crate::model::actuator::ActuatorParams;
use crate::model::tire::{self, TireParams};

/// Parameters of the vehicle (the notations of the paper's Table I). SI units.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleParams {
    /// Total mass `M_T`, kg.
    pub mass_kg: f64,
    /// Roll inertia `I_x` of the carbody about its centre of gravity, kg·m².
    pub ix_kg_m2: f64,
    /// Pitch inertia `I_y` of the carbody about its centre of gravity, kg·m².
    pub iy_kg_m2: f64,
    /// Yaw inertia `I_z` of the vehicle about its centre of gravity, kg·m².
    pub iz_kg_m2: f64,
    /// Distance `l_f` from the centre of gravity to the front axle, m.
    pub lf_m: f64,
    /// Distance `l_r` from the centre of gravity to the rear axle, m.
    pub lr_m: f64,
    /// Half-track `l_w` (same front and rear), m.
    pub lw_m: f64,
    /// Height `h` of the centre of gravity above the ground, m.
    pub h_m: f64,
    /// Effective rolling radius `r_eff` of every wheel, m.
    pub r_eff_m: f64,
    /// Spin inertia `I_r` of one wheel (with its share of the driveline), kg·m².
    pub wheel_inertia_kg_m2: f64,
    /// Suspension stiffness `k_s` at each corner (wheel rate), N/m.
    pub ks_n_per_m: f64,
    /// Suspension damping `d_s` at each corner, N·s/m.
    pub ds_n_s_per_m: f64,
    /// Aerodynamic drag coefficient `C_x`, dimensionless.
    pub cx: f64,
    /// Frontal area `S`, m².
    pub frontal_area_m2: f64,
    /// Air density `ρ_air`, kg/m³.
    pub rho_air_kg_per_m3: f64,
    /// Rolling-resistance coefficient `C_rr` of the tyres, dimensionless, in
    /// `[0, MAX_CRR]`: each tyre resists rolling with `C_rr·F_z` (see `plant`).
    /// Optional in a vehicle file: 0 (no rolling resistance) when absent.
    #[serde(default)]
    pub crr: f64,
    /// Mechanical limit of the front wheels' steering angle (both ways), rad.
    pub max_steer_rad: f64,
    /// Low-speed threshold, m/s: the floor of the slip-angle denominator, the least
    /// floor of the slip-ratio denominator, and the speed under which the tyre
    /// offsets fade out (see `plant`).
    pub low_speed_mps: f64,
    /// Tyre (the same on the four wheels; right-hand wheels mirrored).
    pub tyre: TireParams,
    /// The steering and torque actuators' dynamics (the optional `[actuators]`
    /// table; ideal when absent: see [`crate::model::actuator`]).
    #[serde(default)]
    pub actuators: ActuatorParams,
}

impl Default for VehicleParams {
    /// A typical C-segment passenger car (VW Golf / Peugeot 308 class: about 1500 kg,
    /// 2.65 m wheelbase with 58 % of the weight on the front axle, 1.55 m track),
    /// inertias from the usual estimates for that class (`I_z ≈ m·l_f·l_r`), wheel
    /// rates that give about 4° of roll per g, the 205/60R15 PAC2002 tyre of
    /// Pacejka's book (Table A3.1), whose peak friction is about 1 at `μ = 1`, and a
    /// passenger-car tyre's rolling resistance on a paved road (`C_rr` 0.012; the
    /// sources are in `host-sim/vehicles/default.toml`); ideal actuators.
    fn default() -> Self {
        Self {
            mass_kg: 1500.0,
            ix_kg_m2: 550.0,
            iy_kg_m2: 2200.0,
            iz_kg_m2: 2500.0,
            lf_m: 1.1,
            lr_m: 1.55,
            lw_m: 0.775,
            h_m: 0.55,
            r_eff_m: 0.3,
            wheel_inertia_kg_m2: 1.2,
            ks_n_per_m: 35000.0,
            ds_n_s_per_m: 3000.0,
            cx: 0.31,
            frontal_area_m2: 2.2,
            rho_air_kg_per_m3: 1.225,
            crr: 0.012,
            max_steer_rad: 0.6,
            low_speed_mps: 0.5,
            tyre: TireParams::default(),
            actuators: ActuatorParams::default(),
        }
    }
}

/// A field that fails validation, and why.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("field \"{field}\": {reason}")]
pub struct InvalidField {
    /// Name of the field as written in the vehicle file (`tyre.` prefix for tyre
    /// coefficients).
    pub field: String,
    /// What is wrong and what was found.
    pub reason: String,
}

/// Why a vehicle file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum VehicleError {
    /// The file could not be read.
    #[error("vehicle file {path}: cannot read it: {cause}")]
    Io {
        /// The file, as given.
        path: String,
        /// The operating-system error (in the message; not a `source()`, so a
        /// chain prints it once).
        cause: std::io::Error,
    },
    /// The file is not valid TOML, or a field is missing, unknown or of the wrong type.
    #[error("vehicle file {path}: {message}")]
    Parse {
        /// The file, as given.
        path: String,
        /// The TOML parser's message (names the field and the line).
        message: String,
    },
    /// A field has a value the model cannot use.
    #[error("vehicle file {path}: {invalid}")]
    Invalid {
        /// The file, as given.
        path: String,
        /// The field and the reason.
        invalid: InvalidField,
    },
}

fn bad(field: &str, reason: String) -> InvalidField {
    InvalidField {
        field: field.to_string(),
        reason,
    }
}

impl VehicleParams {
    /// Reads and validates a TOML vehicle file.
    pub fn from_toml_file(path: impl AsRef<Path>) -> Result<Self, VehicleError> {
        let path = path.as_ref();
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|cause| VehicleError::Io {
            path: name.clone(),
            cause,
        })?;
        Self::from_toml_named(&text, &name)
    }

    /// Parses and validates vehicle parameters from TOML text (errors say
    /// `vehicle file (text)`).
    pub fn from_toml_str(text: &str) -> Result<Self, VehicleError> {
        Self::from_toml_named(text, "(text)")
    }

    fn from_toml_named(text: &str, name: &str) -> Result<Self, VehicleError> {
        let params: Self = toml::from_str(text).map_err(|e| VehicleError::Parse {
            path: name.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        params.validate().map_err(|invalid| VehicleError::Invalid {
            path: name.to_string(),
            invalid,
        })?;
        Ok(params)
    }

    /// Checks every field: finite, positive where the model divides by it, the
    /// actuators' ranges, and a tyre whose forces have the signs of this project's
    /// convention.
    pub fn validate(&self) -> Result<(), InvalidField> {
        let positive = [
            ("mass_kg", self.mass_kg),
            ("ix_kg_m2", self.ix_kg_m2),
            ("iy_kg_m2", self.iy_kg_m2),
            ("iz_kg_m2", self.iz_kg_m2),
            ("lf_m", self.lf_m),
            ("lr_m", self.lr_m),
            ("lw_m", self.lw_m),
            ("h_m", self.h_m),
            ("r_eff_m", self.r_eff_m),
            ("wheel_inertia_kg_m2", self.wheel_inertia_kg_m2),
            ("ks_n_per_m", self.ks_n_per_m),
            ("max_steer_rad", self.max_steer_rad),
            ("low_speed_mps", self.low_speed_mps),
        ];
        let non_negative = [
            ("ds_n_s_per_m", self.ds_n_s_per_m),
            ("cx", self.cx),
            ("frontal_area_m2", self.frontal_area_m2),
            ("rho_air_kg_per_m3", self.rho_air_kg_per_m3),
            ("crr", self.crr),
        ];
        for (name, v) in positive.iter().chain(non_negative.iter()) {
            if !v.is_finite() {
                return Err(bad(name, format!("must be a finite number, got {v}")));
            }
        }
        for (name, v) in tire_fields(&self.tyre) {
            if !v.is_finite() {
                return Err(bad(&name, format!("must be a finite number, got {v}")));
            }
        }
        for (name, v) in positive {
            if v <= 0.0 {
                return Err(bad(name, format!("must be positive, got {v}")));
            }
        }
        for (name, v) in non_negative {
            if v < 0.0 {
                return Err(bad(name, format!("must be zero or positive, got {v}")));
            }
        }
        self.actuators.validate()?;
        if self.crr > MAX_CRR {
            return Err(bad(
                "crr",
                format!(
                    "the rolling-resistance coefficient must be at most {MAX_CRR} (passenger-car \
                     tyres on a paved road: about 0.01), got {}",
                    self.crr
                ),
            ));
        }
        if self.max_steer_rad >= core::f64::consts::FRAC_PI_2 {
            return Err(bad(
                "max_steer_rad",
                format!(
                    "must be less than pi/2 (90 degrees), got {}",
                    self.max_steer_rad
                ),
            ));
        }
        let t = &self.tyre;
        for (name, v) in [
            ("tyre.fnomin", t.fnomin),
            ("tyre.lfzo", t.lfzo),
            ("tyre.pcx1", t.pcx1),
            ("tyre.pcy1", t.pcy1),
        ] {
            if v <= 0.0 {
                return Err(bad(name, format!("must be positive, got {v}")));
            }
        }
        if t.pky2 == 0.0 {
            return Err(bad(
                "tyre.pky2",
                "must not be zero (it divides the load in K_y)".to_string(),
            ));
        }
        let fz = t.nominal_load_n();
        let (fx, _) = tire::forces(0.05, 0.0, fz, 1.0, t);
        if fx.is_nan() || fx <= 0.0 {
            return Err(bad(
                "tyre.pkx1",
                format!(
                    "the tyre must push forward when driving (slip ratio 0.05 at the \
                     nominal load gives F_x = {fx:.1} N); check the signs of pdx1 and pkx1"
                ),
            ));
        }
        let (_, fy) = tire::forces(0.0, 0.05, fz, 1.0, t);
        if fy.is_nan() || fy <= 0.0 {
            return Err(bad(
                "tyre.pky1",
                format!(
                    "a slip angle of +0.05 rad (wheel pointing left of its velocity) must \
                     push the tyre left, got F_y = {fy:.1} N; coefficients are expected in \
                     the ISO sign convention of .tir files, where pky1 < 0"
                ),
            ));
        }
        Ok(())
    }

    /// The car with its mass and inertias × `k` (a load the firmware is not told
    /// of: `--mass-scale`); geometry, suspension and tyres unchanged.
    pub fn with_mass_scale(&self, k: f64) -> Self {
        let mut p = *self;
        p.mass_kg *= k;
        p.ix_kg_m2 *= k;
        p.iy_kg_m2 *= k;
        p.iz_kg_m2 *= k;
        p
    }

    /// Static normal load on each wheel `[fl, fr, rl, rr]`, N: `M_T·g·l_r/(2L)` front,
    /// `M_T·g·l_f/(2L)` rear.
    pub fn static_loads_n(&self) -> [f64; 4] {
        let l = self.lf_m + self.lr_m;
        let front = self.mass_kg * G * self.lr_m / (2.0 * l);
        let rear = self.mass_kg * G * self.lf_m / (2.0 * l);
        [front, front, rear, rear]
    }
}

/// Checks a scale of the plant's mass and inertias given on the command line
/// (`--mass-scale`): in (0.2, 5).
pub fn check_mass_scale(k: f64) -> Result<(), String> {
    if !(k.is_finite() && k > 0.2 && k < 5.0) {
        return Err(format!("--mass-scale wants factors in (0.2, 5), got {k}"));
    }
    Ok(())
}

/// Largest rolling-resistance coefficient a vehicle file may give: ten times a
/// passenger-car tyre's on a paved road (soft ground, which this model does not
/// describe, is where larger ones are found).
pub const MAX_CRR: f64 = 0.1;

/// Standard gravity used by the plant, m/s² (the value of `firmware::G`).
pub const G: f64 = 9.81;

fn tire_fields(t: &TireParams) -> impl Iterator<Item = (String, f64)> {
    t.named_values()
        .into_iter()
        .map(|(n, v)| (format!("tyre.{n}"), v))
}

/// What the firmware is told about the car of a vehicle file (the same numbers
/// the ECU receives in its configuration frame).
pub fn vehicle_config<T: Real>(v: &VehicleParams) -> VehicleConfig<T> {
    VehicleConfig {
        l_f_m: T::from_f64(v.lf_m),
        l_r_m: T::from_f64(v.lr_m),
        cg_height_m: T::from_f64(v.h_m),
        width_m: T::from_f64(vehicle_width_m(v)),
        length_m: T::from_f64(vehicle_length_m(v)),
        mass_kg: T::from_f64(v.mass_kg),
        wheel_radius_m: T::from_f64(v.r_eff_m),
        max_steer_rad: T::from_f64(v.max_steer_rad),
    }
}

/// Body width used for clearances: track plus a tyre width, m.
pub fn vehicle_width_m(v: &VehicleParams) -> f64 {
    2.0 * v.lw_m + 0.25
}

/// Body length used for clearances: wheelbase plus overhangs, m.
pub fn vehicle_length_m(v: &VehicleParams) -> f64 {
    v.lf_m + v.lr_m + 1.8
}
