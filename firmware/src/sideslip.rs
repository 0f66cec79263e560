//! The sideslip lag: how far a real car's course falls behind the kinematic
//! bicycle's in a bend, estimated online, for the MPC's model.
//!
//! The kinematic bicycle (the paper's Equation 1) moves its centre of gravity at
//! `β(δ) = atan(tan δ·l_r/L)` from its heading. A real car's rear tyres need a slip
//! angle to carry their share of the lateral force, so in a bend its velocity
//! points further out, by about `λ·a_y` (`a_y` the lateral acceleration; for a
//! linear tyre `λ = m·l_f/(L·C_r)`, `C_r` the rear axle's cornering stiffness). A
//! plan that ignores it holds the right heading on a course that drifts outward,
//! and every new plan corrects it late: a heavy car with soft tyres ran 0.6 m off
//! the line in fast bends.
//!
//! The firmware knows neither `m` nor `C_r` well (a load, other tyres), so it
//! measures `λ`: each sample is the measured sideslip `v_y/v_x` less the kinematic
//! `k·tan δ` (`k = l_r/L`, the MPC's geometry), against the measured `a_y = V·ψ̇`;
//! `λ` is their least-squares slope through the origin with exponential forgetting,
//!
//! ```text
//! S_aa ← ρ·S_aa + a_y²        S_ab ← ρ·S_ab − a_y·(v_y/v_x − k·tan δ)
//! λ = clamp(S_ab / S_aa, 0, lag_max)
//! ```
//!
//! started from a prior of `prior_weight` samples at `λ = 0` (the kinematic
//! model). Samples count only from `min_speed_mps` and with `|a_y| ≥
//! min_lateral_mps2` (elsewhere the ratio is noise), and not while the tyres
//! are beyond their linear range (a sliding car is not the linear tyre `λ`
//! describes): the plan task passes a road found slipperier than configured and
//! the control task's [`crate::tasks::ControlTask::tyres_linear`] (a saturated or
//! sliding front, a slip event, a wheel spinning or locking within the last plan
//! period) as `slipping`. The
//! clamp keeps a transient (a rear that slides for a moment) from making the plan
//! steer into it: `lag_max` is 2.5 times what the heaviest car shipped learns
//! (`host-sim/vehicles/heavy.toml` 30 % over its mass: 0.012 rad per m/s² on
//! MexicoCity; the default car 0.009, the light one 0.008).

use crate::bicycle::BicycleGeometry;
use crate::state_estimate::StateEstimate;
use crate::Real;

/// Settings of the sideslip-lag estimate (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SideslipConfig<T> {
    /// Forgetting factor `ρ` per sample, in `(0, 1]` (0.98 at 10 Hz: a memory of
    /// about 5 s).
    pub forgetting: T,
    /// Prior weight, (m/s²)², > 0: `S_aa`'s start (`S_ab` starts at 0, `λ = 0`).
    pub prior_weight: T,
    /// Samples count from this speed, m/s.
    pub min_speed_mps: T,
    /// Samples count from this lateral acceleration, m/s².
    pub min_lateral_mps2: T,
    /// Largest lag `λ`, rad per m/s², ≥ 0 (0: the kinematic model always).
    pub lag_max: T,
}

impl<T: Real> SideslipConfig<T> {
    /// The shipped settings: `ρ` 0.98 (10 Hz), a prior of 10 samples at 2 m/s²,
    /// samples from 10 m/s and 1.5 m/s², `λ` at most 0.03 rad per m/s² (0.12 rad
    /// at 4 m/s²).
    pub fn shipped() -> Self {
        Self {
            forgetting: T::lit(0.98),
            prior_weight: T::lit(40.0),
            min_speed_mps: T::lit(10.0),
            min_lateral_mps2: T::lit(1.5),
            lag_max: T::lit(0.03),
        }
    }

    /// True when every field is finite and in its range.
    pub fn is_valid(&self) -> bool {
        let f = |x: T| x.is_finite();
        f(self.forgetting)
            && self.forgetting > T::ZERO
            && self.forgetting <= T::ONE
            && f(self.prior_weight)
            && self.prior_weight > T::ZERO
            && f(self.min_speed_mps)
            && self.min_speed_mps > T::ZERO
            && f(self.min_lateral_mps2)
            && self.min_lateral_mps2 >= T::ZERO
            && f(self.lag_max)
            && self.lag_max >= T::ZERO
    }
}

/// The running estimate of the sideslip lag `λ` (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SideslipLag<T> {
    /// `S_aa`, (m/s²)².
    s_aa: T,
    /// `S_ab`, rad·m/s².
    s_ab: T,
    /// Samples that counted (saturating).
    samples: u32,
}

impl<T: Real> SideslipLag<T> {
    /// No sample yet: `S_aa = 0`, read as the prior (`λ = 0`) until the first sample.
    pub const fn new() -> Self {
        Self {
            s_aa: T::ZERO,
            s_ab: T::ZERO,
            samples: 0,
        }
    }

    /// One sample of the estimate `est` of a car of `geometry` (module docs);
    /// `slipping`: the friction check flags a slip. Returns true when it counted.
    /// A non-finite estimate (or geometry) does not count.
    pub fn update(
        &mut self,
        cfg: &SideslipConfig<T>,
        geometry: &BicycleGeometry<T>,
        est: &StateEstimate<T>,
        slipping: bool,
    ) -> bool {
        let vx = est.vx_mps;
        let ay = vx * est.yaw_rate_radps;
        let k = geometry.l_r_m / geometry.wheelbase_m();
        let b = est.vy_mps / vx - k * est.delta_rad.tan();
        let counts = !slipping
            && vx >= cfg.min_speed_mps
            && ay.abs() >= cfg.min_lateral_mps2
            && ay.is_finite()
            && b.is_finite();
        if !counts {
            return false;
        }
        if self.samples == 0 {
            self.s_aa = cfg.prior_weight;
        }
        self.s_aa = cfg.forgetting * self.s_aa + ay * ay;
        self.s_ab = cfg.forgetting * self.s_ab - ay * b;
        self.samples = self.samples.saturating_add(1);
        true
    }

    /// The lag `λ`, rad per m/s², in `[0, lag_max]` (0 before the first sample).
    pub fn lag(&self, cfg: &SideslipConfig<T>) -> T {
        if self.samples == 0 {
            return T::ZERO;
        }
        (self.s_ab / self.s_aa).clamp(T::ZERO, cfg.lag_max)
    }

    /// Samples that counted so far (saturating).
    pub fn samples(&self) -> u32 {
        self.samples
    }
}

impl<T: Real> Default for SideslipLag<T> {
    fn default() -> Self {
        Self::new()
    }
}
