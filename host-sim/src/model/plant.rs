//! The 9-DoF vehicle plant of the paper's Section IV, integrated with a fixed-step
//! RK4 (1 kHz by default).
//!
//! Degrees of freedom: the vehicle's `V_x`, `V_y`, yaw rate `ψ̇` (and `X`, `Y`, `ψ`),
//! the carbody's roll `θ` and pitch `φ` with their rates, and the four wheel spins
//! `ω_i` (`i` = fl, fr, rl, rr). Inputs: the four wheel torques and the front steering
//! angle (both front wheels). Vehicle frame x forward, y left, z up; yaw, roll and
//! pitch right-handed (yaw counter-clockwise, roll positive when the left side rises,
//! pitch positive nose down). The commands go through the car's actuators
//! ([`crate::model::actuator`]: delay, lag, rate limit; ideal by default) before
//! the plant applies them, held over each step.
//!
//! # Equations (the paper's, with these choices)
//!
//! * Normal loads `F_zi = F_z0,i − k_s·ζ_i − d_s·ζ̇_i` (clamped at 0: a wheel may lift)
//!   with the suspension extension `ζ_i = ±l_w·sin θ ∓ x_i·sin φ`, `+l_w` on the left,
//!   `x_i = l_f` front, `−l_r` rear. Braking pitches nose down and loads the front;
//!   cornering to the left rolls the body toward the outside (left side up, `θ > 0`)
//!   and loads the right wheels.
//! * The loads' moments in the roll and pitch equations have the arms `l_w·cos θ` and
//!   `x_i·cos φ` (the paper's `l_w`, `l_f`, `l_r` at small angles): a load `F_zi` does
//!   the work `F_zi·dζ_i` when the body turns, and `∂ζ_i/∂θ = ±l_w·cos θ`,
//!   `∂ζ_i/∂φ = −x_i·cos φ`. With these arms the suspension is exactly a potential
//!   (its springs) plus a dissipation (its dampers, and the clamp at zero load), so a
//!   free roll or pitch oscillation loses energy and never gains it.
//! * The pitch equation subtracts the moment of the static loads, which is zero
//!   analytically, so that a car at rest is an exact equilibrium in floating point.
//! * Aerodynamic drag `½·ρ·C_x·S·V_x·|V_x|` (the paper's `V_x²`, opposing reversing too).
//! * Rolling resistance (not in the paper): each tyre's rolling-resistance moment
//!   `C_rr·F_zi·r_eff` on its wheel, against the wheel's rotation (see *Wheel
//!   torques* below); at steady rolling the tyre then pushes back on the car with
//!   `C_rr·F_zi`.
//! * The road's grade (not in the paper; see *The road's grade* below).
//! * Tyre forces from [`crate::model::tire`], turned from the tyre frame to the vehicle frame
//!   by the steering angle only (derived below; the paper's last equation of Section
//!   IV is not used as printed). The right-hand wheels carry the mirror image of the
//!   tyre (MF-Tyre's `TYRESIDE = RIGHT`), so the car is left-right symmetric and runs
//!   straight with the wheels straight.
//! * A wheel's load never goes below zero: when `F_z0,i − k_s·ζ_i − d_s·ζ̇_i` would,
//!   the wheel is lifted, its load is 0 and it makes no tyre force. The plant reports
//!   it ([`Outputs::wheel_lifted`], [`Plant::wheel_lift`]).
//!
//! # Forces on the body: a derivation
//!
//! Three frames, all right-handed with `z` up: the ground frame (inertial); the
//! vehicle frame, the ground frame turned by the yaw `ψ` about `z` (horizontal); the
//! carbody frame, the vehicle frame turned by the pitch `φ` about `y` (positive: nose
//! down) and then by the roll `θ` about the new `x` (positive: left side up),
//! `R = R_y(φ)·R_x(θ)`. A vector `(a, b, c)` of the vehicle frame has the body
//! components
//!
//! ```text
//! Rᵀ·(a, b, c) = ( a·cos φ                         − c·sin φ,
//!                  a·sin θ·sin φ + b·cos θ          + c·sin θ·cos φ,
//!                  a·cos θ·sin φ − b·sin θ          + c·cos θ·cos φ ).
//! ```
//!
//! The road is a plane (level in the paper; see *The road's grade* for a road that
//! rises along the car) and the vehicle frame lies in it, so each tyre's contact
//! force is `(a_i, b_i, F_zi)` in the vehicle frame, its in-plane part turned by the wheel's
//! steering angle `δ_i` (`δ` front, 0 rear): `a_i = F_xpi·cos δ_i − F_ypi·sin δ_i`,
//! `b_i = F_xpi·sin δ_i + F_ypi·cos δ_i`. The paper's rotation equation is
//! `Rᵀ·(a_i, b_i, F_zi)`: the tyre forces in the body frame. The weight `(0, 0, −M_T·g)`
//! has the body components `M_T·g·(sin φ, −sin θ·cos φ, −cos θ·cos φ)`, which the paper
//! leaves out. The total external force in the body frame is therefore (drag aside)
//!
//! ```text
//! F_x,body = cos φ·Σa_i                      − sin φ·(ΣF_zi − M_T·g)
//! F_y,body = sin θ·sin φ·Σa_i + cos θ·Σb_i    + sin θ·cos φ·(ΣF_zi − M_T·g)
//! ```
//!
//! The paper's `F_z·sin` terms are cancelled by the weight as long as the loads carry
//! the weight; what is left, `ΣF_zi − M_T·g = −k_s·Σζ_i − d_s·Σζ̇_i`, is a vertical
//! (heave) force of the suspension for which the model has no degree of freedom.
//! Roll and pitch turn about the centre of gravity (the paper's assumption), so the
//! centre of gravity moves in the horizontal plane and `V_x`, `V_y` are its velocity
//! in the horizontal vehicle frame. Newton's law for it takes the horizontal
//! components of the total force, the first two components of `R·F_body`, which are
//! `(Σa_i − F_aero, Σb_i)` exactly: the body's attitude drops out. Hence, in the
//! paper's equations of motion,
//!
//! ```text
//! F_xi = F_xpi·cos δ_i − F_ypi·sin δ_i,        F_yi = F_xpi·sin δ_i + F_ypi·cos δ_i,
//! ```
//!
//! and the roll and pitch equations are the paper's, with the load arms above (their
//! moments are about the centre of gravity, where the weight has none). As printed, the paper's rotation
//! adds `≈ ΣF_z·sin θ` to `ΣF_y` and `−ΣF_z·sin φ` to `ΣF_x` with no physical source:
//! about `g·sin θ` toward the inside of a turn (0.5 m/s² at 5 m/s² of lateral
//! acceleration), which let a steady circle hold more lateral acceleration than the
//! tyres' friction allows, and a pitched car coasting on the level speed up or slow
//! down by `g·sin φ`.
//!
//! # The road's grade
//!
//! On a road that rises ahead of the car at the grade angle `γ` (a grade of
//! `100·tan γ` %, positive uphill), the vehicle frame is the road's plane: `x` along
//! the road, tilted up by `γ`, `y` across it (horizontal), `z` normal to the road.
//! The weight there is `M_T·g·(−sin γ, 0, −cos γ)`, so
//!
//! * its component along the road, `−M_T·g·sin γ`, acts on `V_x`, at the centre of
//!   gravity (no moment: the body's pitch and roll are unchanged by it);
//! * the loads carry its normal component: the static loads are `F_z0,i·cos γ` (and
//!   so is the static pitch moment subtracted, zero analytically);
//! * the longitudinal load transfer of a car held or driven on the slope comes from
//!   the tyre forces' pitch moment `−h·ΣF_x`, as on the level: standing on an uphill
//!   grade on its brakes, the tyres push up the slope with `M_T·g·sin γ` and the
//!   load moves to the rear axle;
//! * the centre of gravity moves over the ground at `V_x·cos γ` along the heading:
//!   `Ẋ = V_x·cos γ·cos ψ − V_y·sin ψ`, `Ẏ = V_x·cos γ·sin ψ + V_y·cos ψ`.
//!
//! `γ` is the grade along the car's `x` axis, an input of each step like the road's
//! friction: the road's slope seen across the car (`sin` of the car's heading off
//! the road's direction) and the heading's distortion on the slope (`1 − cos γ`,
//! 0.18 % at 6 %) are left out. [`Outputs::specific_force_x_mps2`] is what an
//! accelerometer on the car reads along `x`, the non-gravitational force per unit
//! mass: the acceleration [`Outputs::ax_mps2`] plus `g·sin γ`.
//!
//! # Slip near standstill
//!
//! `V_xp`, `V_yp` are the wheel-centre velocity components along and across the wheel
//! heading. The slip ratio is the paper's, with its denominator floored:
//!
//! * traction (`r·ω ≥ V_xp`): `κ = (r·ω − V_xp) / max(r·|ω|, v_κ)`;
//! * braking (`r·ω < V_xp`): `κ = (r·ω − V_xp) / max(|V_xp|, v_κ)`;
//!
//! and the slip angle is `α = −atan(V_yp / max(|V_xp|, v_α))`, which equals the
//! paper's `δ − atan((V_y + l_f·ψ̇)/(V_x ∓ l_w·ψ̇))` (front) and
//! `−atan((V_y − l_r·ψ̇)/(V_x ∓ l_w·ψ̇))` (rear) when moving forward above the floor.
//!
//! * `v_α = max(low_speed_mps, v_α,stab)`, where `v_α,stab` is the speed under which
//!   the lateral and yaw modes (time constant ∝ V/C_α) would be too fast for the RK4
//!   step.
//! * `v_κ = max(low_speed_mps, dt·r_eff²·K_xκ(F_z)/(2·I_r))`, per wheel and at its
//!   current load: under that speed the wheel-spin mode, whose rate is
//!   `r_eff²·K_xκ/(I_r·V)`, would make RK4 unstable at the step `dt`. For the default
//!   car at 1 kHz, `v_κ` is about 3.5 m/s at the static load: below it the slip ratio
//!   becomes a slip *velocity* over a constant, i.e. a viscous tyre that brings the
//!   wheel and the car to rest smoothly.
//! * The Magic Formula's offsets (conicity, ply steer, rolling offsets) are multiplied
//!   by `min(1, V_wheel/low_speed_mps)` (`V_wheel` the wheel-centre speed), like the
//!   low-speed treatment of MF-Tyre: a car at rest with zero torque has exactly zero
//!   tyre force and stays exactly at rest.
//!
//! Both floors are continuous in the state (a `max`), so the derivative stays
//! continuous; no division by zero or NaN can occur for finite states.
//!
//! # Wheel torques: drive, friction brakes and rolling resistance
//!
//! A positive wheel torque drives. A negative one is a brake torque of that
//! magnitude: friction that opposes the wheel's rotation and cannot spin it
//! backwards. The tyre's rolling-resistance moment `C_rr·F_zi·r_eff` is friction of
//! the same kind. Their sum `T_f` is applied as `−T_f·clamp(ω/ω_lock, −1, 1)` with
//! `ω_lock` from [`brake_lock_radps`] of `T_f`: the full torque against the
//! rotation above `ω_lock`, and a stiff viscous lock below, so a locked wheel stays
//! (nearly) still instead of reversing, a wheel at rest feels no rolling
//! resistance (a car at rest on the level stays exactly at rest), and the
//! derivative stays continuous for RK4.
//!
//! # Speed
//!
//! What does not change within a step is computed once per step (`sin δ`, `cos δ`,
//! the brake-lock speeds); roll, pitch and yaw share one `sin_cos` each per
//! evaluation. The rest of the time is the tyres' `atan`, `sin` and `cos` (the C
//! library's, bit for bit reproducible on one machine; see the tyre module's *Speed
//! and determinism*), which [`crate::model::tire::AtLoad::forces`] calls in rounds of
//! independent calls. `PLANT_BENCH_STEPS=N cargo bench -p host-sim --bench plant`
//! runs a fixed number of steps (for instruction counters).

