//! Reference path: the centre line of the road as a polyline, with its
//! curvilinear abscissa `s`, heading, curvature, track widths and projection.
//!
//! # Model
//!
//! The path is the polyline through the points `(x_i, y_i)`, m, `i = 0..n`,
//! either open (`n − 1` segments) or closed (`n` segments, the last one from
//! point `n − 1` back to point 0). Optional track half-widths to the right and to
//! the left of the centre line, m, come with each point (the racetrack-database
//! format `x_m,y_m,w_tr_right_m,w_tr_left_m`) and are interpolated linearly in `s`.
//!
//! Everything a query needs is precomputed by [`ReferencePath::load`]:
//!
//! * `s_i`, the cumulative arc length of the polyline at vertex `i`, m;
//! * the unit direction and length of every segment;
//! * the heading `ψ_i` at each vertex, rad: the mean of the (unwrapped) headings
//!   of the two segments meeting there (the segment's own heading at the ends of an
//!   open path). Headings are unwrapped along the path, so they never jump by 2π;
//! * the curvature `κ_i` at each vertex, 1/m, positive for a left turn: the
//!   curvature of the circle through vertex `i` and the vertices `a` before and
//!   `c` after it that are the nearest ones at least `h` of arc length away,
//!   `κ = 2·((b − a) × (c − b)) / (|b − a|·|c − b|·|c − a|)`, with `h` the
//!   configurable half-window ([`ReferencePath::set_curvature_half_window_m`],
//!   default [`DEFAULT_CURVATURE_HALF_WINDOW_M`]). A window of a few metres
//!   filters the noise of measured points (a 2 cm error over a 1 m window is a
//!   curvature error of about 0.04 1/m, over 4 m about 0.003 1/m); taking vertices
//!   (never points on the chords) keeps it exact for points sampled on a circle
//!   whatever their spacing. On a closed path the window spans at most half the
//!   vertices each way. The two end vertices of an open path take the curvature
//!   of their neighbour. Collinear points give `κ = 0`.
//!
//! Between vertices, heading, curvature and widths are interpolated linearly in
//! `s`; positions lie on the polyline.
//!
//! # Arc length beyond the ends
//!
//! Every query accepts any `s`. On a **closed** path `s` wraps: `s` and
//! `s + k·L` are the same point (the MPC's `s` keeps growing lap after lap). The
//! heading keeps growing with it: `heading_at(s + L) = heading_at(s) + Θ`, with
//! `Θ` the total turning of one lap (±2π for a simple loop,
//! [`ReferencePath::total_turning_rad`]), so it is continuous in `s`. On an
//! **open** path positions are extrapolated along the first (`s < 0`) or last
//! (`s > L`) segment; heading, curvature and widths take their end values.
//!
//! # Storage
//!
//! Fixed capacity `CAP` points, no heap. [`ReferencePath::new`] is a `const fn`
//! so the path can live in a `static`; [`ReferencePath::load`] fills it in place.
//! The memory is `CAP · 10` scalars plus a few fields.
//!
//! # Example
//!
//! ```
//! use firmware::reference_path::ReferencePath;
//!
//! // A 20 m square, closed (the repeated first point is dropped).
//! let pts = [[0.0f32, 0.0], [20.0, 0.0], [20.0, 20.0], [0.0, 20.0], [0.0, 0.0]];
//! let mut path: ReferencePath<f32, 64> = ReferencePath::new();
//! path.load(&pts, None, true).unwrap();
//! assert_eq!(path.length_m(), 80.0);
//! // The car 1 m left of the first side, hint from the last plan's s (lap 2).
//! let pr = path.project([5.0, 1.0], Some(84.0)).unwrap();
//! assert_eq!((pr.s_m, pr.lateral_m), (85.0, 1.0));
//! assert_eq!(path.position_at(pr.s_m), [5.0, 0.0]);
//! ```

use crate::Real;

/// Default half-window `h` of the curvature estimate, m.
pub const DEFAULT_CURVATURE_HALF_WINDOW_M: f32 = 3.0;

/// Largest |coordinate| and half-width a path accepts, m (10,000 km: any map frame).
/// Larger finite values (up to `f32::MAX`) made the segment lengths and the arc
/// length overflow to infinity, and every query after them garbage (found by
/// `firmware/tests/fuzz.rs`).
pub const MAX_COORDINATE_M: f32 = 1.0e7;
/// Default length of path searched behind the hint by [`ReferencePath::project`], m.
pub const DEFAULT_SEARCH_BEHIND_M: f32 = 20.0;
/// Default length of path searched ahead of the hint by [`ReferencePath::project`], m.
pub const DEFAULT_SEARCH_AHEAD_M: f32 = 40.0;

/// Most steps of the binary search that finds a distance's segment, on a path
/// of the ECU's window ([`crate::tasks::ECU_PATH_ROWS`] vertices, so at most as
/// many segments): [`binary_search_steps`] of it, steps (for the WCET analysis).
pub const ECU_PATH_SEARCH_STEPS: usize = binary_search_steps(crate::tasks::ECU_PATH_ROWS);

/// Most steps of a binary search over `len` entries that halves `hi - lo` from
/// `len` until it is 1: `⌈log₂ len⌉` (0 for `len ≤ 1`), steps.
pub const fn binary_search_steps(len: usize) -> usize {
    if len <= 1 {
        0
    } else {
        (usize::BITS - (len - 1).leading_zeros()) as usize
    }
}

