//! Stretches of road along a lap, each with a value of its own: the patches of
//! `--mu-patch` (friction) and `--grade` (slope). What they share is here: reading
//! `START_M:LENGTH_M:VALUE`, fitting the patches to a track's lap, and finding
//! which patch covers an arc length.
//!
//! A patch covers the arc lengths `[START_M, START_M + LENGTH_M)` of the track's
//! centre line (m, from its first point). On a closed track positions are taken
//! modulo the lap length, so a patch recurs every lap and one that runs past the
//! lap line goes on from the start of the lap. A patch must start inside the lap
//! (`0 ≤ START_M < lap`), be no longer than it (`0 < LENGTH_M ≤ lap`), and overlap
//! no other patch of the same option; on an open track it must also end by the
//! track's end.

/// Which option's patches: named in every message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PatchKind {
    /// The command-line option, e.g. `--mu-patch`.
    pub option: &'static str,
    /// What a patch gives the road, e.g. `friction`.
    pub quantity: &'static str,
    /// The third number's name and meaning, e.g. `MU` and `friction`, for the usage.
    pub value: (&'static str, &'static str),
    /// An example of the option's value.
    pub example: &'static str,
}

impl PatchKind {
    /// `wants START_M:LENGTH_M:VALUE (...), e.g. ...`.
    pub fn usage(&self) -> String {
        format!(
            "wants START_M:LENGTH_M:{} (metres along the lap, metres, {}), e.g. {}",
            self.value.0, self.value.1, self.example
        )
    }

    /// Reads `START_M:LENGTH_M:VALUE`: three finite numbers, `START_M ≥ 0`,
    /// `LENGTH_M > 0` (the value's own range is the caller's to check).
    pub fn parse(&self, s: &str) -> Result<[f64; 3], String> {
        let option = self.option;
        let usage = self.usage();
        let parts: Vec<&str> = s.split(':').map(str::trim).collect();
        if parts.len() != 3 {
            return Err(format!("{option} {s:?}: {usage}"));
        }
        let mut v = [0.0; 3];
        for (x, (p, name)) in
            v.iter_mut()
                .zip(parts.iter().zip(["START_M", "LENGTH_M", self.value.0]))
        {
            *x = p
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    format!("{option} {s:?}: {name} {p:?} is not a finite number; {usage}")
                })?;
        }
        let [start_m, length_m, _] = v;
        if start_m < 0.0 {
            return Err(format!(
                "{option} {s:?}: START_M must be ≥ 0 m along the lap, got {start_m}"
            ));
        }
        if length_m <= 0.0 {
            return Err(format!(
                "{option} {s:?}: LENGTH_M must be a positive length in m, got {length_m}"
            ));
        }
        Ok(v)
    }
}

/// Why patches do not fit a track.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PatchError {
    /// The road's own friction is out of range.
    #[error("road friction {0}: must be a friction coefficient in (0, 2]")]
    Road(f64),
    /// A patch's numbers are out of range (the option's parser says which).
    #[error("{0}")]
    Value(String),
    /// A patch starts at or past the end of the lap.
    #[error("{option} {patch}: starts at {start_m} m, past the end of the lap of track `{track}` ({lap_m:.1} m long); START_M must be in [0, {lap_m:.1})")]
    StartPastLap {
        /// The option.
        option: &'static str,
        /// The patch, as given.
        patch: String,
        /// Its start, m.
        start_m: f64,
        /// The track's name.
        track: String,
        /// The lap's length, m.
        lap_m: f64,
    },
    /// A patch is longer than the lap (or, on an open track, runs past its end).
    #[error("{option} {patch}: {length_m} m long from {start_m} m does not fit track `{track}` ({lap_m:.1} m long, {kind})")]
    TooLong {
        /// The option.
        option: &'static str,
        /// The patch, as given.
        patch: String,
        /// Its start, m.
        start_m: f64,
        /// Its length, m.
        length_m: f64,
        /// The track's name.
        track: String,
        /// The lap's length, m.
        lap_m: f64,
        /// What the limit is.
        kind: &'static str,
    },
    /// Two patches cover the same stretch of road.
    #[error("{option} {a} and {b} overlap on track `{track}` (lap {lap_m:.1} m): give each stretch of road one {quantity}")]
    Overlap {
        /// The option.
        option: &'static str,
        /// What a patch gives the road.
        quantity: &'static str,
        /// The first patch.
        a: String,
        /// The second patch.
        b: String,
        /// The track's name.
        track: String,
        /// The lap's length, m.
        lap_m: f64,
    },
}

