//! Loading a reference path: the points (and widths) checked, then everything a
//! query needs precomputed once: the arc length, the segments'
//! lengths, the unwrapped headings and total turning, and the vertex curvatures
//! over the configurable half-window (the formulas are in [`super`]'s
//! documentation).

use super::*;

impl<T: Real, const CAP: usize> ReferencePath<T, CAP> {
    /// Sets the curvature half-window `h`, m (used by the next [`Self::load`]). On
    /// a path so dense that `h` spans more than [`MAX_CURVATURE_WINDOW_STEPS`]
    /// segments, the window ends after that many.
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
        let r = self.check_search_density();
        if r.is_err() {
            self.clear();
        }
        r
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
            .and_then(|n| {
                self.compute(n, closed, true);
                self.check_search_density()
            });
        if r.is_err() {
            self.clear();
        }
        r
    }

    /// Refuses a path on which a projection's search near a hint would scan more
    /// segments than its limit ([`Self::with_search_segments`]): from some point,
    /// that many or more
    /// points lie within the search's span (behind + ahead) of it. A search from
    /// a hint covers the segment holding `hint − behind` and the segments that
    /// start before `hint + ahead`: those start within the span of the first of
    /// them, so at most `MAX_SEARCH_SEGMENTS` when this holds. One pass with two
    /// indices (the end of each point's span only moves forward), over one lap
    /// past the end of a closed path. Not inlined: its inner loop's bound is per
    /// call.
    #[inline(never)]
    fn check_search_density(&self) -> Result<(), PathError> {
        let m = self.segment_count();
        if self.search_segments >= CAP {
            // No limit of its own: a search scans at most the path's m < CAP.
            return Ok(());
        }
        let n = self.n;
        let span = T::lit(self.search_behind_m + self.search_ahead_m);
        // The start of segment `j`, counted past the end of a closed path
        // (unwrapped by its length).
        let start = |j: usize| {
            if j < m {
                self.s[j]
            } else {
                self.s[(j - m).min(n - 1)] + self.length
            }
        };
        let end = |i: usize| if self.closed { i + m } else { m };
        let mut j = 0;
        // WCET: m <= CAP (= ECU_PATH_ROWS in the ECU).
        // wcet-bound: ECU_PATH_ROWS
        for i in 0..m {
            j = j.max(i + 1);
            // `j` only moves forward, to at most 2·m over the call.
            // wcet-bound: 2 * ECU_PATH_ROWS per call
            while j < end(i) && start(j) - self.s[i] < span {
                j += 1;
            }
            if j - i >= self.search_segments {
                return Err(PathError::TooDense { index: i });
            }
        }
        Ok(())
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
            self.s[i] = s;
            s += len;
            let raw = dy.atan2(dx);
            let theta = if i == 0 {
                raw
            } else {
                prev_theta + wrap_below_pi(raw - prev_theta)
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
            self.total_turn = (last - first) + wrap_below_pi(first - last);
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
        // Vertex curvatures: circle through the vertices about `h` before and after,
        // at most MAX_CURVATURE_WINDOW_STEPS segments away.
        let max_steps = if closed { (n - 1) / 2 } else { n - 1 };
        let max_steps = max_steps.min(MAX_CURVATURE_WINDOW_STEPS);
        // WCET: n <= CAP (= ECU_PATH_ROWS in the ECU).
        // wcet-bound: ECU_PATH_ROWS
        for i in 0..n {
            let mut ia = i;
            let mut back = T::ZERO;
            // wcet-bound: MAX_CURVATURE_WINDOW_STEPS
            for _ in 0..max_steps {
                if back >= h || (!closed && ia == 0) {
                    break;
                }
                ia = if ia == 0 { n - 1 } else { ia - 1 };
                back += self.seg_len[ia];
            }
            let mut ic = i;
            let mut ahead = T::ZERO;
            // wcet-bound: MAX_CURVATURE_WINDOW_STEPS
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
}

/// Wraps an angle into `[−π, π)` (π itself maps to −π), rad, for the headings'
/// unwrapping; [`crate::low_level::wrap_pi`] wraps into `(−π, π]` instead.
#[inline]
fn wrap_below_pi<T: Real>(a: T) -> T {
    let two_pi = T::TWO * T::PI;
    a - two_pi * ((a + T::PI) / two_pi).floor()
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
