//! The road's grade along the lap: stretches of road that rise or fall
//! (`--grade START_M:LENGTH_M:PERCENT`), and the grade under the car.
//!
//! # Patches
//!
//! A patch rises at `PERCENT` % (`100·tan γ`, positive uphill in the track's
//! direction of travel, `|PERCENT| ≤ 30`) over the arc lengths
//! `[START_M, START_M + LENGTH_M)` of the track's centre line; the rest of the road
//! is level. Patches wrap over laps and must fit the lap as
//! [`crate::world::lap_patches`] says. Arc lengths are the centre line's, measured
//! on the map (horizontally). Only the slope is modelled, not the road's height: on a
//! closed track the patches need not climb back to where they started (a hill that
//! recurs every lap is allowed).
//!
//! # The grade under the car
//!
//! A car straddles a change of grade: its pitch on the road is that of the chord
//! between its axles' contact points. The road's height `z(s)` has the slope
//! `tan γ(s)`, so the chord between the rear axle at `s − l_r` and the front axle at
//! `s + l_f` rises at `(z(s + l_f) − z(s − l_r))/L`: the mean of `tan γ` over the
//! wheelbase. The car's grade angle is its arctangent ([`RoadGrade::under_car_rad`]),
//! so a change of grade is taken over the wheelbase's length, as a car rolls over a
//! crest or through a dip. The plant applies it along the car's `x` axis
//! ([`crate::model::plant::RoadUnder`]).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::world::lap_patches::{LapPatch, LapSpans, PatchError, PatchKind};

/// Steepest grade a patch may have, %: a steep public road (the steepest streets
/// are about 35 %; motorways keep under 6–8 %).
pub const MAX_GRADE_PCT: f64 = 30.0;

/// `--grade`: its name, what it gives the road, its third number.
pub const GRADE: PatchKind = PatchKind {
    option: "--grade",
    quantity: "grade",
    value: ("PERCENT", "grade in %, positive uphill"),
    example: "300:300:6",
};

/// One stretch of road with a grade, as given to `--grade`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GradePatch {
    /// Arc length along the lap where the patch begins, m.
    pub start_m: f64,
    /// Length of the patch along the road (on the map), m.
    pub length_m: f64,
    /// Its grade `100·tan γ`, % (positive: the road rises in the direction of travel).
    pub percent: f64,
}

impl LapPatch for GradePatch {
    fn start_m(&self) -> f64 {
        self.start_m
    }
    fn length_m(&self) -> f64 {
        self.length_m
    }
}

impl fmt::Display for GradePatch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.start_m, self.length_m, self.percent)
    }
}

impl FromStr for GradePatch {
    type Err = String;
    /// `START_M:LENGTH_M:PERCENT`, each a finite number, `START_M ≥ 0`,
    /// `LENGTH_M > 0`, `|PERCENT| ≤ 30` (what needs the track, its length, is
    /// checked by [`RoadGrade::new`]).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let [start_m, length_m, percent] = GRADE.parse(s)?;
        if percent.abs() > MAX_GRADE_PCT {
            return Err(format!(
                "--grade {s:?}: PERCENT must be a grade in [-{MAX_GRADE_PCT}, {MAX_GRADE_PCT}] % (100 × rise over run, positive uphill), got {percent}"
            ));
        }
        Ok(GradePatch {
            start_m,
            length_m,
            percent,
        })
    }
}

/// The road's grade along a track.
#[derive(Clone, Debug, PartialEq)]
pub struct RoadGrade {
    /// Each patch's `tan γ`, in the order given.
    slopes: Vec<f64>,
    spans: LapSpans,
}

impl RoadGrade {
    /// The road with `patches` on a track `track` (name, for errors) of length
    /// `lap_m` (m), closed (patches wrap over laps) or open.
    pub fn new(
        patches: &[GradePatch],
        track: &str,
        lap_m: f64,
        closed: bool,
    ) -> Result<Self, PatchError> {
        Ok(Self {
            slopes: patches.iter().map(|p| p.percent / 100.0).collect(),
            spans: LapSpans::of(&GRADE, patches, track, lap_m, closed)?,
        })
    }

    /// A level road.
    pub fn level() -> Self {
        Self {
            slopes: Vec::new(),
            spans: LapSpans::none(),
        }
    }

    /// No patch: level everywhere.
    pub fn is_level(&self) -> bool {
        self.spans.is_empty()
    }