/// A patch of one option (`--mu-patch`, `--grade`): shown as the option spells it
/// (`START:LENGTH:VALUE`) and read back from that form with every check of the
/// option's.
pub trait LapPatch: std::fmt::Display + std::str::FromStr<Err = String> {
    /// Start along the lap, m.
    fn start_m(&self) -> f64;
    /// Length along the road, m.
    fn length_m(&self) -> f64;
}

/// The patches as one string, each as its option spells it, joined by `;` (empty
/// without any).
pub fn join<P: std::fmt::Display>(patches: &[P]) -> String {
    patches
        .iter()
        .map(P::to_string)
        .collect::<Vec<_>>()
        .join(";")
}

/// One patch as [`LapSpans::new`] takes it.
#[derive(Clone, Debug, PartialEq)]
pub struct PatchPlace {
    /// Start along the lap, m.
    pub start_m: f64,
    /// Length along the road, m.
    pub length_m: f64,
    /// The patch as the option spells it, for messages.
    pub shown: String,
}

/// Patches fitted to a lap: intervals `[a, b)` of `[0, lap)` (a patch that runs
/// over the lap line in two), each with the index of its patch.
#[derive(Clone, Debug, PartialEq)]
pub struct LapSpans {
    /// `(a, b, patch index)`, m.
    spans: Vec<(f64, f64, usize)>,
    lap_m: f64,
    closed: bool,
}

impl LapSpans {
    /// No patch.
    pub fn none() -> Self {
        Self {
            spans: Vec::new(),
            lap_m: f64::INFINITY,
            closed: false,
        }
    }

    /// [`Self::new`] on patches built in code: each is first read back from the
    /// form its option spells (the same checks as parsing the command line).
    pub fn of<P: LapPatch>(
        kind: &PatchKind,
        patches: &[P],
        track: &str,
        lap_m: f64,
        closed: bool,
    ) -> Result<Self, PatchError> {
        let mut places = Vec::new();
        for p in patches {
            let shown = p.to_string();
            shown.parse::<P>().map_err(PatchError::Value)?;
            places.push(PatchPlace {
                start_m: p.start_m(),
                length_m: p.length_m(),
                shown,
            });
        }
        Self::new(kind, &places, track, lap_m, closed)
    }

    /// Fits `patches` of option `kind` to the lap of track `track` (name, for
    /// errors), `lap_m` long (m), closed (patches wrap over laps) or open (module
    /// docs for the rules).
    pub fn new(
        kind: &PatchKind,
        patches: &[PatchPlace],
        track: &str,
        lap_m: f64,
        closed: bool,
    ) -> Result<Self, PatchError> {
        let mut spans = Vec::new();
        for (k, p) in patches.iter().enumerate() {
            if p.start_m >= lap_m {
                return Err(PatchError::StartPastLap {
                    option: kind.option,
                    patch: p.shown.clone(),
                    start_m: p.start_m,
                    track: track.to_string(),
                    lap_m,
                });
            }
            let too_long = |what| PatchError::TooLong {
                option: kind.option,
                patch: p.shown.clone(),
                start_m: p.start_m,
                length_m: p.length_m,
                track: track.to_string(),
                lap_m,
                kind: what,
            };
            let end = p.start_m + p.length_m;
            if closed {
                if p.length_m > lap_m {
                    return Err(too_long("a patch may be at most one lap long"));
                }
                if end > lap_m {
                    spans.push((p.start_m, lap_m, k));
                    spans.push((0.0, end - lap_m, k));
                    continue;
                }
            } else if end > lap_m {
                return Err(too_long("on an open track a patch must end by its end"));
            }
            spans.push((p.start_m, end, k));
        }
        for (i, a) in spans.iter().enumerate() {
            for b in &spans[i + 1..] {
                if a.2 != b.2 && a.0 < b.1 && b.0 < a.1 {
                    return Err(PatchError::Overlap {
                        option: kind.option,
                        quantity: kind.quantity,
                        a: patches[a.2].shown.clone(),
                        b: patches[b.2].shown.clone(),
                        track: track.to_string(),
                        lap_m,
                    });
                }
            }
        }
        Ok(Self {
            spans,
            lap_m,
            closed,
        })
    }

