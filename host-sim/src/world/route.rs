//! The route planner's side of the road: the ECU holds a window of the reference
//! path, not the whole circuit (its RAM does not grow with the track), and this
//! feeder sends the next window as the car moves on. `run` and `pil` use the same
//! feeder, so the modelled and the real ECU plan on the same windows.
//!
//! A window is [`WINDOW_ROWS`] consecutive track rows (wrapping round a closed
//! track) starting about [`BEHIND_M`] behind the car; the next one is sent when
//! the car is [`ADVANCE_M`] past that. A closed track of at most
//! [`WINDOW_ROWS`] rows is sent whole, once, as a closed path.

use anyhow::{bail, Result};
use firmware::reference_path::MAX_SEARCH_SEGMENTS;

use crate::world::track::Track;

/// Rows of a window: the ECU's path capacity.
pub const WINDOW_ROWS: usize = firmware::tasks::ECU_PATH_ROWS;

/// Point capacity of a reference path on the host: the whole track for the
/// modelled ECU and the obstacle placement (the ECU holds [`WINDOW_ROWS`]).
pub const HOST_PATH_CAP: usize = 4096;
/// Road kept behind the car at the start of a window, m.
pub const BEHIND_M: f64 = 40.0;
/// Distance the car drives into a window before the next one is sent, m.
pub const ADVANCE_M: f64 = 60.0;
/// Road a window must reach ahead of the car when the next one is due, m: the
/// MPC's horizon at the top speed (~80 m) and the velocity planner's preview.
pub const AHEAD_M: f64 = 150.0;

/// The span of road a projection near a hint searches on the ECU (behind and
/// ahead of the hint), m.
const SEARCH_SPAN_M: f64 = (firmware::reference_path::DEFAULT_SEARCH_BEHIND_M
    + firmware::reference_path::DEFAULT_SEARCH_AHEAD_M) as f64;
/// The first row from which more than `MAX_SEARCH_SEGMENTS − 2` rows (that one
/// included) lie within [`SEARCH_SPAN_M`] of road ahead, and how many: `rows`
/// at the arc lengths `s` (m), of a track `length_m` long, wrapping when
/// `closed`. `None` when there is none.
fn too_dense(rows: &[[f64; 4]], s: &[f64], length_m: f64, closed: bool) -> Option<(usize, usize)> {
    let n = rows.len();
    let start = |j: usize| if j < n { s[j] } else { s[j - n] + length_m };
    let end = |i: usize| if closed { i + n } else { n };
    let mut j = 0;
    for (i, &si) in s.iter().enumerate().take(n) {
        j = j.max(i + 1);
        while j < end(i) && start(j) - si < SEARCH_SPAN_M {
            j += 1;
        }
        if j - i > MAX_SEARCH_SEGMENTS - 2 {
            return Some((i, j - i));
        }
    }
    None
}

/// One window of the road.
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    /// Rows `[x_m, y_m, w_right_m, w_left_m]`.
    pub rows: Vec<[f64; 4]>,
    /// Distance along the road (laps unwrapped) of the first row, m.
    pub origin_m: f64,
    /// The whole of a closed track, as a closed path.
    pub closed: bool,
}

/// Decides which window the ECU holds.
#[derive(Clone, Debug)]
pub struct RouteFeeder {
    rows: Vec<[f64; 4]>,
    /// Arc length at each row, m.
    s: Vec<f64>,
    length_m: f64,
    closed: bool,
    whole: bool,
    origin_m: f64,
}