use crate::model::actuator::Actuators;
use crate::model::tire;
use crate::model::vehicle::{InvalidField, VehicleParams, G};

/// Index of the front-left wheel in the per-wheel arrays.
pub const FL: usize = 0;
/// Index of the front-right wheel in the per-wheel arrays.
pub const FR: usize = 1;
/// Index of the rear-left wheel in the per-wheel arrays.
pub const RL: usize = 2;
/// Index of the rear-right wheel in the per-wheel arrays.
pub const RR: usize = 3;

/// Default integration step, s (1 kHz).
pub const DEFAULT_DT_S: f64 = 1e-3;

/// Least wheel speed under which a brake torque fades linearly to zero (a locked
/// wheel), rad/s; see [`brake_lock_radps`].
pub const BRAKE_LOCK_RADPS: f64 = 2.0;

/// Wheel speed under which the brake torque `torque_nm` (N·m) fades, rad/s: the
/// larger of [`BRAKE_LOCK_RADPS`] and `|T|·dt/(BRAKE_LOCK_RATE_DT·I_r)`. The fade
/// is a viscous lock of rate `|T|/(ω_lock·I_r)`, at most `BRAKE_LOCK_RATE_DT/dt`.
pub fn brake_lock_radps(torque_nm: f64, dt_s: f64, wheel_inertia_kg_m2: f64) -> f64 {
    BRAKE_LOCK_RADPS.max(torque_nm.abs() * dt_s / (BRAKE_LOCK_RATE_DT * wheel_inertia_kg_m2))
}