    /// No patch at all.
    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }

    /// The `k`-th patch as intervals `[a, b)` of the lap's arc length (m): one, or
    /// two when it runs over the lap line.
    pub fn of_patch(&self, k: usize) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.spans
            .iter()
            .filter(move |s| s.2 == k)
            .map(|&(a, b, _)| (a, b))
    }

    /// The patch at arc length `s_m` (m along the centre line from its first point;
    /// any number of laps on a closed track), if any; none for a non-finite `s_m`.
    pub fn patch_at(&self, s_m: f64) -> Option<usize> {
        if self.spans.is_empty() || !s_m.is_finite() {
            return None;
        }
        let s = if self.closed {
            s_m.rem_euclid(self.lap_m)
        } else {
            s_m
        };
        self.spans
            .iter()
            .find(|(a, b, _)| *a <= s && s < *b)
            .map(|s| s.2)
    }

    /// How much of `[a_m, b_m]` (m of arc length, `a_m ≤ b_m`, at most a lap long
    /// on a closed track) each patch covers: `(patch index, length in m)` for every
    /// span it meets, repeated over the laps it wraps.
    pub fn cover(&self, a_m: f64, b_m: f64) -> impl Iterator<Item = (usize, f64)> + '_ {
        let (a, b, shifts): (f64, f64, &[f64]) = if self.closed && a_m.is_finite() {
            let a = a_m.rem_euclid(self.lap_m);
            (a, a + (b_m - a_m), &[0.0, 1.0])
        } else {
            (a_m, b_m, &[0.0])
        };
        let lap = self.lap_m;
        shifts.iter().flat_map(move |&k| {
            self.spans.iter().filter_map(move |&(sa, sb, owner)| {
                let len = (sb + k * lap).min(b) - (sa + k * lap).max(a);
                (len > 0.0).then_some((owner, len))
            })
        })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const KIND: PatchKind = PatchKind {
        option: "--x-patch",
        quantity: "x",
        value: ("X", "an x"),
        example: "1:2:3",
    };

    fn place(start_m: f64, length_m: f64) -> PatchPlace {
        PatchPlace {
            start_m,
            length_m,
            shown: format!("{start_m}:{length_m}"),
        }
    }

    #[test]
    fn the_cover_of_a_stretch_wraps_over_the_lap_line() {
        let s = LapSpans::new(
            &KIND,
            &[place(900.0, 200.0), place(300.0, 100.0)],
            "t",
            1000.0,
            true,
        )
        .unwrap();
        let cover = |a: f64, b: f64| -> Vec<(usize, f64)> {
            let mut v: Vec<(usize, f64)> = Vec::new();
            for (k, l) in s.cover(a, b) {
                match v.iter_mut().find(|(j, _)| *j == k) {
                    Some(e) => e.1 += l,
                    None => v.push((k, l)),
                }
            }
            v.sort_by_key(|e| e.0);
            v
        };
        assert_eq!(cover(950.0, 1050.0), vec![(0, 100.0)]);
        assert_eq!(cover(-20.0, 10.0), vec![(0, 30.0)]);
        assert_eq!(cover(2095.0, 2105.0), vec![(0, 5.0)]);
        assert_eq!(cover(350.0, 450.0), vec![(1, 50.0)]);
        assert_eq!(cover(500.0, 600.0), vec![]);
        assert_eq!(s.patch_at(-50.0), Some(0));
        assert_eq!(s.patch_at(1350.0), Some(1));
        assert_eq!(s.patch_at(f64::NAN), None);
        // An open track does not wrap.
        let open = LapSpans::new(&KIND, &[place(300.0, 100.0)], "t", 1000.0, false).unwrap();
        assert_eq!(open.cover(1350.0, 1450.0).count(), 0);
        assert_eq!(open.patch_at(1350.0), None);
    }

    #[test]
    fn messages_name_the_option() {
        let e = KIND.parse("1:2").unwrap_err();
        assert!(
            e.starts_with("--x-patch \"1:2\": wants START_M:LENGTH_M:X"),
            "{e}"
        );
        let e = KIND.parse("1:2:z").unwrap_err();
        assert!(e.contains("X \"z\" is not a finite number"), "{e}");
        let e = LapSpans::new(
            &KIND,
            &[place(0.0, 100.0), place(50.0, 10.0)],
            "t",
            1000.0,
            true,
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("--x-patch 0:100 and 50:10 overlap"),
            "{e}"
        );
        assert!(e.to_string().ends_with("one x"), "{e}");
    }
}
