//! Friction that changes along the road: patches of road with their own μ
//! (`--mu-patch START_M:LENGTH_M:MU`), the μ each wheel of the plant stands on, and
//! how the firmware's friction estimate `μ̂` compares with the road the car drove on.
//!
//! # Patches
//!
//! A patch covers the arc lengths `[START_M, START_M + LENGTH_M)` of the track's
//! centre line with the road friction `MU` there, `0 < MU ≤ 2`; the rest of the
//! road has the run's `--mu`. Patches wrap over laps and must fit the lap as
//! [`crate::world::lap_patches`] says.
//!
//! # What the plant sees
//!
//! Each wheel sees the μ at its own arc length: the car's (its centre of gravity
//! projected on the centre line every 10 ms, advanced by its speed between
//! projections) plus the wheel's distance ahead of the centre of gravity, `+l_f` for
//! the front wheels and `−l_r` for the rear ones (the wheels' lateral offsets are
//! neglected: on a curve of radius R they shift the arc length by `l_f·l_w/R` at
//! most, centimetres). The log's `road_mu` is the lowest μ under the four wheels at
//! the sample.
//!
//! # Judging `μ̂` against the road ([`judge`])
//!
//! - **False drop**: at some 10 ms sample `t`, `μ̂(t) < 0.9·min{road_mu(t') : t − 10 s
//!   ≤ t' ≤ t}`: the estimate fell below 90 % of the lowest grip the car stood on
//!   during the last 10 s ([`FALSE_DROP_RATIO`], [`FALSE_DROP_WINDOW_S`]). A drop on a
//!   patch, or within 10 s after it, down to 0.9 × the patch's μ is not a false drop;
//!   a drop below that, or a low `μ̂` that lasts more than 10 s after the car left the
//!   patch, is.
//! - **Recovery**: an exit is a sample where `road_mu` rises (the last wheel left a
//!   patch of lower grip). The recovery time of an exit is the time from it to the
//!   first sample where `μ̂ ≥ 0.9·road_mu`, looked for until the next exit or the end
//!   of the run (0 when `μ̂` never fell that low); `mu_recovery_s` is the slowest over
//!   the exits that recovered, `mu_unrecovered_exits` counts those that did not.
//!
//! `μ̂` is `inf` while the friction check has seen no slip (never below anything);
//! when the ECU does not report it (NaN: processor in the loop) nothing is judged.

use std::collections::VecDeque;
use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

pub use crate::world::lap_patches::PatchError;
use crate::world::lap_patches::{LapPatch, LapSpans, PatchKind};

/// `μ̂` below this fraction of the road's lowest recent μ is a false drop.
pub const FALSE_DROP_RATIO: f64 = 0.9;

/// How far back "recent" reaches for a false drop, s.
pub const FALSE_DROP_WINDOW_S: f64 = 10.0;

/// Largest friction coefficient a patch (or the road) may have, as for `--mu`.
pub const MAX_MU: f64 = 2.0;

/// One patch of road with its own friction, as given to `--mu-patch`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MuPatch {
    /// Arc length along the lap where the patch begins, m.
    pub start_m: f64,
    /// Length of the patch along the road, m.
    pub length_m: f64,
    /// Road friction on the patch, dimensionless.
    pub mu: f64,
}

impl LapPatch for MuPatch {
    fn start_m(&self) -> f64 {
        self.start_m
    }
    fn length_m(&self) -> f64 {
        self.length_m
    }
}

impl fmt::Display for MuPatch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.start_m, self.length_m, self.mu)
    }
}

/// `--mu-patch`: its name, what it gives the road, its third number.
pub const MU_PATCH: PatchKind = PatchKind {
    option: "--mu-patch",
    quantity: "friction",
    value: ("MU", "friction"),
    example: "300:200:0.5",
};

impl FromStr for MuPatch {
    type Err = String;
    /// `START_M:LENGTH_M:MU`, each a finite number, `START_M ≥ 0`, `LENGTH_M > 0`,
    /// `0 < MU ≤ 2` (what needs the track, its length, is checked by
    /// [`RoadFriction::new`]).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let [start_m, length_m, mu] = MU_PATCH.parse(s)?;
        if !(mu > 0.0 && mu <= MAX_MU) {
            return Err(format!(
                "--mu-patch {s:?}: MU must be a friction coefficient in (0, {MAX_MU}], got {mu}"
            ));
        }
        Ok(MuPatch {
            start_m,
            length_m,
            mu,
        })
    }
}

