//! Named fault scenarios for `host-sim sweep --faults`, each with the behaviour the
//! architecture promises under it, and the run outcome the sweep classifies every
//! run into.
//!
//! | fault (`--faults`) | what happens | expected behaviour (checked) |
//! |---|---|---|
//! | `none` | nothing | `ok` |
//! | `dropout-nan:N` (N = 20) | every estimate field NaN for N control periods (10 ms) from t = [`FAULT_START_S`] | both tasks refuse the estimate; `control` applies the safe actuation (gentle braking, steering held) in each of the N periods, then follows again: outcome `ok` and at least N safe actuations |
//! | `dropout-hold:N` (N = 20) | no estimate update for N control periods from t = [`FAULT_START_S`] (the last one again, stamp and all) | keep following on the held estimate: outcome `ok` |
//! | `overrun:MHZ` (MHZ = 20) | the ECU clock at MHZ instead of 168 MHz: the plan activations that cost more than `0.1 s × MHZ` cycles overrun their 100 ms period | misses counted, late plans published or dropped by the late-plan policy, the car keeps following: outcome `deadline-miss` (the lap completes, no collision, no off-road) with at least one miss |
//! | `mu-high:F` (F = 1.5) | the planner assumes `F × μ` on a road of `μ` | the plan's `a_y ≤ 0.5·F·μ·g` is still within the tyres' `μ·g` for `F < 2`, its acceleration bounds (`0.8·F·μ·g`) are not: the control task's friction check (`firmware::friction`) sees the wheels spin or lock and the planner plans with the lower friction measured; keep following, outcome `ok` (lateral error and consistency degrade, reported; `friction_mu_min` in the summary) |
//! | `late-obstacle:D` (D = 60 m) | a 2 m × 2 m box half across the centre line at half the lap, given to the planner only when the car is D m before it along the path | replan around it or stop before it: outcome `ok` or `stopped-safely`, and the obstacle was revealed |
//! | `steer-rate:R` (R = 0.5 rad/s) | the steering actuator moves at most R rad/s (the firmware does not know) | keep following: outcome `ok` |

use std::fmt;
use std::str::FromStr;

use serde::Serialize;

/// Simulated time at which the dropouts start, s.
pub const FAULT_START_S: f64 = 20.0;

/// A named fault scenario (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fault {
    /// No fault.
    None,
    /// Every estimate field NaN for this many control periods.
    DropoutNan(u32),
    /// No estimate update for this many control periods.
    DropoutHold(u32),
    /// ECU clock, MHz.
    Overrun(f64),
    /// Planner friction over road friction.
    MuHigh(f64),
    /// Distance before the obstacle at which the planner sees it, m.
    LateObstacle(f64),
    /// Steering actuator rate limit, rad/s.
    SteerRate(f64),
}

impl Fault {
    /// What the architecture promises under this fault (module docs).
    pub fn expected(&self) -> &'static str {
        match self {
            Fault::None => "outcome ok",
            Fault::DropoutNan(_) => {
                "safe actuation in each NaN period, then following again: outcome ok"
            }
            Fault::DropoutHold(_) => "keep following on the held estimate: outcome ok",
            Fault::Overrun(_) => {
                "misses counted (> 0), the car keeps following: outcome deadline-miss"
            }
            Fault::MuHigh(_) => "keep following (plan within the tyres' μg): outcome ok",
            Fault::LateObstacle(_) => {
                "replan around it or stop before it: outcome ok or stopped-safely"
            }
            Fault::SteerRate(_) => "keep following: outcome ok",
        }
    }

    /// Whether a run showed the expected behaviour.
    pub fn check(&self, f: &RunFacts) -> bool {
        match self {
            Fault::None | Fault::DropoutHold(_) | Fault::MuHigh(_) | Fault::SteerRate(_) => {
                f.outcome == Outcome::Ok
            }
            Fault::DropoutNan(n) => f.outcome == Outcome::Ok && f.safe_actuations >= u64::from(*n),
            Fault::Overrun(_) => f.outcome == Outcome::DeadlineMiss && f.completed,
            Fault::LateObstacle(_) => {
                f.fault_event_s.is_some()
                    && matches!(f.outcome, Outcome::Ok | Outcome::StoppedSafely)
            }
        }
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Fault::None => write!(f, "none"),
            Fault::DropoutNan(n) => write!(f, "dropout-nan:{n}"),
            Fault::DropoutHold(n) => write!(f, "dropout-hold:{n}"),
            Fault::Overrun(m) => write!(f, "overrun:{m}"),
            Fault::MuHigh(k) => write!(f, "mu-high:{k}"),
            Fault::LateObstacle(d) => write!(f, "late-obstacle:{d}"),
            Fault::SteerRate(r) => write!(f, "steer-rate:{r}"),
        }
    }
}