impl RouteFeeder {
    /// The feeder for `track`; fails, saying what to change, when the track's
    /// points are so dense that a window cannot reach [`AHEAD_M`] ahead.
    pub fn new(track: &Track) -> Result<Self> {
        let rows = track.rows();
        let n = rows.len();
        let closed = track.closed;
        let mut s = Vec::with_capacity(n);
        let mut acc = 0.0;
        for i in 0..n {
            s.push(acc);
            let j = if i + 1 < n { i + 1 } else { 0 };
            if i + 1 < n || closed {
                acc += (rows[j][0] - rows[i][0]).hypot(rows[j][1] - rows[i][1]);
            }
        }
        // The ECU's projections near a hint scan a bounded number of segments
        // (`firmware::reference_path::MAX_SEARCH_SEGMENTS`): its path refuses a
        // window whose search span holds more points. Said here, for the whole
        // track, with a point to find it by (one point stricter than the ECU, whose
        // arithmetic is f32).
        if let Some((i, count)) = too_dense(&rows, &s, acc, closed) {
            bail!(
                "track {}: its points are too dense near ({:.1}, {:.1}) m (row {i}): {count} points within {SEARCH_SPAN_M} m of it, where the ECU's projections search at most {}: resample the track to at least {:.2} m between points",
                track.name,
                rows[i][0],
                rows[i][1],
                MAX_SEARCH_SEGMENTS - 2,
                SEARCH_SPAN_M / (MAX_SEARCH_SEGMENTS - 2) as f64
            );
        }
        // A track that fits the window is sent whole, once.
        let whole = n <= WINDOW_ROWS;
        let feeder = Self {
            rows,
            s,
            length_m: acc,
            closed,
            whole,
            origin_m: 0.0,
        };
        if !whole {
            // The shortest span of WINDOW_ROWS rows anywhere on the track (on an
            // open track, windows that end before the road does: the last ones
            // reach its end).
            let starts = if closed { n } else { n + 1 - WINDOW_ROWS };
            let span = (0..starts)
                .map(|i| feeder.span_from(i))
                .fold(f64::INFINITY, f64::min);
            let needed = BEHIND_M + ADVANCE_M + AHEAD_M;
            if span < needed {
                bail!(
                    "track {}: its points are too dense for the ECU's {WINDOW_ROWS}-row window of the road ({span:.0} m where it must cover {needed:.0} m): resample the track to at least {:.2} m between points",
                    track.name,
                    needed / (WINDOW_ROWS - 1) as f64
                );
            }
        }
        Ok(feeder)
    }

    /// Length of the road covered by the window starting at row `i`, m.
    fn span_from(&self, i: usize) -> f64 {
        let n = self.rows.len();
        let last = i + WINDOW_ROWS - 1;
        if self.closed {
            let laps = (last / n) as f64;
            self.s[last % n] + laps * self.length_m - self.s[i]
        } else {
            self.s[last.min(n - 1)] - self.s[i]
        }
    }

    /// The window starting at row `i` of lap `lap`.
    fn window_at(&self, i: usize, lap: f64) -> Window {
        let n = self.rows.len();
        let count = if self.closed {
            WINDOW_ROWS
        } else {
            WINDOW_ROWS.min(n - i)
        };
        Window {
            rows: (0..count).map(|k| self.rows[(i + k) % n]).collect(),
            origin_m: lap * self.length_m + self.s[i],
            closed: false,
        }
    }

    /// The row starting a window `BEHIND_M` behind `progress_m` (distance driven
    /// along the road from row 0, laps unwrapped) and its lap.
    fn start_for(&self, progress_m: f64) -> (usize, f64) {
        let target = (progress_m - BEHIND_M).max(0.0);
        let (lap, s) = if self.closed && self.length_m > 0.0 {
            ((target / self.length_m).floor(), target % self.length_m)
        } else {
            (0.0, target)
        };
        let i = self.s.partition_point(|&x| x <= s).saturating_sub(1);
        let i = if self.closed {
            i
        } else {
            i.min(self.rows.len().saturating_sub(2))
        };
        (i, lap)
    }

    /// The first window (the car at the start of the track).
    pub fn first(&mut self) -> Window {
        if self.whole {
            return Window {
                rows: self.rows.clone(),
                origin_m: 0.0,
                closed: self.closed,
            };
        }
        let w = self.window_at(0, 0.0);
        self.origin_m = w.origin_m;
        w
    }

    /// The next window when the car, `progress_m` along the road, is due one.
    pub fn update(&mut self, progress_m: f64) -> Option<Window> {
        if self.whole || progress_m < self.origin_m + BEHIND_M + ADVANCE_M {
            return None;
        }
        let (i, lap) = self.start_for(progress_m);
        let w = self.window_at(i, lap);
        if w.origin_m <= self.origin_m {
            return None; // the end of an open track: nothing further to send
        }
        self.origin_m = w.origin_m;
        Some(w)
    }
}