/// The road's friction along a track: its μ and its patches.
#[derive(Clone, Debug, PartialEq)]
pub struct RoadFriction {
    base_mu: f64,
    /// Each patch's μ, in the order given.
    mus: Vec<f64>,
    spans: LapSpans,
}

impl RoadFriction {
    /// The road of friction `base_mu` with `patches` on a track `track` (name, for
    /// errors) of length `lap_m` (m), closed (patches wrap over laps) or open.
    pub fn new(
        base_mu: f64,
        patches: &[MuPatch],
        track: &str,
        lap_m: f64,
        closed: bool,
    ) -> Result<Self, PatchError> {
        if !(base_mu.is_finite() && base_mu > 0.0 && base_mu <= MAX_MU) {
            return Err(PatchError::Road(base_mu));
        }
        Ok(Self {
            base_mu,
            mus: patches.iter().map(|p| p.mu).collect(),
            spans: LapSpans::of(&MU_PATCH, patches, track, lap_m, closed)?,
        })
    }

    /// A road of friction `mu` everywhere.
    pub fn uniform(mu: f64) -> Self {
        Self {
            base_mu: mu,
            mus: Vec::new(),
            spans: LapSpans::none(),
        }
    }

    /// No patch: the same μ everywhere.
    pub fn is_uniform(&self) -> bool {
        self.spans.is_empty()
    }

    /// The road's own μ (off the patches).
    pub fn base_mu(&self) -> f64 {
        self.base_mu
    }

    /// The `k`-th patch given as intervals `[a, b)` of the lap's arc length (m): one,
    /// or two when it runs over the lap line.
    pub fn patch_spans(&self, k: usize) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.spans.of_patch(k)
    }

    /// The friction at arc length `s_m` (m along the centre line from its first
    /// point; any number of laps on a closed track, before the start or past the end
    /// of an open one: the road's μ).
    pub fn mu_at(&self, s_m: f64) -> f64 {
        self.spans
            .patch_at(s_m)
            .map_or(self.base_mu, |k| self.mus[k])
    }

    /// The friction under each wheel `[fl, fr, rl, rr]` of a car whose centre of
    /// gravity is at arc length `s_m` (m), front axle `lf_m` ahead of it and rear
    /// axle `lr_m` behind (module docs).
    pub fn wheels_mu(&self, s_m: f64, lf_m: f64, lr_m: f64) -> [f64; 4] {
        if self.is_uniform() {
            return [self.base_mu; 4];
        }
        let (front, rear) = (self.mu_at(s_m + lf_m), self.mu_at(s_m - lr_m));
        [front, front, rear, rear]
    }
}

/// One 10 ms sample for [`judge`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MuSample {
    /// Time, s.
    pub t_s: f64,
    /// Lowest road μ under the wheels.
    pub road_mu: f64,
    /// The firmware's estimate `μ̂` (`inf` before any slip, NaN if not reported).
    pub mu_hat: f64,
}

/// How `μ̂` fared against the road (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MuVerdict {
    /// `μ̂` fell below 0.9 × the lowest road μ of the last 10 s at some sample.
    pub false_drop: bool,
    /// When it first did, s.
    pub first_false_drop_s: Option<f64>,
    /// Exits from a patch of lower grip.
    pub exits: u32,
    /// The slowest recovery over the exits that recovered, s (`None` without one).
    pub recovery_s: Option<f64>,
    /// Exits after which `μ̂` did not reach 0.9 × the road's μ before the next exit
    /// or the end of the run.
    pub unrecovered_exits: u32,
}

