//! Disturbances between the plant and the firmware: sensor noise, a delayed state
//! estimate, a sensor dropout, a steering actuator rate limit and an obstacle the
//! sensors see late, described here; the closed loop's `DisturbedEcu` wraps the modelled
//! ECU and applies them at its boundary, so the closed-loop driver runs unchanged.
//!
//! # The estimate the tasks see, every 10 ms
//!
//! 1. **Noise** (measured at the instant): independent Gaussian draws added to the
//!    true state, standard deviations `scale ×` [`NOISE_UNIT`]: position X and Y
//!    0.05 m each, heading 0.005 rad (0.29°), longitudinal speed 0.05 m/s, yaw rate
//!    0.005 rad/s, lateral speed 0.02 m/s (an RTK-GNSS/INS estimate), each
//!    wheel's speed 0.03 m/s (an ABS tone wheel's count over 10 ms, from a
//!    stream of its own: the other channels' draws are those without it), the
//!    accelerometer's specific force along the car 0.02 m/s² (a MEMS IMU's
//!    white noise over 10 ms and the body's vibration, from a stream of its
//!    own too). The lateral
//!    speed and the yaw rate (what the plan task's sideslip learner reads) also
//!    carry a **bias**, constant over the run and drawn once from its seed
//!    ([`estimate_biases`]), of standard deviation `scale ×` 0.02 m/s and
//!    0.002 rad/s (0.11°/s, a MEMS gyro's after its start-up calibration; 0.46°/s
//!    at `high`, one without it); the specific force a bias of `scale ×`
//!    0.02 m/s² (2 mg, a MEMS accelerometer's after calibration), drawn after
//!    those two. The measured steering angle is not disturbed.
//!    Level 0 (`--noise none`, the default) draws nothing.
//! 2. **Delay**: the tasks see the (noisy) estimate measured `delay` ago, rounded
//!    to whole control periods (10 ms), stamped with its measurement time, as an
//!    estimator with latency would deliver it. Before that much history exists they
//!    see the oldest estimate.
//! 3. **Dropout**: from [`Dropout::start_us`] for [`Dropout::periods`] control
//!    periods, either every field NaN ([`DropoutKind::Nan`]) or no update (the last
//!    estimate delivered before the dropout, stamp and all, [`DropoutKind::Hold`]).
//!
//! # The actuators
//!
//! A steering rate limit `R` (rad/s) lets the applied angle move at most
//! `R × 10 ms` from the previous applied angle at each control period; the plant
//! receives the limited angle (and measures it back in the estimate), the firmware
//! does not know of the limit.
//!
//! # The late obstacle
//!
//! An obstacle of the scenario that the planner is given only when the car (its
//! true position, projected on the reference path) is [`LateObstacle::appear_m`]
//! or less before it along the path; the plant and the collision check have it
//! from the start.
//!
//! Every random draw comes from [`SplitMix64`] seeded by the run, so a run is
//! reproducible bit for bit.

use firmware::tasks::CONTROL_PERIOD_US;

/// Standard deviations of noise level 1 (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseSigmas {
    /// Position X and Y, each, m.
    pub position_m: f64,
    /// Heading, rad.
    pub heading_rad: f64,
    /// Longitudinal speed, m/s.
    pub speed_mps: f64,
    /// Yaw rate, rad/s.
    pub yaw_rate_radps: f64,
    /// Lateral speed, m/s.
    pub lateral_speed_mps: f64,
    /// The lateral speed's bias over a run, m/s.
    pub lateral_speed_bias_mps: f64,
    /// The yaw rate's bias over a run, rad/s.
    pub yaw_rate_bias_radps: f64,
    /// Each wheel's speed `ω·r_eff`, m/s.
    pub wheel_speed_mps: f64,
    /// The accelerometer's specific force along the car, m/s².
    pub specific_force_mps2: f64,
    /// The specific force's bias over a run, m/s².
    pub specific_force_bias_mps2: f64,
}

/// Noise level 1: an RTK-GNSS/INS-grade estimate.
pub const NOISE_UNIT: NoiseSigmas = NoiseSigmas {
    position_m: 0.05,
    heading_rad: 0.005,
    speed_mps: 0.05,
    yaw_rate_radps: 0.005,
    lateral_speed_mps: 0.02,
    lateral_speed_bias_mps: 0.02,
    yaw_rate_bias_radps: 0.002,
    wheel_speed_mps: 0.03,
    specific_force_mps2: 0.02,
    specific_force_bias_mps2: 0.02,
};