/// Largest rate of the brakes' viscous lock times the step (see
/// [`brake_lock_radps`]). At a standstill the wheel's spin mode has the tyre's
/// rate too: the slip ratio's floor `v_κ` puts it at `2/dt` (`2.07/dt` with the
/// car's own inertia, default car), and the two add. RK4 is stable to 2.78/dt on
/// the real axis: with the lock's 0.5 on top the sum stays under it, so a car held
/// on its brakes on a slope settles (a larger lock rate let the RK4 step sit at a
/// spurious fixed point whose forces were not the car's).
pub const BRAKE_LOCK_RATE_DT: f64 = 0.5;

/// Torque acting on a wheel spinning at `omega_radps` (rad/s) for the commanded
/// torque `torque_nm` (N·m) and the tyre's rolling-resistance moment `rolling_nm`
/// (N·m, ≥ 0), with the step `dt_s` (s) and the wheel's inertia (kg·m²): a drive
/// torque as is; a brake torque (negative) and the rolling resistance against the
/// rotation, fading linearly below the lock speed of their sum
/// ([`brake_lock_radps`]). Returns the net torque and the rolling resistance's
/// part of it (≤ 0 rolling forward), N·m.
pub fn wheel_torque_nm(
    torque_nm: f64,
    rolling_nm: f64,
    omega_radps: f64,
    dt_s: f64,
    wheel_inertia_kg_m2: f64,
) -> (f64, f64) {
    let friction_nm = rolling_nm + (-torque_nm).max(0.0);
    let lock = brake_lock_radps(friction_nm, dt_s, wheel_inertia_kg_m2);
    let against = (omega_radps / lock).clamp(-1.0, 1.0);
    (
        torque_nm.max(0.0) - friction_nm * against,
        -rolling_nm * against,
    )
}

/// Number of scalar states.
pub const N: usize = 14;

/// State of the plant. Positions in the ground frame, velocities in the vehicle frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct State {
    /// Ground-frame position `X` of the centre of gravity, m.
    pub x_m: f64,
    /// Ground-frame position `Y` of the centre of gravity, m.
    pub y_m: f64,
    /// Yaw angle `ψ`, rad (counter-clockwise from the ground X axis).
    pub psi_rad: f64,
    /// Longitudinal speed `V_x` of the centre of gravity, vehicle frame, m/s.
    pub vx_mps: f64,
    /// Lateral speed `V_y` of the centre of gravity, vehicle frame (left), m/s.
    pub vy_mps: f64,
    /// Yaw rate `ψ̇`, rad/s (counter-clockwise positive).
    pub yaw_rate_radps: f64,
    /// Roll angle `θ` of the carbody, rad (positive: left side up).
    pub roll_rad: f64,
    /// Roll rate `θ̇`, rad/s.
    pub roll_rate_radps: f64,
    /// Pitch angle `φ` of the carbody, rad (positive: nose down).
    pub pitch_rad: f64,
    /// Pitch rate `φ̇`, rad/s.
    pub pitch_rate_radps: f64,
    /// Wheel spin rates `ω_i` `[fl, fr, rl, rr]`, rad/s (positive rolling forward).
    pub omega_radps: [f64; 4],
}

