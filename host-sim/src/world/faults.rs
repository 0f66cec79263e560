//! Named fault scenarios (`--fault` of `run` and `sweep`; [`FAULT_KINDS`] is their
//! one list, which `--help` prints), each with the behaviour the architecture
//! promises under it, and the run outcome the sweep classifies every run into.
//!
//! | fault (`--fault`) | what happens | expected behaviour (checked) |
//! |---|---|---|
//! | `none` | nothing | `ok` |
//! | `dropout-nan:N` (N = 20) | every estimate field NaN for N control periods (10 ms) from t = [`FAULT_START_S`] | both tasks refuse the estimate; `control` applies the safe actuation (gentle braking, steering held) in each of the N periods, then follows again: outcome `ok` and at least N safe actuations |
//! | `dropout-hold:N` (N = 20) | no estimate update for N control periods from t = [`FAULT_START_S`] (the last one again, stamp and all) | keep following on the held estimate: outcome `ok` |
//! | `overrun:MHZ` (MHZ = 20) | the ECU clock at MHZ instead of 168 MHz: the plan activations that cost more than `0.1 s × MHZ` cycles overrun their 100 ms period | misses counted, late plans published or dropped by the late-plan policy, the car keeps following: outcome `deadline-miss` (the lap completes, no collision, no off-road) with at least one miss |
//! | `mu-high:F` (F = 1.5) | the planner assumes `F × μ` on a road of `μ` | the plan's `a_y ≤ 0.5·F·μ·g` is still within the tyres' `μ·g` for `F < 2`, its acceleration bounds (`0.8·F·μ·g`) are not: the control task's friction check (`firmware::friction`) sees the wheels spin or lock and the planner plans with the lower friction measured; keep following, outcome `ok` (lateral error and consistency degrade, reported; `friction_mu_min` in the summary) |
//! | `late-obstacle:D` (D = 60 m) | a 2 m × 2 m box half across the centre line at half the lap, given to the planner only when the car is D m before it along the path | replan around it or stop before it: outcome `ok` or `stopped-safely`, and the obstacle was revealed |
//! | `blocked-road:D` (D = 150 m) | a 2 m box across the whole road at half the lap, given to the planner only when the car is D m before it along the path | no way round: the planner keeps the obstacle and caps the speed to stop before it (`firmware::obstacles::obstacle_speed_cap`); outcome `stopped-safely` (no collision, no off-road), and the obstacle was revealed |
//! | `steer-rate:R` (R = 0.5 rad/s) | the steering actuator moves at most R rad/s (the firmware does not know) | keep following: outcome `ok` |

use std::fmt;
use std::str::FromStr;

use serde::Serialize;

/// Simulated time at which the dropouts start, s.
pub const FAULT_START_S: f64 = 20.0;

/// A named fault scenario (module docs; [`FAULT_KINDS`] lists them).
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
    /// Distance before the road-blocking obstacle at which the planner sees it, m.
    BlockedRoad(f64),
    /// Steering actuator rate limit, rad/s.
    SteerRate(f64),
}

/// The parameter of a fault scenario: `NAME:VALUE` on the command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultParam {
    /// Its placeholder in the help (`N`, `MHZ`, ...).
    pub placeholder: &'static str,
    /// What it is, with its unit.
    pub meaning: &'static str,
    /// Its value when the name is given alone.
    pub default: f64,
    /// Only whole numbers (a count of control periods).
    pub whole: bool,
}

/// One fault scenario: its name, parameter, what it does and what is expected of
/// the architecture under it. [`FAULT_KINDS`] is the one list: parsing, printing,
/// the expected behaviour and the command-line help all read it.
#[derive(Clone, Copy, Debug)]
pub struct FaultKind {
    /// Name on the command line and in `sweep.csv`.
    pub name: &'static str,
    /// Its parameter, if any.
    pub param: Option<FaultParam>,
    /// What happens.
    pub what: &'static str,
    /// What the architecture promises (checked per run by [`Fault::check`]).
    pub expected: &'static str,
    /// Whether a processor-in-the-loop run (`host-sim pil`) can apply it: the
    /// dropouts, the steering rate limit and the late obstacle act around the
    /// in-process ECU, and the overrun changes the modelled ECU's clock (in PIL
    /// the ECU's own clock times the run).
    pub pil: bool,
    /// The fault with this parameter value (the default when given alone).
    make: fn(f64) -> Fault,
}