/// The biases of a run's estimate (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EstimateBias {
    /// Added to the lateral speed, m/s.
    pub lateral_speed_mps: f64,
    /// Added to the yaw rate, rad/s.
    pub yaw_rate_radps: f64,
    /// Added to the specific force, m/s².
    pub specific_force_mps2: f64,
}

/// The biases of a run of seed `seed` at noise level `scale` (0: none, nothing
/// drawn): Gaussian, of standard deviation `scale ×` the level-1 biases, from a
/// stream of their own (the other channels' draws are not moved by them).
pub fn estimate_biases(seed: u64, scale: f64) -> EstimateBias {
    if scale <= 0.0 {
        return EstimateBias::default();
    }
    let mut rng = SplitMix64::new(seed ^ BIAS_STREAM);
    EstimateBias {
        lateral_speed_mps: scale * NOISE_UNIT.lateral_speed_bias_mps * rng.gaussian(),
        yaw_rate_radps: scale * NOISE_UNIT.yaw_rate_bias_radps * rng.gaussian(),
        specific_force_mps2: scale * NOISE_UNIT.specific_force_bias_mps2 * rng.gaussian(),
    }
}

/// Mixed into a run's seed for the estimate's noise (the first channels').
pub const NOISE_STREAM: u64 = 0x6E6F_6973_6521;

/// Mixed into a run's seed for the lateral speed's noise.
pub const LATERAL_NOISE_STREAM: u64 = 0x6C61_7465_7261_6C21;

/// Mixed into a run's seed for the wheel speeds' noise.
pub const WHEEL_NOISE_STREAM: u64 = 0x7768_6565_6c73_2121;

/// Mixed into a run's seed for the accelerometer's noise.
pub const ACCEL_NOISE_STREAM: u64 = 0x6163_6365_6c21;
/// Mixed into a run's seed for the biases.
pub const BIAS_STREAM: u64 = 0x6269_6173_6573_2121;

/// A noise level: a multiple of [`NOISE_UNIT`] (`--noise`: `none` 0, `low` 1,
/// `medium` 2, `high` 4, or a number ≥ 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseLevel(pub f64);

impl std::str::FromStr for NoiseLevel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let k = match s {
            "none" => 0.0,
            "low" => 1.0,
            "medium" => 2.0,
            "high" => 4.0,
            _ => s.parse::<f64>().map_err(|_| {
                format!("noise level {s:?}: none, low, medium, high or a number ≥ 0")
            })?,
        };
        if !(k.is_finite() && k >= 0.0) {
            return Err(format!("noise level {s:?} must be a number ≥ 0"));
        }
        Ok(NoiseLevel(k))
    }
}

/// Checks a delay of the estimate given on the command line (`--delay-ms`), ms.
pub fn check_delay_ms(d: f64) -> Result<(), String> {
    if !(d.is_finite() && (0.0..=1000.0).contains(&d)) {
        return Err(format!("--delay-ms wants delays in [0, 1000] ms, got {d}"));
    }
    Ok(())
}

/// The seed of a run's random draws from its track's name and a seed number (FNV-1a
/// of the name, mixed with the number): the same noise on a track across frictions,
/// vehicles and faults, and `run` with a sweep run's factors replays it.
pub fn run_seed(track_name: &str, seed: u32) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in track_name.bytes() {
        h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
    }
    h ^ u64::from(seed).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// A small, fast, reproducible pseudo-random generator (SplitMix64, Steele et al.
/// 2014); its output depends only on the seed, on every platform.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal (Box–Muller; one draw of the pair).
    pub fn gaussian(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]: ln is finite
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// How a dropout corrupts the estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DropoutKind {
    /// Every field NaN.
    Nan,
    /// No update: the last estimate before the dropout, again.
    Hold,
}