impl FromStr for Fault {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (name, arg) = match s.split_once(':') {
            Some((n, a)) => (n, Some(a)),
            None => (s, None),
        };
        let num = |default: f64| -> Result<f64, String> {
            match arg {
                None => Ok(default),
                Some(a) => match a.parse::<f64>() {
                    Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
                    _ => Err(format!("fault {s:?}: {a:?} is not a positive number")),
                },
            }
        };
        let periods = |default: f64| -> Result<u32, String> {
            let n = num(default)?;
            if n.fract() != 0.0 || n > 1e6 {
                return Err(format!(
                    "fault {s:?}: give a whole number of control periods"
                ));
            }
            Ok(n as u32)
        };
        match name {
            "none" => Ok(Fault::None),
            "dropout-nan" => Ok(Fault::DropoutNan(periods(20.0)?)),
            "dropout-hold" => Ok(Fault::DropoutHold(periods(20.0)?)),
            "overrun" => Ok(Fault::Overrun(num(20.0)?)),
            "mu-high" => Ok(Fault::MuHigh(num(1.5)?)),
            "late-obstacle" => Ok(Fault::LateObstacle(num(60.0)?)),
            "steer-rate" => Ok(Fault::SteerRate(num(0.5)?)),
            _ => Err(format!(
                "unknown fault {s:?}: one of none, dropout-nan[:N], dropout-hold[:N], overrun[:MHZ], mu-high[:F], late-obstacle[:D_M], steer-rate[:RAD_PER_S]"
            )),
        }
    }
}

/// How a run ended, worst first (the first that applies).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// The run could not be set up or errored (a bad track file, a planner that
    /// refuses the track), or ended neither completed nor stopped (time limit).
    Failed,
    /// The car's footprint overlapped an obstacle.
    Collision,
    /// The centre of gravity left the road (beyond the local half-width).
    OffRoad,
    /// A plan or control activation missed its deadline.
    DeadlineMiss,
    /// The car stood still (a controlled stop) before completing.
    StoppedSafely,
    /// The laps completed with none of the above.
    Ok,
}

impl Outcome {
    /// Every outcome, worst first.
    pub const ALL: [Outcome; 6] = [
        Outcome::Failed,
        Outcome::Collision,
        Outcome::OffRoad,
        Outcome::DeadlineMiss,
        Outcome::StoppedSafely,
        Outcome::Ok,
    ];

    /// The name written in `sweep.csv`.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Failed => "failed",
            Outcome::Collision => "collision",
            Outcome::OffRoad => "off-road",
            Outcome::DeadlineMiss => "deadline-miss",
            Outcome::StoppedSafely => "stopped-safely",
            Outcome::Ok => "ok",
        }
    }

    /// The outcome of a name written by [`Outcome::name`].
    pub fn from_name(s: &str) -> Option<Outcome> {
        Outcome::ALL.into_iter().find(|o| o.name() == s)
    }
}

/// What a fault check reads of a run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunFacts {
    /// The run's outcome.
    pub outcome: Outcome,
    /// The laps completed.
    pub completed: bool,
    /// Control activations that applied the safe actuation.
    pub safe_actuations: u64,
    /// When the fault took effect, s (the late obstacle: when it was revealed).
    pub fault_event_s: Option<f64>,
}

/// The outcome of a finished run (module docs of [`Outcome`]: worst first).
pub fn classify(s: &crate::closed_loop::Summary, off_road: bool) -> Outcome {
    if s.collisions > 0 {
        Outcome::Collision
    } else if off_road || s.stop_reason.starts_with("left the road") {
        Outcome::OffRoad
    } else if s.plan_deadline_misses + s.control_deadline_misses > 0 {
        Outcome::DeadlineMiss
    } else if s.completed {
        Outcome::Ok
    } else if s.stop_reason.starts_with("stood still") {
        Outcome::StoppedSafely
    } else {
        Outcome::Failed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_parse_with_defaults_and_print_back() {
        for (s, f) in [
            ("none", Fault::None),
            ("dropout-nan", Fault::DropoutNan(20)),
            ("dropout-hold:5", Fault::DropoutHold(5)),
            ("overrun:30", Fault::Overrun(30.0)),
            ("mu-high", Fault::MuHigh(1.5)),
            ("late-obstacle:45", Fault::LateObstacle(45.0)),
            ("steer-rate:0.3", Fault::SteerRate(0.3)),
        ] {
            assert_eq!(s.parse::<Fault>(), Ok(f));
            assert_eq!(f.to_string().parse::<Fault>(), Ok(f));
        }
        assert!("dropout-nan:2.5".parse::<Fault>().is_err());
        assert!("overrun:-1".parse::<Fault>().is_err());
        assert!("meteor".parse::<Fault>().is_err());
    }

    #[test]
    fn outcome_names_round_trip() {
        for o in Outcome::ALL {
            assert_eq!(Outcome::from_name(o.name()), Some(o));
        }
    }
}