/// Why a path could not be loaded. Point indices refer to the slice given to
/// [`ReferencePath::load`]. After an error the path is empty.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathError {
    /// Fewer than 3 distinct points (after dropping the duplicate closing point of
    /// a closed loop); `count` is how many were usable.
    TooFewPoints {
        /// Number of usable points.
        count: usize,
    },
    /// More points than the capacity `CAP` of the path.
    TooManyPoints {
        /// Number of points given.
        count: usize,
        /// Capacity of the path.
        capacity: usize,
    },
    /// A coordinate or width of point `index` is NaN, infinite, or farther than
    /// [`MAX_COORDINATE_M`] from the origin (its arc length would overflow).
    NonFinite {
        /// Index of the bad point.
        index: usize,
    },
    /// Point `index` is at the same place as point `index − 1` (a zero-length
    /// segment). For a closed loop, `index == 0` means the last point equals the
    /// first after the tolerated duplicate was dropped (i.e. two duplicates).
    RepeatedPoint {
        /// Index of the repeated point.
        index: usize,
    },
    /// A track half-width of point `index` is negative.
    NegativeWidth {
        /// Index of the bad point.
        index: usize,
    },
    /// The widths slice does not have one entry per point.
    WidthCountMismatch {
        /// Number of points.
        points: usize,
        /// Number of width entries.
        widths: usize,
    },
    /// The configured curvature half-window is not a positive finite length.
    InvalidCurvatureWindow,
}

/// Result of [`ReferencePath::project`]: the path point closest to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projection<T> {
    /// Curvilinear abscissa of the foot point, m. Without a hint, in `[0, L)` for
    /// a closed path; with a hint, unwrapped to the lap closest to the hint. On an
    /// open path it may be negative or exceed `L` (extrapolated end segments).
    pub s_m: T,
    /// Signed lateral offset of the query point from the path, m, positive to the
    /// left of the direction of travel.
    pub lateral_m: T,
    /// Path heading at `s_m`, rad (interpolated, unwrapped as [`ReferencePath::heading_at`]).
    pub heading_rad: T,
    /// Path curvature at `s_m`, 1/m, positive for a left turn.
    pub curvature_1pm: T,
    /// Foot point on the polyline `[x, y]`, m.
    pub point_m: [T; 2],
    /// Index of the segment the foot point lies on.
    pub segment: usize,
}

/// Track half-widths at a point of the path, m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Widths<T> {
    /// Half-width to the right of the centre line, m.
    pub right_m: T,
    /// Half-width to the left of the centre line, m.
    pub left_m: T,
}

/// The state of a sliding scan for [`ReferencePath::max_abs_curvature_window`]:
/// the largest vertex curvature found in the last window and where the scan
/// stopped, so that the next window (whose ends did not move back) scans only the
/// vertices that entered it. Start each sequence of windows with
/// [`CurvatureWindow::new`]; one sequence per path (and per path change).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurvatureWindow<T> {
    /// The last window, unwrapped arc lengths, m (`valid` false: none).
    a: T,
    b: T,
    /// Largest `|κ|` (1/m) of the vertices scanned inside the window (−∞ when
    /// none), and the unwrapped arc length (m) of the last vertex that attains it.
    vmax: T,
    vpos: T,
    /// Segment the scan goes on with, and the unwrapped arc length of its start, m.
    seg: usize,
    pos: T,
    /// Segments the scan went past (it stops after one lap), and whether it met the
    /// end of an open path.
    steps: usize,
    ended: bool,
    valid: bool,
}

impl<T: Real> CurvatureWindow<T> {
    /// No window yet: the first query scans its whole window.
    pub const fn new() -> Self {
        Self {
            a: T::ZERO,
            b: T::ZERO,
            vmax: T::NEG_INFINITY,
            vpos: T::ZERO,
            seg: 0,
            pos: T::ZERO,
            steps: 0,
            ended: false,
            valid: false,
        }
    }
}

impl<T: Real> Default for CurvatureWindow<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// The path at one arc length, from one segment lookup (see
/// [`ReferencePath::sample_at`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSample<T> {
    /// Position `[x, y]`, m (as [`ReferencePath::position_at`]).
    pub position: [T; 2],
    /// Heading, rad (as [`ReferencePath::heading_at`]).
    pub heading_rad: T,
    /// Curvature, 1/m (as [`ReferencePath::curvature_at`]).
    pub curvature_1pm: T,
    /// Track half-widths, m (as [`ReferencePath::widths_at`]).
    pub widths: Option<Widths<T>>,
    /// The lookup behind the sample: segment and distance along it (m), for
    /// [`ReferencePath::max_abs_curvature_from`].
    segment: usize,
    segment_offset_m: T,
}

/// A reference path of at most `CAP` points; see the [module docs](self).
#[derive(Clone, Debug)]
pub struct ReferencePath<T, const CAP: usize> {
    /// Vertices `[x, y]`, m.
    xy: [[T; 2]; CAP],
    /// Half-widths `[right, left]`, m (zero if none were given).
    widths: [[T; 2]; CAP],
    /// Arc length at each vertex, m.
    s: [T; CAP],
    /// Unwrapped heading at each vertex, rad.
    heading: [T; CAP],
    /// Curvature at each vertex, 1/m.
    curvature: [T; CAP],
    /// Unit direction of segment `i` (vertex `i` to `i + 1`).
    dir: [[T; 2]; CAP],
    /// Length of segment `i`, m.
    seg_len: [T; CAP],
    /// Number of vertices loaded (0 when empty).
    n: usize,
    closed: bool,
    has_widths: bool,
    length: T,
    total_turn: T,
    max_abs_curvature: T,
    curvature_half_window_m: f32,
    search_behind_m: f32,
    search_ahead_m: f32,
}