    /// The `k`-th patch given as intervals `[a, b)` of the lap's arc length (m): one,
    /// or two when it runs over the lap line.
    pub fn patch_spans(&self, k: usize) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.spans.of_patch(k)
    }

    /// The road's grade at arc length `s_m` (m; any number of laps on a closed
    /// track), % (0 off the patches).
    pub fn percent_at(&self, s_m: f64) -> f64 {
        self.spans
            .patch_at(s_m)
            .map_or(0.0, |k| 100.0 * self.slopes[k])
    }

    /// The grade angle of a car whose centre of gravity is at arc length `s_m` (m),
    /// front axle `lf_m` ahead of it and rear axle `lr_m` behind: the chord's
    /// between its axles (module docs), rad.
    pub fn under_car_rad(&self, s_m: f64, lf_m: f64, lr_m: f64) -> f64 {
        if self.is_level() || !s_m.is_finite() {
            return 0.0;
        }
        let rise: f64 = self
            .spans
            .cover(s_m - lr_m, s_m + lf_m)
            .map(|(k, len)| self.slopes[k] * len)
            .sum();
        (rise / (lf_m + lr_m)).atan()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn p(s: &str) -> Result<GradePatch, String> {
        s.parse()
    }

    #[test]
    fn grades_parse_and_refuse_nonsense_with_the_reason() {
        assert_eq!(
            p("300:300:-6"),
            Ok(GradePatch {
                start_m: 300.0,
                length_m: 300.0,
                percent: -6.0
            })
        );
        assert_eq!(p("0:1:30").map(|g| g.percent), Ok(30.0));
        let e = p("300:300").unwrap_err();
        assert!(
            e.contains("--grade \"300:300\": wants START_M:LENGTH_M:PERCENT"),
            "{e}"
        );
        let e = p("300:300:6%").unwrap_err();
        assert!(e.contains("PERCENT \"6%\" is not a finite number"), "{e}");
        let e = p("300:300:31").unwrap_err();
        assert!(e.contains("[-30, 30] %") && e.contains("got 31"), "{e}");
        assert!(p("300:300:-45").is_err());
        assert!(p("300:300:nan").is_err());
        assert!(p("-1:300:6").unwrap_err().contains("START_M must be ≥ 0"));
        assert!(p("300:0:6")
            .unwrap_err()
            .contains("LENGTH_M must be a positive"));
    }

    #[test]
    fn patches_that_do_not_fit_the_lap_name_the_option_and_the_lap() {
        let g = |start_m, length_m| GradePatch {
            start_m,
            length_m,
            percent: 6.0,
        };
        let e = RoadGrade::new(&[g(1000.0, 10.0)], "t", 1000.0, true).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("--grade 1000:10:6: starts at 1000 m"),
            "{e}"
        );
        let e = RoadGrade::new(&[g(900.0, 200.0), g(50.0, 100.0)], "t", 1000.0, true).unwrap_err();
        assert!(
            e.to_string()
                .contains("give each stretch of road one grade"),
            "{e}"
        );
        let e = RoadGrade::new(&[g(900.0, 200.0)], "t", 1000.0, false).unwrap_err();
        assert!(e.to_string().contains("on an open track"), "{e}");
        let bad = GradePatch {
            percent: 40.0,
            ..g(0.0, 10.0)
        };
        assert!(RoadGrade::new(&[bad], "t", 1000.0, true).is_err());
    }

    #[test]
    fn the_car_takes_a_change_of_grade_over_its_wheelbase() {
        // +6 % from 300 m for 300 m, -6 % from 900 m over the lap line to 200 m.
        let patches = [
            GradePatch {
                start_m: 300.0,
                length_m: 300.0,
                percent: 6.0,
            },
            GradePatch {
                start_m: 900.0,
                length_m: 300.0,
                percent: -6.0,
            },
        ];
        let r = RoadGrade::new(&patches, "t", 1000.0, true).unwrap();
        let (lf, lr) = (1.0, 1.5);
        let up = 0.06_f64.atan();
        assert_eq!(r.under_car_rad(700.0, lf, lr), 0.0);
        assert!((r.under_car_rad(450.0, lf, lr) - up).abs() < 1e-15);
        assert!((r.under_car_rad(2050.0, lf, lr) + up).abs() < 1e-15);
        // Rear axle on the level, front one 0.5 m up the slope: a fifth of it.
        let entering = r.under_car_rad(299.5, lf, lr);
        assert!(
            (entering - (0.2 * 0.06_f64).atan()).abs() < 1e-15,
            "{entering}"
        );
        // Across the lap line, the front axle at 0.5 m on the way down.
        let across = r.under_car_rad(999.5 + 1000.0, lf, lr);
        assert!((across + up).abs() < 1e-15, "{across}");
        // Leaving the downhill patch at 200 m over 2.5 m: monotonic back to level.
        let mut last = -up;
        for k in 0..=30 {
            let g = r.under_car_rad(198.5 + 0.1 * f64::from(k), lf, lr);
            assert!(g >= last - 1e-15 && g <= 0.0, "{g} after {last}");
            last = g;
        }
        assert_eq!(last, 0.0);
        assert_eq!(r.percent_at(450.0), 6.0);
        assert_eq!(r.percent_at(-50.0), -6.0);
        assert_eq!(RoadGrade::level().under_car_rad(450.0, lf, lr), 0.0);
    }
}