impl State {
    /// At rest at the origin, heading along X.
    pub fn at_rest() -> Self {
        Self::default()
    }

    /// At the origin heading along X at speed `speed_mps` (m/s), straight, with the
    /// wheels rolling freely (`ω = V/r_eff`).
    pub fn at_speed(speed_mps: f64, params: &VehicleParams) -> Self {
        let w = speed_mps / params.r_eff_m;
        Self {
            vx_mps: speed_mps,
            omega_radps: [w; 4],
            ..Self::default()
        }
    }

    /// The state as one array, in the order of the fields: `X`, `Y` (m), `ψ` (rad),
    /// `v_x`, `v_y` (m/s), yaw rate (rad/s), roll (rad), roll rate (rad/s), pitch
    /// (rad), pitch rate (rad/s), the four wheel speeds (rad/s, FL, FR, RL, RR).
    pub fn to_array(self) -> [f64; N] {
        let w = self.omega_radps;
        [
            self.x_m,
            self.y_m,
            self.psi_rad,
            self.vx_mps,
            self.vy_mps,
            self.yaw_rate_radps,
            self.roll_rad,
            self.roll_rate_radps,
            self.pitch_rad,
            self.pitch_rate_radps,
            w[0],
            w[1],
            w[2],
            w[3],
        ]
    }

    fn from_array(a: &[f64; N]) -> Self {
        Self {
            x_m: a[0],
            y_m: a[1],
            psi_rad: a[2],
            vx_mps: a[3],
            vy_mps: a[4],
            yaw_rate_radps: a[5],
            roll_rad: a[6],
            roll_rate_radps: a[7],
            pitch_rad: a[8],
            pitch_rate_radps: a[9],
            omega_radps: [a[10], a[11], a[12], a[13]],
        }
    }

    /// Speed of the centre of gravity over the ground, m/s.
    pub fn speed_mps(&self) -> f64 {
        self.vx_mps.hypot(self.vy_mps)
    }
}

/// Inputs of the plant, held constant over a step: the commands to its actuators.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Inputs {
    /// Torque commanded on each wheel `[fl, fr, rl, rr]`, N·m: positive drives forward,
    /// negative is a brake torque of that magnitude, acting against the wheel's
    /// rotation (it stops a wheel, it never spins it backwards; see the module doc).
    pub torque_nm: [f64; 4],
    /// Steering angle of both front wheels, rad (positive to the left). The
    /// steering actuator holds it within the vehicle's `max_steer_rad`.
    pub delta_rad: f64,
}

/// The road under the car over a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoadUnder {
    /// Road friction under each wheel `[fl, fr, rl, rr]`, dimensionless, ≥ 0.
    pub mu: [f64; 4],
    /// The road's grade angle `γ` along the vehicle's `x` axis, rad, in
    /// `(−π/4, π/4)` (positive: the road rises ahead of the car; a grade of
    /// `100·tan γ` %).
    pub grade_rad: f64,
}

impl RoadUnder {
    /// A level road of friction `mu` under every wheel.
    pub fn level(mu: f64) -> Self {
        Self {
            mu: [mu; 4],
            grade_rad: 0.0,
        }
    }
}

/// Quantities of the plant at the current state (with the last inputs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Outputs {
    /// Simulated time, s.
    pub time_s: f64,
    /// Steering angle applied over the last step (the steering actuator's output,
    /// within the mechanical limit), rad.
    pub delta_rad: f64,
    /// Wheel torques applied over the last step `[fl, fr, rl, rr]` (the torque
    /// actuators' outputs), N·m.
    pub torque_nm: [f64; 4],
    /// Normal loads `F_zi`, N (never negative).
    pub fz_n: [f64; 4],
    /// Wheels whose load would be negative or zero (lifted off the road).
    pub wheel_lifted: [bool; 4],
    /// Slip ratios `τ_xi` (the paper's definition, floored), dimensionless.
    pub kappa: [f64; 4],
    /// Slip angles `α_i`, rad (positive when the wheel points left of its velocity).
    pub alpha_rad: [f64; 4],
    /// Longitudinal tyre forces in the tyre frame `F_xpi`, N.
    pub fxp_n: [f64; 4],
    /// Lateral tyre forces in the tyre frame `F_ypi`, N.
    pub fyp_n: [f64; 4],
    /// Longitudinal tyre forces in the (horizontal) vehicle frame `F_xi`, N.
    pub fx_n: [f64; 4],
    /// Lateral tyre forces in the (horizontal) vehicle frame `F_yi`, N.
    pub fy_n: [f64; 4],
    /// Aerodynamic drag force (positive opposes forward motion), N.
    pub aero_drag_n: f64,
    /// Rolling resistance of each tyre `[fl, fr, rl, rr]`: its wheel's
    /// rolling-resistance moment over `r_eff` (positive opposes rolling forward), N;
    /// `C_rr·F_zi` while the wheel turns, fading to 0 as it stops.
    pub rolling_resistance_n: [f64; 4],
    /// The road's grade angle `γ` along the vehicle's `x` axis over the last step,
    /// rad (positive: the road rises ahead).
    pub grade_rad: f64,
    /// Longitudinal acceleration of the centre of gravity along the vehicle's `x`
    /// axis, `(ΣF_x − F_aero)/M_T − g·sin γ`, m/s² (the rate of change of `V_x` less
    /// `ψ̇·V_y`).
    pub ax_mps2: f64,
    /// Longitudinal specific force at the centre of gravity, `(ΣF_x − F_aero)/M_T`,
    /// m/s²: what an accelerometer on the car reads along its `x` axis, the
    /// acceleration [`Outputs::ax_mps2`] plus `g·sin γ` (zero for a car at rest on
    /// the level, `g·sin γ` for one held at rest on a grade).
    pub specific_force_x_mps2: f64,
    /// Lateral acceleration at the centre of gravity, `V̇_y + ψ̇·V_x = ΣF_y/M_T`, m/s²
    /// (positive to the left).
    pub ay_mps2: f64,
    /// Speed of the centre of gravity, m/s.
    pub speed_mps: f64,
    /// Vehicle side-slip angle at the centre of gravity `atan2(V_y, V_x)`, rad.
    pub beta_rad: f64,
}