impl<T: Real, const CAP: usize> Default for ReferencePath<T, CAP> {
    fn default() -> Self {
        Self::new()
    }
}

#[inline]
fn lerp<T: Real>(a: T, b: T, f: T) -> T {
    a + (b - a) * f
}

/// Wraps an angle into `[−π, π)`, rad.
#[inline]
fn wrap_pi<T: Real>(a: T) -> T {
    let two_pi = T::TWO * T::PI;
    a - two_pi * ((a + T::PI) / two_pi).floor()
}

impl<T: Real, const CAP: usize> ReferencePath<T, CAP> {
    const CAP_OK: () = assert!(CAP >= 3, "a reference path needs a capacity of at least 3");

    /// An empty path (length 0); a valid `const` initialiser for a `static`.
    pub const fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::CAP_OK;
        Self {
            xy: [[T::ZERO; 2]; CAP],
            widths: [[T::ZERO; 2]; CAP],
            s: [T::ZERO; CAP],
            heading: [T::ZERO; CAP],
            curvature: [T::ZERO; CAP],
            dir: [[T::ZERO; 2]; CAP],
            seg_len: [T::ZERO; CAP],
            n: 0,
            closed: false,
            has_widths: false,
            length: T::ZERO,
            total_turn: T::ZERO,
            max_abs_curvature: T::ZERO,
            curvature_half_window_m: DEFAULT_CURVATURE_HALF_WINDOW_M,
            search_behind_m: DEFAULT_SEARCH_BEHIND_M,
            search_ahead_m: DEFAULT_SEARCH_AHEAD_M,
        }
    }

    /// Sets the curvature half-window `h`, m (used by the next [`Self::load`]).
    pub fn set_curvature_half_window_m(&mut self, h_m: f32) {
        self.curvature_half_window_m = h_m;
    }

    /// Loads the centre line `points` (`[x, y]`, m) and optional `widths`
    /// (`[right, left]` half-widths, m, one per point), closed loop or open.
    ///
    /// For a closed loop, a last point equal to the first is tolerated and dropped
    /// (the usual way files close a loop). On error the path is left empty.
    /// Works in place: no copy of the path on the stack.
    pub fn load(
        &mut self,
        points: &[[T; 2]],
        widths: Option<&[[T; 2]]>,
        closed: bool,
    ) -> Result<(), PathError> {
        if let Some(w) = widths {
            if w.len() != points.len() {
                self.clear();
                return Err(PathError::WidthCountMismatch {
                    points: points.len(),
                    widths: w.len(),
                });
            }
        }
        let get = |i: usize| {
            let p = points.get(i).copied().unwrap_or([T::ZERO; 2]);
            let w = widths
                .and_then(|w| w.get(i).copied())
                .unwrap_or([T::ZERO; 2]);
            (p, w)
        };
        self.load_with(points.len(), widths.is_some(), get, closed)
    }

    /// Loads rows in the racetrack-database format
    /// `[x_m, y_m, w_tr_right_m, w_tr_left_m]`; as [`Self::load`] with widths.
    pub fn load_track(&mut self, rows: &[[T; 4]], closed: bool) -> Result<(), PathError> {
        let get = |i: usize| {
            let r = rows.get(i).copied().unwrap_or([T::ZERO; 4]);
            ([r[0], r[1]], [r[2], r[3]])
        };
        self.load_with(rows.len(), true, get, closed)
    }

    /// Common loader: `get(i)` gives point `i` and its widths `[right, left]`.
    fn load_with<F: Fn(usize) -> ([T; 2], [T; 2])>(
        &mut self,
        count: usize,
        has_widths: bool,
        get: F,
        closed: bool,
    ) -> Result<(), PathError> {
        self.clear();
        let r = self.load_inner(count, has_widths, get, closed);
        if r.is_err() {
            self.clear();
        }
        r
    }

    fn clear(&mut self) {
        self.n = 0;
        self.closed = false;
        self.has_widths = false;
        self.length = T::ZERO;
        self.total_turn = T::ZERO;
        self.max_abs_curvature = T::ZERO;
    }

    /// Checks `count` points given by `get` and returns how many the path keeps
    /// (a closed loop's repeated closing point dropped).
    fn validate<F: Fn(usize) -> ([T; 2], [T; 2])>(
        &self,
        count: usize,
        has_widths: bool,
        get: F,
        closed: bool,
    ) -> Result<usize, PathError> {
        let h = T::lit(self.curvature_half_window_m);
        if !h.is_finite() || h <= T::ZERO {
            return Err(PathError::InvalidCurvatureWindow);
        }
        // Validate every point and width.
        for i in 0..count {
            let (p, w) = get(i);
            let far = T::lit(MAX_COORDINATE_M);
            if !(p[0].abs() <= far && p[1].abs() <= far) {
                return Err(PathError::NonFinite { index: i });
            }
            if has_widths {
                if !(w[0].abs() <= far && w[1].abs() <= far) {
                    return Err(PathError::NonFinite { index: i });
                }
                // WCET: this line closes the `for i in 0..count` loop above; in the ECU `validate`
                // is reached only from `load_staged`, which refuses count > CAP (= ECU_PATH_ROWS) first.
                // wcet-bound: ECU_PATH_ROWS
                if w[0] < T::ZERO || w[1] < T::ZERO {
                    return Err(PathError::NegativeWidth { index: i });
                }
            }
        }
        let mut n = count;
        if closed && n >= 2 && same_point(get(0).0, get(n - 1).0) {
            n -= 1;
        }
        if n < 3 {
            return Err(PathError::TooFewPoints { count: n });
        }
        if n > CAP {
            return Err(PathError::TooManyPoints {
                count,
                capacity: CAP,
            });
        }
        // WCET: n <= CAP (= ECU_PATH_ROWS in the ECU), checked just above.
        // wcet-bound: ECU_PATH_ROWS
        for i in 1..n {
            if same_point(get(i - 1).0, get(i).0) {
                return Err(PathError::RepeatedPoint { index: i });
            }
        }
        if closed && same_point(get(n - 1).0, get(0).0) {
            return Err(PathError::RepeatedPoint { index: 0 });
        }
        Ok(n)
    }

    fn load_inner<F: Fn(usize) -> ([T; 2], [T; 2])>(
        &mut self,
        count: usize,
        has_widths: bool,
        get: F,
        closed: bool,
    ) -> Result<(), PathError> {
        let n = self.validate(count, has_widths, &get, closed)?;
        // Copy (n <= CAP).
        for (i, (xy, wd)) in self
            .xy
            .iter_mut()
            .zip(self.widths.iter_mut())
            .take(n)
            .enumerate()
        {
            let (p, w) = get(i);
            *xy = p;
            *wd = if has_widths { w } else { [T::ZERO; 2] };
        }
        self.compute(n, closed, has_widths);
        Ok(())
    }

    /// Writes track row `i` (`[x_m, y_m, w_right_m, w_left_m]`) into the path's own
    /// storage, for [`Self::load_staged`]: a path received piece by piece (the
    /// ECU's frames) is loaded without a second copy of the track in RAM. Returns
    /// false, writing nothing, when `i ≥ CAP`. Empties the path.
    pub fn stage_row(&mut self, i: usize, row: [T; 4]) -> bool {
        self.clear();
        match (self.xy.get_mut(i), self.widths.get_mut(i)) {
            (Some(xy), Some(w)) => {
                *xy = [row[0], row[1]];
                *w = [row[2], row[3]];
                true
            }
            _ => false,
        }
    }

    /// Loads the `count` rows written by [`Self::stage_row`] as
    /// [`Self::load_track`] would load them (same checks, same result bit for bit).
    pub fn load_staged(&mut self, count: usize, closed: bool) -> Result<(), PathError> {
        self.clear();
        if count > CAP {
            return Err(PathError::TooManyPoints {
                count,
                capacity: CAP,
            });
        }
        let r = self
            .validate(
                count,
                true,
                |i| (self.xy[i.min(CAP - 1)], self.widths[i.min(CAP - 1)]),
                closed,
            )
            .map(|n| {
                self.compute(n, closed, true);
            });
        if r.is_err() {
            self.clear();
        }
        r
    }

    /// Derives segments, arc length, headings and curvatures from the `n` points
    /// in `xy` (already checked).
    fn compute(&mut self, n: usize, closed: bool, has_widths: bool) {
        let h = T::lit(self.curvature_half_window_m);
        self.n = n;
        self.closed = closed;
        self.has_widths = has_widths;
        let m = self.segment_count();
        // Segments, arc length, unwrapped segment headings (kept in `heading` for now).
        let mut s = T::ZERO;
        let mut prev_theta = T::ZERO;
        // WCET: m = segment_count() <= n <= CAP (= ECU_PATH_ROWS in the ECU).
        // wcet-bound: ECU_PATH_ROWS
        for i in 0..m {
            let a = self.xy[i];
            let b = self.xy[(i + 1) % n];
            let dx = b[0] - a[0];
            let dy = b[1] - a[1];
            let len = dx.hypot(dy);
            self.seg_len[i] = len;
            self.dir[i] = [dx / len, dy / len];
            self.s[i] = s;
            s += len;
            let raw = dy.atan2(dx);
            let theta = if i == 0 {
                raw
            } else {
                prev_theta + wrap_pi(raw - prev_theta)
            };
            self.heading[i] = theta;
            prev_theta = theta;
        }
        if !closed {
            self.s[n - 1] = s;
        }
        self.length = s;
        // Vertex headings from the segment headings (in place, back to front).
        if closed {
            let first = self.heading[0];
            let last = self.heading[m - 1];
            self.total_turn = (last - first) + wrap_pi(first - last);
            // wcet-bound: ECU_PATH_ROWS
            for i in (1..m).rev() {
                self.heading[i] = T::HALF * (self.heading[i - 1] + self.heading[i]);
            }
            self.heading[0] = T::HALF * (last - self.total_turn + first);
        } else {
            self.total_turn = self.heading[m - 1] - self.heading[0];
            self.heading[n - 1] = self.heading[m - 1];
            // wcet-bound: ECU_PATH_ROWS
            for i in (1..m).rev() {
                self.heading[i] = T::HALF * (self.heading[i - 1] + self.heading[i]);
            }
        }
        // Vertex curvatures: circle through the vertices about `h` before and after.
        let max_steps = if closed { (n - 1) / 2 } else { n - 1 };
        // WCET: n <= CAP (= ECU_PATH_ROWS in the ECU); the two step loops below take at
        // most max_steps <= n - 1 steps each (the half-window in metres only stops them earlier).
        // wcet-bound: ECU_PATH_ROWS
        for i in 0..n {
            let mut ia = i;
            let mut back = T::ZERO;
            // wcet-bound: ECU_PATH_ROWS
            for _ in 0..max_steps {
                if back >= h || (!closed && ia == 0) {
                    break;
                }
                ia = if ia == 0 { n - 1 } else { ia - 1 };
                back += self.seg_len[ia];
            }
            let mut ic = i;
            let mut ahead = T::ZERO;
            // wcet-bound: ECU_PATH_ROWS
            for _ in 0..max_steps {
                if ahead >= h || (!closed && ic == n - 1) {
                    break;
                }
                ahead += self.seg_len[ic];
                ic = self.next_vertex(ic);
            }
            self.curvature[i] = if ia == i || ic == i {
                T::ZERO // end of an open path: copied from the neighbour below
            } else {
                circle_curvature(self.xy[ia], self.xy[i], self.xy[ic])
            };
        }
        if !closed {
            self.curvature[0] = self.curvature[1];
            self.curvature[n - 1] = self.curvature[n - 2];
        }
        let mut kmax = T::ZERO;
        // WCET: `curvature` holds CAP (= ECU_PATH_ROWS in the ECU) entries.
        // wcet-bound: ECU_PATH_ROWS
        for k in self.curvature.iter().take(n) {
            kmax = kmax.max(k.abs());
        }
        self.max_abs_curvature = kmax;
    }

    /// Number of vertices loaded (0 when empty).
    pub fn len(&self) -> usize {
        self.n
    }

    /// True when no path is loaded.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Number of segments: `n` for a closed path, `n − 1` for an open one, 0 if empty.
    pub fn segment_count(&self) -> usize {
        if self.n == 0 {
            0
        } else if self.closed {
            self.n
        } else {
            self.n - 1
        }
    }

    /// Total length `L` of the polyline (including the closing segment), m.
    pub fn length_m(&self) -> T {
        self.length
    }

    /// True for a closed loop.
    pub fn is_closed(&self) -> bool {
        self.closed
    }

    /// Heading change over one lap (closed) or from start to end (open), rad.
    pub fn total_turning_rad(&self) -> T {
        self.total_turn
    }

    /// Largest `|κ|` of all vertices, 1/m.
    pub fn max_abs_curvature_1pm(&self) -> T {
        self.max_abs_curvature
    }

    /// Vertex `i` `[x, y]`, m, if loaded.
    pub fn vertex(&self, i: usize) -> Option<[T; 2]> {
        if i < self.n {
            self.xy.get(i).copied()
        } else {
            None
        }
    }

    /// `s` wrapped into `[0, L)` for a closed path, m; unchanged for an open one.
    pub fn wrap_s(&self, s_m: T) -> T {
        if !self.closed || self.length <= T::ZERO {
            return s_m;
        }
        let l = self.length;
        let w = s_m - l * (s_m / l).floor();
        if !w.is_finite() || w >= l || w < T::ZERO {
            T::ZERO
        } else {
            w
        }
    }

    /// The `s_m + k·L` (integer `k`) closest to `s_ref_m`, m, for a closed path
    /// (so that an abscissa from [`Self::project`] continues the MPC's growing
    /// `s`); `s_m` unchanged for an open path.
    pub fn unwrap_s(&self, s_m: T, s_ref_m: T) -> T {
        if !self.closed || self.length <= T::ZERO {
            return s_m;
        }
        let l = self.length;
        let k = ((s_ref_m - s_m) / l + T::HALF).floor();
        s_m + k * l
    }

    /// For `w` in `[0, L]`: the segment containing it and the distance along it, m.
    fn locate(&self, w: T) -> (usize, T) {
        let m = self.segment_count();
        if m == 0 {
            return (0, T::ZERO);
        }
        // Largest i < m with s[i] <= w (binary search, s[0] = 0).
        let mut lo = 0usize;
        let mut hi = m; // invariant: s[lo] <= w (or lo == 0), answer < hi

        // WCET: hi - lo starts at m <= CAP and becomes floor or ceil of its half each
        // step: ceil(log2 m) steps ([`ECU_PATH_SEARCH_STEPS`] for the ECU's CAP).
        // wcet-bound: ECU_PATH_SEARCH_STEPS
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if self.s[mid] <= w {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        (lo, w - self.s[lo])
    }

    /// Index of the vertex at the end of segment `i`.
    #[inline]
    fn next_vertex(&self, i: usize) -> usize {
        if i + 1 < self.n {
            i + 1
        } else {
            0
        }
    }

    /// For any `s`: segment, distance along it (clamped to the segment), the
    /// interpolation fraction, and the number of whole laps (closed paths).
    fn locate_any(&self, s_m: T) -> (usize, T, T, T) {
        let l = self.length;
        if self.n == 0 || l <= T::ZERO {
            return (0, T::ZERO, T::ZERO, T::ZERO);
        }
        let (w, laps) = if self.closed {
            let w = self.wrap_s(s_m);
            (w, ((s_m - w) / l + T::HALF).floor())
        } else {
            (s_m.clamp(T::ZERO, l), T::ZERO)
        };
        let (i, ds) = self.locate(w);
        let len = self.seg_len[i];
        let ds = ds.clamp(T::ZERO, len);
        let f = if len > T::ZERO { ds / len } else { T::ZERO };
        (i, ds, f, laps)
    }

    /// Position `[x, y]` of the path point at arc length `s_m`, m. Wraps on a
    /// closed path; extrapolates along the end segments of an open path.
    /// `[0, 0]` when empty.
    pub fn position_at(&self, s_m: T) -> [T; 2] {
        if self.n == 0 {
            return [T::ZERO; 2];
        }
        if !self.closed {
            let m = self.segment_count();
            if s_m < T::ZERO {
                let p = self.xy[0];
                let d = self.dir[0];
                return [p[0] + d[0] * s_m, p[1] + d[1] * s_m];
            }
            if s_m > self.length {
                let p = self.xy[self.n - 1];
                let d = self.dir[m - 1];
                let e = s_m - self.length;
                return [p[0] + d[0] * e, p[1] + d[1] * e];
            }
        }
        let (i, ds, _, _) = self.locate_any(s_m);
        let p = self.xy[i];
        let d = self.dir[i];
        [p[0] + d[0] * ds, p[1] + d[1] * ds]
    }

    /// Heading of the path at `s_m`, rad, counter-clockwise from the X axis:
    /// linear between vertex headings, continuous and unwrapped in `s` (on a
    /// closed path `heading_at(s + L) = heading_at(s) + total_turning_rad()`).
    pub fn heading_at(&self, s_m: T) -> T {
        if self.n == 0 {
            return T::ZERO;
        }
        let (i, _, f, laps) = self.locate_any(s_m);
        let j = self.next_vertex(i);
        let hj = if j == 0 {
            self.heading[0] + self.total_turn
        } else {
            self.heading[j]
        };
        lerp(self.heading[i], hj, f) + laps * self.total_turn
    }

    /// Curvature of the path at `s_m`, 1/m, positive for a left turn (linear
    /// between vertex curvatures).
    pub fn curvature_at(&self, s_m: T) -> T {
        if self.n == 0 {
            return T::ZERO;
        }
        let (i, _, f, _) = self.locate_any(s_m);
        let j = self.next_vertex(i);
        lerp(self.curvature[i], self.curvature[j], f)
    }

    /// Track half-widths at `s_m`, m (linear between vertices); `None` when the
    /// path was loaded without widths.
    pub fn widths_at(&self, s_m: T) -> Option<Widths<T>> {
        if self.n == 0 || !self.has_widths {
            return None;
        }
        let (i, _, f, _) = self.locate_any(s_m);
        let j = self.next_vertex(i);
        Some(Widths {
            right_m: lerp(self.widths[i][0], self.widths[j][0], f),
            left_m: lerp(self.widths[i][1], self.widths[j][1], f),
        })
    }

    /// Position, heading, curvature and widths at `s_m` (m), with the same values
    /// as [`Self::position_at`], [`Self::heading_at`], [`Self::curvature_at`] and
    /// [`Self::widths_at`], from one segment lookup instead of four.
    pub fn sample_at(&self, s_m: T) -> PathSample<T> {
        if self.n == 0 {
            return PathSample {
                position: [T::ZERO; 2],
                heading_rad: T::ZERO,
                curvature_1pm: T::ZERO,
                widths: None,
                segment: 0,
                segment_offset_m: T::ZERO,
            };
        }
        let (i, ds, f, laps) = self.locate_any(s_m);
        let j = self.next_vertex(i);
        let position = if !self.closed && (s_m < T::ZERO || s_m > self.length) {
            self.position_at(s_m)
        } else {
            let p = self.xy[i];
            let d = self.dir[i];
            [p[0] + d[0] * ds, p[1] + d[1] * ds]
        };
        let hj = if j == 0 {
            self.heading[0] + self.total_turn
        } else {
            self.heading[j]
        };
        let widths = if self.has_widths {
            Some(Widths {
                right_m: lerp(self.widths[i][0], self.widths[j][0], f),
                left_m: lerp(self.widths[i][1], self.widths[j][1], f),
            })
        } else {
            None
        };
        PathSample {
            position,
            heading_rad: lerp(self.heading[i], hj, f) + laps * self.total_turn,
            curvature_1pm: lerp(self.curvature[i], self.curvature[j], f),
            widths,
            segment: i,
            segment_offset_m: ds,
        }
    }

    /// Largest `|κ|` over the arc lengths `[s0_m, s1_m]` (either order), 1/m.
    /// Exact for the piecewise-linear curvature: the end values and the vertices
    /// in between. On a closed path a range of a lap or more gives the global
    /// maximum; on an open path the range is clamped to `[0, L]`.
    pub fn max_abs_curvature_between(&self, s0_m: T, s1_m: T) -> T {
        if self.n == 0 {
            return T::ZERO;
        }
        let (a, b) = sorted(s0_m, s1_m);
        if self.closed && b - a >= self.length {
            return self.max_abs_curvature;
        }
        self.max_curvature_between_by(a, b, T::abs)
    }

    /// The largest `g(κ)` over `[a, b]` (`a <= b`): the end values and the vertices
    /// in between, from one lookup of `a`.
    fn max_curvature_between_by(&self, a: T, b: T, g: impl Fn(T) -> T) -> T {
        // κ(a) as curvature_at(a) computes it, from the one lookup of `a`.
        let (i0, ds0, f0, _) = self.locate_any(a);
        let ka = lerp(self.curvature[i0], self.curvature[self.next_vertex(i0)], f0);
        self.max_curvature_scan(a, b, i0, ds0, ka, g)
    }

    /// [`Self::max_abs_curvature_between`]`(s0_m, s1_m)` (same value) for the
    /// `s0_m` that `at` was sampled at ([`Self::sample_at`]), without looking `s0_m`
    /// up again.
    pub fn max_abs_curvature_from(&self, at: &PathSample<T>, s0_m: T, s1_m: T) -> T {
        if self.n == 0 {
            return T::ZERO;
        }
        let ordered = s0_m <= s1_m;
        if !ordered {
            return self.max_abs_curvature_between(s0_m, s1_m);
        }
        if self.closed && s1_m - s0_m >= self.length {
            return self.max_abs_curvature;
        }
        let (i0, ds0) = (at.segment, at.segment_offset_m);
        self.max_abs_curvature_scan(s0_m, s1_m, i0, ds0, at.curvature_1pm)
    }

    /// [`Self::max_abs_curvature_from`]`(at, s0_m, s1_m)` for a sequence of
    /// windows whose ends never move back (`s0_m`, `s1_m` not below the previous
    /// query's; the MPC's nodes along the horizon), 1/m: while the previous
    /// window's largest vertex is still inside, only the vertices that entered
    /// the window are scanned (`O(vertices entered)` instead of `O(vertices in the
    /// window)`); otherwise, and whenever the ends move back, the window is scanned
    /// afresh. The same maximum as the full scan, up to the rounding of the
    /// vertices' unwrapped arc lengths (summed from the first window's start).
    pub fn max_abs_curvature_window(
        &self,
        win: &mut CurvatureWindow<T>,
        at: &PathSample<T>,
        s0_m: T,
        s1_m: T,
    ) -> T {
        if self.n == 0 {
            return T::ZERO;
        }
        let ordered = s0_m <= s1_m; // false for a NaN
        if !ordered || (self.closed && s1_m - s0_m >= self.length) {
            win.valid = false;
            return self.max_abs_curvature_from(at, s0_m, s1_m);
        }
        // The kept maximum stands for the vertices in `(s0_m, win.b)` if it is
        // attained there (or is at most 0: no vertex, or all scanned vertices flat);
        // the scan then goes on from `win.b`, which must not lie before the new start.
        let keep = win.valid
            && s0_m >= win.a
            && s0_m < win.b
            && s1_m >= win.b
            && (win.vpos > s0_m || win.vmax <= T::ZERO);
        if !keep {
            *win = self.window_at(s0_m, at.segment, at.segment_offset_m);
        }
        self.scan_vertices(win, s1_m, T::abs);
        win.a = s0_m;
        win.b = s1_m;
        at.curvature_1pm
            .abs()
            .max(self.curvature_at(s1_m).abs())
            .max(win.vmax)
    }

    /// A window starting at `a` (unwrapped, m), which lies in segment `i0` at `ds0`
    /// (m) along it, with no vertex scanned yet.
    fn window_at(&self, a: T, i0: usize, ds0: T) -> CurvatureWindow<T> {
        CurvatureWindow {
            a,
            b: a,
            seg: i0,
            // Unwrapped arc length of the start of segment i0.
            pos: if self.closed { a - ds0 } else { self.s[i0] },
            valid: true,
            ..CurvatureWindow::new()
        }
    }

    /// Takes the vertices before `b` (unwrapped, m) into the window's maximum of
    /// `g(κ)`, from where the window's scan stopped; the scan stops after one lap
    /// or at the end of an open path.
    fn scan_vertices(&self, win: &mut CurvatureWindow<T>, b: T, g: impl Fn(T) -> T) {
        let segments = self.segment_count();
        // WCET: `win.steps` grows by one each pass and the scan stops at n <= CAP
        // (= ECU_PATH_ROWS in the ECU); every other exit is a break.
        // wcet-bound: ECU_PATH_ROWS
        while win.steps < self.n && !win.ended {
            if win.seg >= self.n {
                win.seg = 0;
            }
            if win.seg >= segments {
                win.ended = true;
                break;
            }
            let next = win.pos + self.seg_len[win.seg];
            if next >= b {
                break;
            }
            win.pos = next;
            let v = self.next_vertex(win.seg);
            if !self.closed && v == 0 {
                win.ended = true;
                break;
            }
            let kv = g(self.curvature[v]);
            if kv >= win.vmax {
                win.vmax = kv;
                win.vpos = next;
            }
            win.seg += 1;
            win.steps += 1;
        }
    }

    /// The scan of [`Self::max_abs_curvature_between`] over `[a, b]` (`a <= b`),
    /// `a` in segment `i0` at `ds0` along it, `ka = κ(a)`.
    fn max_abs_curvature_scan(&self, a: T, b: T, i0: usize, ds0: T, ka: T) -> T {
        self.max_curvature_scan(a, b, i0, ds0, ka, T::abs)
    }

    /// The largest `sign·κ` over `[s0_m, s1_m]` (either order), 1/m, as
    /// [`Self::max_abs_curvature_between`] finds `|κ|` (end values and the vertices
    /// in between): with `sign` `+1` the sharpest left bend (negative if the range
    /// bends only right), with `−1` the sharpest right bend.
    pub fn max_signed_curvature_between(&self, s0_m: T, s1_m: T, sign: T) -> T {
        if self.n == 0 {
            return T::ZERO;
        }
        let (a, b) = sorted(s0_m, s1_m);
        // A range of a lap or more: every vertex (the scan stops after one lap).
        self.max_curvature_between_by(a, b, |k| sign * k)
    }

    /// The largest `g(κ)` over the end values and the vertices of `[a, b]`, `a`
    /// in segment `i0` at `ds0` along it, `ka = κ(a)`.
    fn max_curvature_scan(&self, a: T, b: T, i0: usize, ds0: T, ka: T, g: impl Fn(T) -> T) -> T {
        let mut win = self.window_at(a, i0, ds0);
        self.scan_vertices(&mut win, b, &g);
        g(ka).max(g(self.curvature_at(b))).max(win.vmax)
    }

    /// Projects the point `p` (`[x, y]`, m) on the path: the closest point of the
    /// polyline (end segments of an open path extended to infinity).
    ///
    /// With `s_hint_m`, only the segments within `[hint − behind, hint + ahead]`
    /// ([`DEFAULT_SEARCH_BEHIND_M`] and [`DEFAULT_SEARCH_AHEAD_M`]) are searched, which
    /// keeps the answer on the right branch where the track crosses or comes back
    /// near itself, and costs `O(window)`; on a closed path the returned `s_m` is
    /// unwrapped to the lap of the hint. Without a hint every segment is searched
    /// and `s_m` is in `[0, L)` (closed paths). The result is the best point in the
    /// window even when the true closest point lies outside it.
    ///
    /// `None` when the path is empty or `p` is not finite.
    pub fn project(&self, p: [T; 2], s_hint_m: Option<T>) -> Option<Projection<T>> {
        self.project_impl(p, s_hint_m, true)
    }

    /// [`Self::project`] on the polyline itself: the end segments of an open path
    /// are not extended, so a point is never matched to the straight line beyond
    /// an end (which can pass near a far part of the road), and `s_m` stays in
    /// `[0, L]`. For what lies beside the road (obstacles), not for the car.
    pub fn project_on_polyline(&self, p: [T; 2], s_hint_m: Option<T>) -> Option<Projection<T>> {
        self.project_impl(p, s_hint_m, false)
    }

    fn project_impl(&self, p: [T; 2], s_hint_m: Option<T>, extend: bool) -> Option<Projection<T>> {
        let m = self.segment_count();
        if m == 0 || !p[0].is_finite() || !p[1].is_finite() {
            return None;
        }
        let behind = T::lit(self.search_behind_m);
        let ahead = T::lit(self.search_ahead_m);
        let hint = s_hint_m.filter(|h| h.is_finite());
        let (first, count) = match hint {
            Some(h) if !self.closed || behind + ahead < self.length => {
                let (i0, ds0, _, _) = self.locate_any(h - behind);
                let end = h + ahead;
                let mut pos = if self.closed {
                    (h - behind) - ds0
                } else {
                    self.s[i0]
                };
                let mut count = 0;
                // WCET: m <= CAP (= ECU_PATH_ROWS in the ECU); the search window is in metres,
                // not in segments (segments may be short), so only m caps it.
                // wcet-bound: ECU_PATH_ROWS
                for step in 0..m {
                    let seg = (i0 + step) % m;
                    if step > 0 && pos > end {
                        break;
                    }
                    if !self.closed && step > 0 && seg == 0 {
                        break;
                    }
                    pos += self.seg_len[seg];
                    count += 1;
                }
                (i0, count)
            }
            _ => (0, m),
        };
        let mut best: Option<(T, usize, T)> = None; // (dist², segment, t)

        // WCET: count <= m <= CAP (= ECU_PATH_ROWS in the ECU).
        // wcet-bound: ECU_PATH_ROWS
        for step in 0..count {
            let i = (first + step) % m;
            let a = self.xy[i];
            let d = self.dir[i];
            let rx = p[0] - a[0];
            let ry = p[1] - a[1];
            let mut t = rx * d[0] + ry * d[1];
            let lo_open = extend && !self.closed && i == 0;
            let hi_open = extend && !self.closed && i + 1 == m;
            if !lo_open {
                t = t.max(T::ZERO);
            }
            if !hi_open {
                t = t.min(self.seg_len[i]);
            }
            let ex = rx - d[0] * t;
            let ey = ry - d[1] * t;
            let d2 = ex * ex + ey * ey;
            let better = match best {
                None => true,
                Some((bd, _, _)) => d2 < bd,
            };
            if better {
                best = Some((d2, i, t));
            }
        }
        let (_, i, t) = best?;
        let a = self.xy[i];
        let d = self.dir[i];
        let foot = [a[0] + d[0] * t, a[1] + d[1] * t];
        let lateral = d[0] * (p[1] - foot[1]) - d[1] * (p[0] - foot[0]);
        let mut s = self.s[i] + t;
        if let Some(h) = hint {
            s = self.unwrap_s(s, h);
        } else {
            s = self.wrap_s(s);
        }
        Some(Projection {
            s_m: s,
            lateral_m: lateral,
            heading_rad: self.heading_at(s),
            curvature_1pm: self.curvature_at(s),
            point_m: foot,
            segment: i,
        })
    }
}