/// Every fault scenario, `none` first.
pub const FAULT_KINDS: [FaultKind; 8] = [
    FaultKind {
        name: "none",
        param: None,
        what: "nothing",
        expected: "outcome ok",
        pil: true,
        make: |_| Fault::None,
    },
    FaultKind {
        name: "dropout-nan",
        param: Some(FaultParam {
            placeholder: "N",
            meaning: "control periods of 10 ms",
            default: 20.0,
            whole: true,
        }),
        what: "every estimate field NaN for N control periods from the fault's start",
        expected: "safe actuation in each NaN period, then following again: outcome ok",
        pil: false,
        make: |n| Fault::DropoutNan(n as u32),
    },
    FaultKind {
        name: "dropout-hold",
        param: Some(FaultParam {
            placeholder: "N",
            meaning: "control periods of 10 ms",
            default: 20.0,
            whole: true,
        }),
        what: "no estimate update for N control periods from the fault's start",
        expected: "keep following on the held estimate: outcome ok",
        pil: false,
        make: |n| Fault::DropoutHold(n as u32),
    },
    FaultKind {
        name: "overrun",
        param: Some(FaultParam {
            placeholder: "MHZ",
            meaning: "the ECU clock, MHz",
            default: 20.0,
            whole: false,
        }),
        what: "the modelled ECU clocked at MHZ instead of 168 MHz",
        expected: "misses counted (> 0), the car keeps following: outcome deadline-miss",
        pil: false,
        make: Fault::Overrun,
    },
    FaultKind {
        name: "mu-high",
        param: Some(FaultParam {
            placeholder: "F",
            meaning: "planner friction over the road's",
            default: 1.5,
            whole: false,
        }),
        what: "the planner assumes F × the road's μ (at most 2)",
        expected: "keep following (plan within the tyres' μg): outcome ok",
        pil: true,
        make: Fault::MuHigh,
    },
    FaultKind {
        name: "late-obstacle",
        param: Some(FaultParam {
            placeholder: "D_M",
            meaning: "distance before it, m",
            default: 60.0,
            whole: false,
        }),
        what: "a 2 m × 2 m box at half the lap, given to the planner only D_M metres before it",
        expected: "replan around it or stop before it: outcome ok or stopped-safely",
        pil: false,
        make: Fault::LateObstacle,
    },
    FaultKind {
        name: "blocked-road",
        param: Some(FaultParam {
            placeholder: "D_M",
            meaning: "distance before it, m",
            default: 150.0,
            whole: false,
        }),
        what: "a 2 m box across the whole road at half the lap, given to the planner only D_M metres before it",
        expected: "stop before it: outcome stopped-safely",
        pil: false,
        make: Fault::BlockedRoad,
    },
    FaultKind {
        name: "steer-rate",
        param: Some(FaultParam {
            placeholder: "RAD_PER_S",
            meaning: "steering rate limit, rad/s",
            default: 0.5,
            whole: false,
        }),
        what: "the steering actuator moves at most RAD_PER_S (the firmware does not know)",
        expected: "keep following: outcome ok",
        pil: false,
        make: Fault::SteerRate,
    },
];

impl FaultKind {
    /// `name` or `name[:PARAM]`, as the command line takes it.
    pub fn usage(&self) -> String {
        match self.param {
            None => self.name.to_string(),
            Some(p) => format!("{}[:{}]", self.name, p.placeholder),
        }
    }
}

/// The fault scenarios for `--help`: one line each with its parameter, default,
/// what it does, the expected behaviour and whether PIL can apply it.
pub fn fault_help() -> String {
    let mut t = format!(
        "Fault scenarios, comma-separated (`sweep` runs each; `run` and `pil` take one); the fault's start is t = {FAULT_START_S} s:"
    );
    for k in &FAULT_KINDS {
        t.push_str("\n  ");
        t.push_str(&k.usage());
        t.push_str(": ");
        t.push_str(k.what);
        if let Some(p) = k.param {
            t.push_str(&format!(
                "; {}: {}, default {}",
                p.placeholder, p.meaning, p.default
            ));
        }
        t.push_str(&format!(". Expected: {}.", k.expected));
        if !k.pil {
            t.push_str(" Not in `pil`.");
        }
    }
    t
}