/// Why the plant refused to start or to step.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlantError {
    /// The vehicle parameters are unusable (the field and the reason in the
    /// message; not a `source()`, so a chain prints them once).
    #[error("invalid vehicle parameters: {0}")]
    Vehicle(InvalidField),
    /// The step is not a positive number of at most 10 ms.
    #[error("integration step dt = {0} s: must be positive and at most 0.01 s")]
    Step(f64),
    /// A field of the initial state is not finite.
    #[error("initial state field \"{0}\" is not a finite number")]
    State(&'static str),
    /// An input is not finite.
    #[error("input {0} is not a finite number")]
    Input(&'static str),
    /// The road friction is not a finite number ≥ 0.
    #[error("road friction mu = {0}: must be a finite number, zero or positive")]
    Mu(f64),
    /// The road's grade angle is not a finite number of magnitude under π/4.
    #[error(
        "road grade angle {0} rad: must be a finite number in (-pi/4, pi/4) (a grade under 100 %)"
    )]
    Grade(f64),
    /// The state stopped being finite.
    #[error(
        "the simulation diverged (non-finite state) at t = {0} s; use a smaller step or \
         check the vehicle file"
    )]
    Diverged(f64),
}

impl From<InvalidField> for PlantError {
    fn from(e: InvalidField) -> Self {
        PlantError::Vehicle(e)
    }
}

/// Constants derived once from the parameters.
#[derive(Clone, Copy, Debug)]
struct Derived {
    fz0: [f64; 4],
    pitch_static_nm: f64,
    x_w: [f64; 4],
    y_w: [f64; 4],
    alpha_floor_mps: f64,
    kappa_floor_per_k: f64,
    aero: f64,
    /// `C_rr·r_eff`: the rolling-resistance moment per unit load, m.
    rolling_m: f64,
}

/// What the derivative needs from the inputs, computed once per step (the inputs
/// are held over the step).
#[derive(Clone, Copy, Debug)]
struct StepInputs {
    /// Steering angle (clamped), rad.
    delta_rad: f64,
    /// `sin δ_i`, `cos δ_i` of each wheel (`δ` front, 0 rear).
    sin_cos_delta: [(f64, f64); 4],
    /// Wheel torques applied, N·m.
    torque_nm: [f64; 4],
    /// Road friction under each wheel `[fl, fr, rl, rr]`.
    mu: [f64; 4],
    /// The road's grade angle `γ`, rad.
    grade_rad: f64,
    /// `sin γ`, `cos γ`.
    sin_cos_grade: (f64, f64),
}

/// Wheel lift seen by the plant since it started.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WheelLift {
    /// Simulated time during which at least one wheel was lifted, s (whole steps: a
    /// step counts when any of its RK4 stages saw a lifted wheel).
    pub lifted_s: f64,
    /// Earliest time at which a wheel was lifted, s (the time of the RK4 stage that
    /// first saw it); `None` if no wheel ever lifted.
    pub first_lift_s: Option<f64>,
    /// Number of lifts: steps with a lifted wheel after a step with none.
    pub count: u64,
    /// The wheels lifted in the last step (any stage), `[fl, fr, rl, rr]`.
    pub last_step: [bool; 4],
}

/// The 9-DoF plant.
#[derive(Clone, Debug)]
pub struct Plant {
    params: VehicleParams,
    derived: Derived,
    state: State,
    dt_s: f64,
    time_s: f64,
    /// What the actuators applied over the last step.
    last_inputs: Inputs,
    actuators: Actuators,
    road: RoadUnder,
    lift: WheelLift,
}

impl Plant {
    /// A plant stepping at [`DEFAULT_DT_S`] from `initial`.
    pub fn new(params: VehicleParams, initial: State) -> Result<Self, PlantError> {
        Self::with_step(params, initial, DEFAULT_DT_S)
    }