/// `(a, b)` in increasing order (as given when not comparable).
fn sorted<T: Real>(a: T, b: T) -> (T, T) {
    if a <= b {
        (a, b)
    } else {
        (b, a)
    }
}

/// True when two points coincide to within rounding (a zero-length segment).
fn same_point<T: Real>(a: [T; 2], b: [T; 2]) -> bool {
    let scale = T::ONE
        .max(a[0].abs())
        .max(a[1].abs())
        .max(b[0].abs())
        .max(b[1].abs());
    (a[0] - b[0]).abs().max((a[1] - b[1]).abs()) <= T::lit(4.0) * T::EPSILON * scale
}

/// Signed curvature of the circle through `a`, `b`, `c` (1/m, positive when the
/// points turn left); 0 when two of them coincide or they are collinear.
fn circle_curvature<T: Real>(a: [T; 2], b: [T; 2], c: [T; 2]) -> T {
    let abx = b[0] - a[0];
    let aby = b[1] - a[1];
    let bcx = c[0] - b[0];
    let bcy = c[1] - b[1];
    let acx = c[0] - a[0];
    let acy = c[1] - a[1];
    let cross = abx * bcy - aby * bcx;
    let den = abx.hypot(aby) * bcx.hypot(bcy) * acx.hypot(acy);
    if !den.is_finite() || den <= T::ZERO {
        return T::ZERO;
    }
    T::TWO * cross / den
}