/// A sensor dropout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dropout {
    /// First control instant affected, µs.
    pub start_us: u64,
    /// Control periods affected.
    pub periods: u32,
    /// NaN or no update.
    pub kind: DropoutKind,
    /// The windows of the road given during the dropout reach the planner only
    /// after it, at its first period: a link fault's refused sensor frames (the
    /// ECU learns of the route frames from the frames it accepts); false for the
    /// estimator's dropouts (`--fault dropout-*`), where the road arrives on time.
    pub withholds_route: bool,
}

impl Dropout {
    /// Whether the dropout is under way at `t_us`, µs.
    pub fn covers(&self, t_us: u64) -> bool {
        t_us >= self.start_us && t_us < self.start_us + u64::from(self.periods) * CONTROL_PERIOD_US
    }
}

/// An obstacle of the scenario that the planner learns of late.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LateObstacle {
    /// Its index in the scenario's obstacles.
    pub index: usize,
    /// Distance along the path before it at which the planner is given it, m.
    pub appear_m: f64,
}

/// Everything done to the firmware's inputs and outputs at the ECU's boundary.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Disturbances {
    /// Noise level (multiplies [`NOISE_UNIT`]); 0 for none.
    pub noise_scale: f64,
    /// Estimate delay, ms (rounded to whole 10 ms control periods).
    pub delay_ms: f64,
    /// A sensor dropout, if any.
    pub dropout: Option<Dropout>,
    /// Steering actuator rate limit, rad/s, if any.
    pub steer_rate_limit_radps: Option<f64>,
    /// An obstacle seen late, if any.
    pub late_obstacle: Option<LateObstacle>,
    /// Seed of the noise.
    pub seed: u64,
}

impl Disturbances {
    /// The delay in whole control periods.
    pub fn delay_periods(&self) -> usize {
        (self.delay_ms * 1e3 / CONTROL_PERIOD_US as f64)
            .round()
            .max(0.0) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix_is_reproducible_and_gaussian_has_unit_variance() {
        let mut a = SplitMix64::new(7);
        let mut b = SplitMix64::new(7);
        assert_eq!(a.next_u64(), b.next_u64());
        let n = 20_000;
        let xs: Vec<f64> = (0..n).map(|_| a.gaussian()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.03, "mean {mean}");
        assert!((var - 1.0).abs() < 0.05, "variance {var}");
    }

    #[test]
    fn biases_are_drawn_once_per_seed_with_the_levels_spread() {
        let a = estimate_biases(run_seed("Spielberg", 3), 4.0);
        assert_eq!(a, estimate_biases(run_seed("Spielberg", 3), 4.0));
        assert_ne!(a, estimate_biases(run_seed("Spielberg", 4), 4.0));
        assert_ne!(a.lateral_speed_mps, 0.0);
        assert_eq!(
            estimate_biases(run_seed("Spielberg", 3), 0.0),
            EstimateBias::default()
        );
        // Twice the level, twice the bias: the same draw scaled.
        let half = estimate_biases(run_seed("Spielberg", 3), 2.0);
        assert_eq!(a.yaw_rate_radps, 2.0 * half.yaw_rate_radps);
        // Over many seeds: zero mean, the level's standard deviation.
        let n = 20_000;
        let draws: Vec<EstimateBias> = (0..n).map(|k| estimate_biases(k, 1.0)).collect();
        for (name, xs, sigma) in [
            (
                "lateral speed",
                draws
                    .iter()
                    .map(|b| b.lateral_speed_mps)
                    .collect::<Vec<_>>(),
                NOISE_UNIT.lateral_speed_bias_mps,
            ),
            (
                "yaw rate",
                draws.iter().map(|b| b.yaw_rate_radps).collect::<Vec<_>>(),
                NOISE_UNIT.yaw_rate_bias_radps,
            ),
        ] {
            let mean = xs.iter().sum::<f64>() / n as f64;
            let sd = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
            assert!(mean.abs() < 0.03 * sigma, "{name}: mean {mean}");
            assert!(
                (sd / sigma - 1.0).abs() < 0.03,
                "{name}: σ {sd} for {sigma}"
            );
        }
    }

    #[test]
    fn delay_rounds_to_control_periods() {
        let d = Disturbances {
            delay_ms: 24.0,
            ..Disturbances::default()
        };
        assert_eq!(d.delay_periods(), 2);
        let d = Disturbances {
            delay_ms: 0.0,
            ..Disturbances::default()
        };
        assert_eq!(d.delay_periods(), 0);
    }
}