    /// A plant stepping at `dt_s` (s, at most 0.01) from `initial`.
    pub fn with_step(params: VehicleParams, initial: State, dt_s: f64) -> Result<Self, PlantError> {
        params.validate()?;
        if !(dt_s > 0.0 && dt_s <= 0.01) {
            return Err(PlantError::Step(dt_s));
        }
        check_state(&initial)?;
        let p = &params;
        let fz0 = p.static_loads_n();
        let pitch_static_nm = p.lr_m * (fz0[RL] + fz0[RR]) - p.lf_m * (fz0[FL] + fz0[FR]);
        let c_alpha = p.tyre.max_cornering_stiffness_n_per_rad();
        let l2 = p.lf_m.max(p.lr_m).powi(2);
        let alpha_stab = dt_s * c_alpha * (4.0 / p.mass_kg + 4.0 * l2 / p.iz_kg_m2) / 2.0;
        let derived = Derived {
            fz0,
            pitch_static_nm,
            x_w: [p.lf_m, p.lf_m, -p.lr_m, -p.lr_m],
            y_w: [p.lw_m, -p.lw_m, p.lw_m, -p.lw_m],
            alpha_floor_mps: p.low_speed_mps.max(alpha_stab),
            kappa_floor_per_k: dt_s * p.r_eff_m * p.r_eff_m / (2.0 * p.wheel_inertia_kg_m2),
            aero: 0.5 * p.rho_air_kg_per_m3 * p.cx * p.frontal_area_m2,
            rolling_m: p.crr * p.r_eff_m,
        };
        Ok(Self {
            params,
            derived,
            state: initial,
            dt_s,
            time_s: 0.0,
            last_inputs: Inputs::default(),
            actuators: Actuators::new(&p.actuators, p.max_steer_rad, dt_s),
            road: RoadUnder::level(1.0),
            lift: WheelLift::default(),
        })
    }

    /// Advances one step `dt` with `inputs` held constant on a road of friction `mu`.
    /// On error the state is left as it was before the call.
    pub fn step(&mut self, inputs: &Inputs, mu: f64) -> Result<(), PlantError> {
        self.step_on(inputs, [mu; 4])
    }

    /// As [`Plant::step`], each wheel `[fl, fr, rl, rr]` on a road of its own
    /// friction `mu` (friction that changes along the road), level.
    pub fn step_on(&mut self, inputs: &Inputs, mu: [f64; 4]) -> Result<(), PlantError> {
        self.step_on_road(inputs, &RoadUnder { mu, grade_rad: 0.0 })
    }