/// Judges `μ̂` against the road over `samples` (in time order); `None` when any
/// sample's `μ̂` is NaN (the ECU does not report it) or there are no samples.
pub fn judge(samples: &[MuSample]) -> Option<MuVerdict> {
    if samples.is_empty() || samples.iter().any(|s| s.mu_hat.is_nan()) {
        return None;
    }
    let mut v = MuVerdict::default();
    // Sliding-window minimum of road_mu over [t - window, t]: indices with
    // increasing road_mu.
    let mut window: VecDeque<usize> = VecDeque::new();
    for (k, s) in samples.iter().enumerate() {
        while window
            .back()
            .is_some_and(|&j| samples[j].road_mu >= s.road_mu)
        {
            window.pop_back();
        }
        window.push_back(k);
        while window
            .front()
            .is_some_and(|&j| samples[j].t_s < s.t_s - FALSE_DROP_WINDOW_S)
        {
            window.pop_front();
        }
        let low = window.front().map_or(s.road_mu, |&j| samples[j].road_mu);
        if s.mu_hat < FALSE_DROP_RATIO * low && !v.false_drop {
            v.false_drop = true;
            v.first_false_drop_s = Some(s.t_s);
        }
    }
    let exits: Vec<usize> = (1..samples.len())
        .filter(|&k| samples[k].road_mu > samples[k - 1].road_mu)
        .collect();
    v.exits = exits.len() as u32;
    for (n, &k) in exits.iter().enumerate() {
        let end = exits.get(n + 1).copied().unwrap_or(samples.len());
        let back = samples[k..end]
            .iter()
            .find(|s| s.mu_hat >= FALSE_DROP_RATIO * s.road_mu);
        match back {
            Some(s) => {
                let dt = s.t_s - samples[k].t_s;
                v.recovery_s = Some(v.recovery_s.map_or(dt, |r: f64| r.max(dt)));
            }
            None => v.unrecovered_exits += 1,
        }
    }
    Some(v)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn p(s: &str) -> Result<MuPatch, String> {
        s.parse()
    }

    #[test]
    fn patches_parse_and_refuse_nonsense_with_the_reason() {
        assert_eq!(
            p("300:200:0.5"),
            Ok(MuPatch {
                start_m: 300.0,
                length_m: 200.0,
                mu: 0.5
            })
        );
        assert_eq!(p(" 0 : 1.5 : 2 ").map(|x| x.length_m), Ok(1.5));
        assert!(p("300:200").unwrap_err().contains("START_M:LENGTH_M:MU"));
        assert!(p("300:200:0.5:1").is_err());
        assert!(p("a:200:0.5").unwrap_err().contains("START_M \"a\""));
        assert!(p("300:NaN:0.5").unwrap_err().contains("LENGTH_M"));
        assert!(p("300:inf:0.5").unwrap_err().contains("not a finite"));
        assert!(p("-1:200:0.5").unwrap_err().contains("≥ 0"));
        assert!(p("300:0:0.5").unwrap_err().contains("positive"));
        assert!(p("300:-5:0.5").unwrap_err().contains("positive"));
        assert!(p("300:200:0").unwrap_err().contains("(0, 2]"));
        assert!(p("300:200:-0.3").is_err());
        assert!(p("300:200:2.5").is_err());
        assert!(p("300:200:inf").is_err());
    }

    fn patch(start_m: f64, length_m: f64, mu: f64) -> MuPatch {
        MuPatch {
            start_m,
            length_m,
            mu,
        }
    }

    #[test]
    fn patches_that_do_not_fit_the_lap_say_its_length() {
        let e = RoadFriction::new(1.0, &[patch(1000.0, 10.0, 0.5)], "t", 1000.0, true).unwrap_err();
        assert!(matches!(e, PatchError::StartPastLap { .. }));
        assert!(e.to_string().contains("1000.0 m long"), "{e}");
        let e = RoadFriction::new(1.0, &[patch(0.0, 1000.5, 0.5)], "t", 1000.0, true).unwrap_err();
        assert!(matches!(e, PatchError::TooLong { .. }));
        assert!(e.to_string().contains("1000.0 m long"), "{e}");
        // A whole lap is fine; past an open track's end is not.
        assert!(RoadFriction::new(1.0, &[patch(0.0, 1000.0, 0.5)], "t", 1000.0, true).is_ok());
        assert!(RoadFriction::new(1.0, &[patch(900.0, 200.0, 0.5)], "t", 1000.0, false).is_err());
        let e = RoadFriction::new(
            1.0,
            &[patch(900.0, 200.0, 0.5), patch(50.0, 100.0, 0.3)],
            "t",
            1000.0,
            true,
        )
        .unwrap_err();
        assert!(matches!(e, PatchError::Overlap { .. }), "{e}");
        // Touching is not overlapping.
        assert!(RoadFriction::new(
            1.0,
            &[patch(900.0, 200.0, 0.5), patch(100.0, 100.0, 0.3)],
            "t",
            1000.0,
            true
        )
        .is_ok());
        assert!(RoadFriction::new(1.0, &[patch(10.0, 10.0, 0.0)], "t", 1000.0, true).is_err());
        assert!(RoadFriction::new(f64::NAN, &[], "t", 1000.0, true).is_err());
    }

    #[test]
    fn the_mu_along_the_road_wraps_over_laps() {
        let r = RoadFriction::new(
            1.0,
            &[patch(300.0, 200.0, 0.5), patch(900.0, 200.0, 0.3)],
            "t",
            1000.0,
            true,
        )
        .unwrap();
        for (s, mu) in [
            (0.0, 0.3),
            (99.9, 0.3),
            (100.0, 1.0),
            (299.9, 1.0),
            (300.0, 0.5),
            (499.9, 0.5),
            (500.0, 1.0),
            (899.9, 1.0),
            (900.0, 0.3),
            (1300.0, 0.5),
            (2450.0, 0.5),
            (2550.0, 1.0),
            (-50.0, 0.3),
            (-600.0, 0.5),
        ] {
            assert_eq!(r.mu_at(s), mu, "s = {s}");
        }
        // The second patch runs over the lap line: two spans.
        assert_eq!(r.patch_spans(0).collect::<Vec<_>>(), vec![(300.0, 500.0)]);
        assert_eq!(
            r.patch_spans(1).collect::<Vec<_>>(),
            vec![(900.0, 1000.0), (0.0, 100.0)]
        );
        // Front wheels reach the patch first, the rear ones leave it last.
        assert_eq!(r.wheels_mu(299.0, 1.1, 1.5), [0.5, 0.5, 1.0, 1.0]);
        assert_eq!(r.wheels_mu(501.0, 1.1, 1.5), [1.0, 1.0, 0.5, 0.5]);
        // An open track does not wrap.
        let open = RoadFriction::new(1.0, &[patch(300.0, 200.0, 0.5)], "t", 1000.0, false).unwrap();
        assert_eq!(open.mu_at(1300.0), 1.0);
        assert_eq!(open.mu_at(400.0), 0.5);
        assert_eq!(RoadFriction::uniform(0.7).mu_at(123.0), 0.7);
    }

    /// A synthetic trace: 10 ms samples, road μ and μ̂ as functions of time.
    fn trace(end_s: f64, road: impl Fn(f64) -> f64, hat: impl Fn(f64) -> f64) -> Vec<MuSample> {
        (0..=(end_s * 100.0).round() as usize)
            .map(|k| {
                let t = k as f64 * 0.01;
                MuSample {
                    t_s: t,
                    road_mu: road(t),
                    mu_hat: hat(t),
                }
            })
            .collect()
    }

    /// A patch of μ 0.5 on a road of μ 1 from 20 s to 25 s.
    fn wet(t: f64) -> f64 {
        if (20.0..25.0).contains(&t) {
            0.5
        } else {
            1.0
        }
    }

    #[test]
    fn a_drop_on_the_patch_that_recovers_is_no_false_drop() {
        // μ̂ falls to 0.46 (> 0.9 × 0.5) on the patch and is back to 0.95 at 31 s.
        let s = trace(60.0, wet, |t| {
            if t < 21.0 {
                f64::INFINITY
            } else if t < 31.0 {
                0.46
            } else {
                0.95
            }
        });
        let v = judge(&s).unwrap();
        assert!(!v.false_drop, "{v:?}");
        assert_eq!(v.exits, 1);
        assert_eq!(v.unrecovered_exits, 0);
        let r = v.recovery_s.unwrap();
        assert!((r - 6.0).abs() < 1e-9, "{r}");
    }

    #[test]
    fn false_drops_are_caught() {
        // On a dry road: μ̂ at 0.85 < 0.9.
        let v = judge(&trace(30.0, |_| 1.0, |t| if t < 12.0 { 1.0 } else { 0.85 })).unwrap();
        assert!(v.false_drop);
        assert!((v.first_false_drop_s.unwrap() - 12.0).abs() < 1e-9);
        assert_eq!(v.exits, 0);
        assert_eq!(v.recovery_s, None);
        // On the patch, below 0.9 × its μ.
        let v = judge(&trace(60.0, wet, |t| if t < 22.0 { 1.0 } else { 0.44 })).unwrap();
        assert!(v.false_drop);
        assert!((v.first_false_drop_s.unwrap() - 22.0).abs() < 1e-9);
        // After the patch, at 0.46: fine for 10 s after the last wet sample (24.99 s),
        // a false drop from then on; it never recovers.
        let v = judge(&trace(60.0, wet, |t| if t < 22.0 { 1.0 } else { 0.46 })).unwrap();
        assert!(v.false_drop);
        let t = v.first_false_drop_s.unwrap();
        assert!((t - 35.0).abs() < 0.015, "{t}");
        assert_eq!(v.unrecovered_exits, 1);
        assert_eq!(v.recovery_s, None);
        // Exactly at 0.9 × the road is not below it; `inf` never is.
        let v = judge(&trace(
            30.0,
            |_| 1.0,
            |t| if t < 5.0 { f64::INFINITY } else { 0.9 },
        ))
        .unwrap();
        assert!(!v.false_drop);
        // Not reported: not judged.
        assert_eq!(judge(&trace(1.0, |_| 1.0, |_| f64::NAN)), None);
        assert_eq!(judge(&[]), None);
    }
}