impl Fault {
    /// Its row of [`FAULT_KINDS`].
    pub fn kind(&self) -> &'static FaultKind {
        let this = std::mem::discriminant(self);
        FAULT_KINDS
            .iter()
            .find(|k| std::mem::discriminant(&(k.make)(1.0)) == this)
            .unwrap_or(&FAULT_KINDS[0])
    }

    /// Its parameter's value, if it has one.
    pub fn param(&self) -> Option<f64> {
        match *self {
            Fault::None => None,
            Fault::DropoutNan(n) | Fault::DropoutHold(n) => Some(f64::from(n)),
            Fault::Overrun(x)
            | Fault::MuHigh(x)
            | Fault::LateObstacle(x)
            | Fault::BlockedRoad(x)
            | Fault::SteerRate(x) => Some(x),
        }
    }

    /// What the architecture promises under this fault (module docs).
    pub fn expected(&self) -> &'static str {
        self.kind().expected
    }

    /// Whether a processor-in-the-loop run can apply it ([`FaultKind::pil`]).
    pub fn applies_to_pil(&self) -> bool {
        self.kind().pil
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
            Fault::BlockedRoad(_) => {
                f.fault_event_s.is_some() && f.outcome == Outcome::StoppedSafely
            }
        }
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.param() {
            None => write!(f, "{}", self.kind().name),
            Some(x) => write!(f, "{}:{x}", self.kind().name),
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
        let Some(kind) = FAULT_KINDS.iter().find(|k| k.name == name) else {
            let all: Vec<String> = FAULT_KINDS.iter().map(FaultKind::usage).collect();
            return Err(format!(
                "unknown fault {s:?}: one of {} (`host-sim sweep --help` says what each does)",
                all.join(", ")
            ));
        };
        let x = match (kind.param, arg) {
            (None, None) => 0.0,
            (None, Some(_)) => return Err(format!("fault {s:?}: `{name}` takes no parameter")),
            (Some(p), None) => p.default,
            (Some(p), Some(a)) => match a.parse::<f64>() {
                Ok(x) if x.is_finite() && x > 0.0 => {
                    if p.whole && (x.fract() != 0.0 || x > 1e6) {
                        return Err(format!("fault {s:?}: give a whole number of {}", p.meaning));
                    }
                    x
                }
                _ => return Err(format!("fault {s:?}: {a:?} is not a positive number")),
            },
        };
        Ok((kind.make)(x))
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
            ("blocked-road:80", Fault::BlockedRoad(80.0)),
            ("steer-rate:0.3", Fault::SteerRate(0.3)),
        ] {
            assert_eq!(s.parse::<Fault>(), Ok(f));
            assert_eq!(f.to_string().parse::<Fault>(), Ok(f));
        }
        assert!("dropout-nan:2.5".parse::<Fault>().is_err());
        assert!("overrun:-1".parse::<Fault>().is_err());
        assert!("none:3".parse::<Fault>().is_err());
        assert!("meteor".parse::<Fault>().is_err());
    }

    #[test]
    fn every_row_of_the_table_parses_to_its_own_kind_and_back() {
        let mut seen = Vec::new();
        for k in &FAULT_KINDS {
            let f: Fault = k.name.parse().unwrap_or(Fault::None);
            assert_eq!(f.kind().name, k.name);
            assert_eq!(f.param(), k.param.map(|p| p.default), "{}", k.name);
            assert!(
                fault_help().contains(&k.usage()),
                "{} not in the help",
                k.name
            );
            let d = std::mem::discriminant(&f);
            assert!(
                !seen.contains(&d),
                "{} is a second row for one variant",
                k.name
            );
            seen.push(d);
        }
        let e = "meteor".parse::<Fault>().err().unwrap_or_default();
        for k in &FAULT_KINDS {
            assert!(e.contains(&k.usage()), "{e}");
        }
    }

    #[test]
    fn outcome_names_round_trip() {
        for o in Outcome::ALL {
            assert_eq!(Outcome::from_name(o.name()), Some(o));
        }
    }
}