    /// As [`Plant::step`] on the road `road`: each wheel's friction and the road's
    /// grade along the car.
    pub fn step_on_road(&mut self, inputs: &Inputs, road: &RoadUnder) -> Result<(), PlantError> {
        let mu = road.mu;
        for (i, t) in inputs.torque_nm.iter().enumerate() {
            if !t.is_finite() {
                return Err(PlantError::Input(
                    [
                        "torque_nm[0] (fl)",
                        "torque_nm[1] (fr)",
                        "torque_nm[2] (rl)",
                        "torque_nm[3] (rr)",
                    ][i],
                ));
            }
        }
        if !inputs.delta_rad.is_finite() {
            return Err(PlantError::Input("delta_rad"));
        }
        if let Some(&bad) = mu.iter().find(|m| !(**m >= 0.0 && m.is_finite())) {
            return Err(PlantError::Mu(bad));
        }
        if !road.grade_rad.is_finite() || road.grade_rad.abs() >= core::f64::consts::FRAC_PI_4 {
            return Err(PlantError::Grade(road.grade_rad));
        }
        let command = (inputs.delta_rad, inputs.torque_nm);
        let applied = self.actuators.peek(command.0, command.1);
        let inp = Inputs {
            torque_nm: applied.1,
            delta_rad: applied.0,
        };
        let si = self.step_inputs(&inp, road);
        let h = self.dt_s;
        let y0 = self.state.to_array();
        let (k1, l1) = self.derivative(&y0, &si);
        let (k2, l2) = self.derivative(&axpy(&y0, 0.5 * h, &k1), &si);
        let (k3, l3) = self.derivative(&axpy(&y0, 0.5 * h, &k2), &si);
        let (k4, l4) = self.derivative(&axpy(&y0, h, &k3), &si);
        let mut y = y0;
        for i in 0..N {
            y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        if y.iter().any(|v| !v.is_finite()) {
            return Err(PlantError::Diverged(self.time_s + h));
        }
        self.record_lift([(l1, 0.0), (l2, 0.5 * h), (l3, 0.5 * h), (l4, h)]);
        self.state = State::from_array(&y);
        self.time_s += h;
        self.last_inputs = inp;
        self.actuators.commit(command, applied);
        self.road = *road;
        Ok(())
    }

    /// Updates the wheel-lift record with the lifted wheels seen at each RK4 stage
    /// (with the stage's time offset in the step, s).
    fn record_lift(&mut self, stages: [([bool; 4], f64); 4]) {
        let mut any = [false; 4];
        let mut first: Option<f64> = None;
        for (lifted, dt) in stages {
            for (a, l) in any.iter_mut().zip(lifted) {
                *a |= l;
            }
            if first.is_none() && lifted.iter().any(|&l| l) {
                first = Some(self.time_s + dt);
            }
        }
        let lift = &mut self.lift;
        if let Some(t) = first {
            if !lift.last_step.iter().any(|&l| l) {
                lift.count += 1;
            }
            lift.lifted_s += self.dt_s;
            lift.first_lift_s.get_or_insert(t);
        }
        lift.last_step = any;
    }

    /// The wheel lift seen since the plant started.
    pub fn wheel_lift(&self) -> &WheelLift {
        &self.lift
    }

    /// The current state.
    pub fn state(&self) -> &State {
        &self.state
    }

    /// The vehicle parameters.
    pub fn params(&self) -> &VehicleParams {
        &self.params
    }

    /// Integration step, s.
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Simulated time since the start, s.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Floor of the slip-angle denominator, m/s (see the module documentation).
    pub fn alpha_floor_mps(&self) -> f64 {
        self.derived.alpha_floor_mps
    }

    /// Floor of the slip-ratio denominator for a slip stiffness `k_n` (N), m/s.
    fn kappa_floor_for_stiffness(&self, k_n: f64) -> f64 {
        self.params
            .low_speed_mps
            .max(self.derived.kappa_floor_per_k * k_n)
    }

    /// Loads, slips, forces and accelerations at the current state with what the
    /// actuators applied and the road of the last step (zero torque, straight,
    /// `μ = 1`, level before any step).
    pub fn outputs(&self) -> Outputs {
        let y = self.state.to_array();
        let si = self.step_inputs(&self.last_inputs, &self.road);
        let mut o = Outputs::default();
        self.eval(&y, &si, Some(&mut o));
        o.time_s = self.time_s;
        o
    }

    /// The per-step part of the derivative for the (clamped) inputs `inp`.
    fn step_inputs(&self, inp: &Inputs, road: &RoadUnder) -> StepInputs {
        let front = inp.delta_rad.sin_cos();
        let rear = (0.0, 1.0);
        StepInputs {
            delta_rad: inp.delta_rad,
            sin_cos_delta: [front, front, rear, rear],
            torque_nm: inp.torque_nm,
            mu: road.mu,
            grade_rad: road.grade_rad,
            sin_cos_grade: road.grade_rad.sin_cos(),
        }
    }

    /// State derivative at `y` and the wheels lifted there.
    fn derivative(&self, y: &[f64; N], si: &StepInputs) -> ([f64; N], [bool; 4]) {
        self.eval(y, si, None)
    }

    /// State derivative at `y` and the wheels lifted there; fills `out` if given.
    #[allow(clippy::needless_range_loop)] // four wheels, several arrays indexed alike
    fn eval(
        &self,
        y: &[f64; N],
        si: &StepInputs,
        out: Option<&mut Outputs>,
    ) -> ([f64; N], [bool; 4]) {
        let p = &self.params;
        let d = &self.derived;
        let s = State::from_array(y);
        let (st, ct) = s.roll_rad.sin_cos();
        let (sp, cp) = s.pitch_rad.sin_cos();
        let r = s.yaw_rate_radps;
        let (s_grade, c_grade) = si.sin_cos_grade;
        let mut w = [Wheel::default(); 4];
        for i in 0..4 {
            let side = if d.y_w[i] > 0.0 { 1.0 } else { -1.0 };
            // Suspension extension and its rate.
            let zeta = side * p.lw_m * st - d.x_w[i] * sp;
            let zeta_dot =
                side * p.lw_m * ct * s.roll_rate_radps - d.x_w[i] * cp * s.pitch_rate_radps;
            let fz_spring = d.fz0[i] * c_grade - p.ks_n_per_m * zeta - p.ds_n_s_per_m * zeta_dot;
            // Wheel-centre velocity, vehicle frame then tyre frame.
            let vxw = s.vx_mps - d.y_w[i] * r;
            let vyw = s.vy_mps + d.x_w[i] * r;
            let (sdi, cdi) = si.sin_cos_delta[i];
            let vxp = vxw * cdi + vyw * sdi;
            let vyp = -vxw * sdi + vyw * cdi;
            w[i] = self.wheel(i, side, fz_spring, vxp, vyp, s.omega_radps[i], si);
        }
        let aero = d.aero * s.vx_mps * s.vx_mps.abs();
        let m = p.mass_kg;
        let sum_fx = w[0].fx + w[1].fx + w[2].fx + w[3].fx;
        let sum_fy = w[0].fy + w[1].fy + w[2].fy + w[3].fy;
        let specific_x = (sum_fx - aero) / m;
        let ax = specific_x - G * s_grade;
        let dvx = r * s.vy_mps + ax;
        let dvy = -r * s.vx_mps + sum_fy / m;
        let dr = (p.lf_m * (w[FL].fy + w[FR].fy) - p.lr_m * (w[RL].fy + w[RR].fy)
            + p.lw_m * ((w[FR].fx - w[FL].fx) + (w[RR].fx - w[RL].fx)))
            / p.iz_kg_m2;
        // The loads' moments with the arms `l_w·cos θ`, `x_i·cos φ` (see the module doc).
        let droll = (p.lw_m * ct * ((w[FL].fz - w[FR].fz) + (w[RL].fz - w[RR].fz))
            + p.h_m * sum_fy)
            / p.ix_kg_m2;
        let dpitch = (cp
            * (p.lr_m * (w[RL].fz + w[RR].fz)
                - p.lf_m * (w[FL].fz + w[FR].fz)
                - d.pitch_static_nm * c_grade)
            - p.h_m * sum_fx)
            / p.iy_kg_m2;
        let (spsi, cpsi) = s.psi_rad.sin_cos();
        let dy = [
            s.vx_mps * c_grade * cpsi - s.vy_mps * spsi,
            s.vx_mps * c_grade * spsi + s.vy_mps * cpsi,
            r,
            dvx,
            dvy,
            dr,
            s.roll_rate_radps,
            droll,
            s.pitch_rate_radps,
            dpitch,
            w[0].domega,
            w[1].domega,
            w[2].domega,
            w[3].domega,
        ];
        let lifted = w.map(|x| x.lifted);
        if let Some(o) = out {
            *o = Outputs {
                time_s: o.time_s,
                delta_rad: si.delta_rad,
                torque_nm: si.torque_nm,
                fz_n: w.map(|x| x.fz),
                wheel_lifted: lifted,
                kappa: w.map(|x| x.kappa),
                alpha_rad: w.map(|x| x.alpha),
                fxp_n: w.map(|x| x.fxp),
                fyp_n: w.map(|x| x.fyp),
                fx_n: w.map(|x| x.fx),
                fy_n: w.map(|x| x.fy),
                aero_drag_n: aero,
                rolling_resistance_n: w.map(|x| x.rolling_nm / -p.r_eff_m),
                grade_rad: si.grade_rad,
                ax_mps2: ax,
                specific_force_x_mps2: specific_x,
                ay_mps2: sum_fy / m,
                speed_mps: s.speed_mps(),
                beta_rad: s.vy_mps.atan2(s.vx_mps),
            };
        }
        (dy, lifted)
    }

    /// One wheel: its load from the suspension force `fz_spring` (N), its slips from
    /// the wheel-centre velocity `(vxp, vyp)` in the tyre frame (m/s) and its spin
    /// `omega` (rad/s), its tyre forces and its spin acceleration.
    #[allow(clippy::too_many_arguments)]
    fn wheel(
        &self,
        i: usize,
        side: f64,
        fz_spring: f64,
        vxp: f64,
        vyp: f64,
        omega: f64,
        si: &StepInputs,
    ) -> Wheel {
        let p = &self.params;
        let d = &self.derived;
        let lifted = fz_spring <= 0.0;
        let fz = fz_spring.max(0.0);
        let at = tire::AtLoad::new(fz, si.mu[i], &p.tyre);
        // Slip ratio (paper's definition, floored denominators).
        let rw = p.r_eff_m * omega;
        let k = match at {
            Some(a) => a.slip_stiffness_n(),
            None => p.tyre.longitudinal_slip_stiffness_n(fz),
        };
        let v_k = self.kappa_floor_for_stiffness(k);
        let kappa = if rw >= vxp {
            (rw - vxp) / rw.abs().max(v_k)
        } else {
            (rw - vxp) / vxp.abs().max(v_k)
        };
        let alpha = -(vyp / vxp.abs().max(d.alpha_floor_mps)).atan();
        let fade = offset_fade(vxp, vyp, p.low_speed_mps);
        // Right-hand wheels carry the mirrored tyre.
        let (fxp, fyp) = match at {
            None => (0.0, 0.0),
            Some(at) if side > 0.0 => at.forces(kappa, alpha, fade),
            Some(at) => {
                let (fx, fy) = at.forces(kappa, -alpha, fade);
                (fx, -fy)
            }
        };
        // To the horizontal vehicle frame (see the derivation in the module doc).
        let (sdi, cdi) = si.sin_cos_delta[i];
        let fx = fxp * cdi - fyp * sdi;
        let fy = fyp * cdi + fxp * sdi;
        let (torque, rolling_nm) = wheel_torque_nm(
            si.torque_nm[i],
            d.rolling_m * fz,
            omega,
            self.dt_s,
            p.wheel_inertia_kg_m2,
        );
        let domega = (torque - p.r_eff_m * fxp) / p.wheel_inertia_kg_m2;
        Wheel {
            fz,
            lifted,
            kappa,
            alpha,
            fxp,
            fyp,
            fx,
            fy,
            domega,
            rolling_nm,
        }
    }
}

/// The tyre offsets' fade `min(1, V_wheel/low_speed)` for the wheel-centre velocity
/// `(vxp, vyp)` (m/s). When `max(|vxp|, |vyp|)` reaches the threshold it is 1 without
/// the `hypot` (the same value: `hypot(x, y) ≥ max(|x|, |y|)`).
fn offset_fade(vxp: f64, vyp: f64, low_speed_mps: f64) -> f64 {
    if vxp.abs().max(vyp.abs()) >= low_speed_mps {
        1.0
    } else {
        (vxp.hypot(vyp) / low_speed_mps).min(1.0)
    }
}

/// One wheel's quantities in an evaluation of the derivative.
#[derive(Clone, Copy, Debug, Default)]
struct Wheel {
    /// Normal load, N.
    fz: f64,
    /// The load would be negative or zero.
    lifted: bool,
    /// Slip ratio.
    kappa: f64,
    /// Slip angle, rad.
    alpha: f64,
    /// Tyre-frame forces, N.
    fxp: f64,
    fyp: f64,
    /// Vehicle-frame forces, N.
    fx: f64,
    fy: f64,
    /// Spin acceleration, rad/s².
    domega: f64,
    /// The rolling resistance's part of the wheel's torque, N·m (≤ 0 rolling forward).
    rolling_nm: f64,
}

/// `y + h·k`.
fn axpy(y: &[f64; N], h: f64, k: &[f64; N]) -> [f64; N] {
    let mut out = *y;
    for i in 0..N {
        out[i] += h * k[i];
    }
    out
}

fn check_state(s: &State) -> Result<(), PlantError> {
    let named = [
        ("x_m", s.x_m),
        ("y_m", s.y_m),
        ("psi_rad", s.psi_rad),
        ("vx_mps", s.vx_mps),
        ("vy_mps", s.vy_mps),
        ("yaw_rate_radps", s.yaw_rate_radps),
        ("roll_rad", s.roll_rad),
        ("roll_rate_radps", s.roll_rate_radps),
        ("pitch_rad", s.pitch_rad),
        ("pitch_rate_radps", s.pitch_rate_radps),
        ("omega_radps[0]", s.omega_radps[0]),
        ("omega_radps[1]", s.omega_radps[1]),
        ("omega_radps[2]", s.omega_radps[2]),
        ("omega_radps[3]", s.omega_radps[3]),
    ];
    for (n, v) in named {
        if !v.is_finite() {
            return Err(PlantError::State(n));
        }
    }
    Ok(())
}
