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
//! * the length of every segment (its unit direction is computed from it and the
//!   two vertices where a query needs it, the same values bit for bit);
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
//!   vertices each way, and on any path at most [`MAX_CURVATURE_WINDOW_STEPS`]
//!   segments each way (a path denser than `h / 32`). The two end vertices of an
//!   open path take the curvature of their neighbour. Collinear points give
//!   `κ = 0`.
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
//! This file holds the path and its queries at one arc length; the submodules
//! `loading` the loading and precomputation, `projection` the projection of a
//! point, `curvature_window` the largest curvature over a stretch of the path.
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

mod curvature_window;
mod loading;
mod projection;

pub use curvature_window::CurvatureWindow;

use crate::Real;

/// Default half-window `h` of the curvature estimate, m.
pub const DEFAULT_CURVATURE_HALF_WINDOW_M: f32 = 3.0;

/// Most segments the curvature half-window spans on each side of a vertex, a
/// count: the window ends after `h` metres or this many segments, whichever comes
/// first. It bounds the cost of a load (on the ECU, of the window adoption) by
/// `2·n·MAX_CURVATURE_WINDOW_STEPS` steps rather than `2·n²` on a path of `n`
/// points; with the default 3 m half-window it binds only where points are closer
/// than about 0.1 m.
pub const MAX_CURVATURE_WINDOW_STEPS: usize = 32;

/// Largest |coordinate| and half-width a path accepts, m (10,000 km: any map frame).
/// Larger finite values (up to `f32::MAX`) made the segment lengths and the arc
/// length overflow to infinity, and every query after them garbage (found by
/// `firmware/tests/fuzz.rs`).
pub const MAX_COORDINATE_M: f32 = 1.0e7;
/// Most segments a projection with a hint scans in the plan task
/// ([`ReferencePath::with_search_segments`]): its path is refused
/// ([`PathError::TooDense`]) where `MAX_SEARCH_SEGMENTS − 1` or more of its points
/// lie within the search's span ([`DEFAULT_SEARCH_BEHIND_M`] +
/// [`DEFAULT_SEARCH_AHEAD_M`], 60 m) from one of them: points at least 0.63 m
/// apart on average there. The projections of the car and of the obstacles'
/// vertices then each scan at most this many segments, not the whole path.
pub const MAX_SEARCH_SEGMENTS: usize = 96;
/// Default length of path searched behind the hint by [`ReferencePath::project`], m.
pub const DEFAULT_SEARCH_BEHIND_M: f32 = 20.0;
/// Default length of path searched ahead of the hint by [`ReferencePath::project`], m.
pub const DEFAULT_SEARCH_AHEAD_M: f32 = 40.0;

/// Rows of the window of the road the ECU holds (its `PlanTask`'s path capacity;
/// the simulator sends the next window as the car moves on).
pub const ECU_PATH_ROWS: usize = 320;

/// Most steps of the binary search that finds a distance's segment, on a path
/// of the ECU's window ([`ECU_PATH_ROWS`] vertices, so at most as many segments):
/// [`binary_search_steps`] of it, steps (for the WCET analysis).
pub const ECU_PATH_SEARCH_STEPS: usize = binary_search_steps(ECU_PATH_ROWS);

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
    /// From point `index` on, as many points as a projection near a hint may scan
    /// segments ([`ReferencePath::with_search_segments`], [`MAX_SEARCH_SEGMENTS`]
    /// in the plan task) or more lie within the search's span (60 m): the path is
    /// too dense there for the bounded search. Resample it.
    TooDense {
        /// Index of the first point of the dense span.
        index: usize,
    },
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
    /// Most segments a projection near a hint scans (`CAP`: no limit of its
    /// own); a path denser than that allows is refused at load.
    search_segments: usize,
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
            search_segments: CAP,
        }
    }

    /// An empty path whose projections near a hint scan at most `segments`
    /// segments (at least 2; [`MAX_SEARCH_SEGMENTS`] in the plan task): a path on
    /// which the search's span (behind + ahead the hint) could hold more is
    /// refused at load ([`PathError::TooDense`]), so the limit never cuts a
    /// search short. The plan task's projections then cost a bounded scan, not
    /// one of the whole path. A valid `const` initialiser.
    pub const fn with_search_segments(segments: usize) -> Self {
        let mut p = Self::new();
        p.search_segments = if segments < 2 { 2 } else { segments };
        p
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

    /// Unit direction of segment `i` (vertex `i` to the next), from the vertices
    /// and the segment's length as the load computed them: the same values a table
    /// of them would hold, bit for bit, without its `2·CAP` values of RAM (2.5 KB
    /// on the ECU) for two divisions a use.
    #[inline(always)]
    fn dir(&self, i: usize) -> [T; 2] {
        let a = self.xy[i];
        let b = self.xy[self.next_vertex(i)];
        let len = self.seg_len[i];
        [(b[0] - a[0]) / len, (b[1] - a[1]) / len]
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
                let d = self.dir(0);
                return [p[0] + d[0] * s_m, p[1] + d[1] * s_m];
            }
            if s_m > self.length {
                let p = self.xy[self.n - 1];
                let d = self.dir(m - 1);
                let e = s_m - self.length;
                return [p[0] + d[0] * e, p[1] + d[1] * e];
            }
        }
        let (i, ds, _, _) = self.locate_any(s_m);
        let p = self.xy[i];
        let d = self.dir(i);
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
            let d = self.dir(i);
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
}
