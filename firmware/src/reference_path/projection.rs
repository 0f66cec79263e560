//! Projecting a point on the reference path: the closest point of the polyline,
//! searched near a hint (the last plan's abscissa) or over every segment.

use super::*;

impl<T: Real, const CAP: usize> ReferencePath<T, CAP> {
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

    /// [`Self::project`] of each of `points` with the one hint `s_hint_m`, keeping
    /// what placing an obstacle needs: `(s_m, lateral_m)` (m, as in [`Projection`])
    /// per point, `None` for a point that is not finite or on an empty path; only
    /// the first `K` points are projected. The search window is found once for all
    /// the points, then scanned per point: the segments a call of `project` per
    /// point searches, in the same order and with the same arithmetic, so the same
    /// results bit for bit, without a window search (and the heading and curvature
    /// lookups) per point. The hint is required (a search near it, never a scan of
    /// the whole path): with one not finite, every point gives `None`.
    pub fn project_each<const K: usize>(
        &self,
        points: &[[T; 2]],
        s_hint_m: T,
    ) -> [Option<(T, T)>; K] {
        let mut out = [None; K];
        let m = self.segment_count();
        if m == 0 || !s_hint_m.is_finite() {
            return out;
        }
        let n = points.len().min(K);
        let hint = Some(s_hint_m);
        let (first, count) = self.search_window(hint);
        // One scan per point (a scan of all the points per segment, unrolled by the
        // compiler, is longer than the instruction cache holds).
        // WCET: K = MAX_VERTICES at the one caller (`obstacles::build_inner`).
        // wcet-bound: MAX_VERTICES
        for k in 0..n {
            let p = points[k];
            // No `continue`: one path back to the loop's head keeps it one loop.
            let found = if p[0].is_finite() && p[1].is_finite() {
                self.closest(p, first, count, true, true)
            } else {
                None
            };
            if let Some((_, i, t)) = found {
                let (s, lateral, _) = self.foot(p, i, t, hint);
                out[k] = Some((s, lateral));
            }
        }
        out
    }

    /// The segments a search near `hint` covers, `(first, count)`: every segment
    /// without a hint (or when the window would cover a closed path's whole lap).
    fn search_window(&self, hint: Option<T>) -> (usize, usize) {
        let m = self.segment_count();
        let behind = T::lit(self.search_behind_m);
        let ahead = T::lit(self.search_ahead_m);
        match hint {
            Some(h) if !self.closed || behind + ahead < self.length => {
                let (i0, ds0, _, _) = self.locate_any(h - behind);
                let end = h + ahead;
                let mut pos = if self.closed {
                    (h - behind) - ds0
                } else {
                    self.s[i0]
                };
                let mut count = 0;
                // The search window is in metres; the load's density rule
                // (`check_search_density`) keeps it within the path's limit of
                // segments, which the loop's range states. WCET: the plan task's
                // path has the limit MAX_SEARCH_SEGMENTS (`PlanTask::new`).
                // wcet-bound: MAX_SEARCH_SEGMENTS
                for step in 0..m.min(self.search_segments) {
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
        }
    }

    /// The segment of the `count` from `first` (wrapping) closest to `p`, the first
    /// of equals: `(dist², segment, t)` (m², index, m along it); `None` when
    /// `count` is 0. `near`: a search near a hint ([`Self::search_window`]), at
    /// most the path's limit of segments (which the load's density rule keeps
    /// from cutting it short); else a scan of the whole path. Two loops, each
    /// with its own bound.
    #[inline(always)]
    fn closest(
        &self,
        p: [T; 2],
        first: usize,
        count: usize,
        near: bool,
        extend: bool,
    ) -> Option<(T, usize, T)> {
        let m = self.segment_count();
        let mut best: Option<(T, usize, T)> = None;
        if near {
            // WCET: the plan task's path has the limit MAX_SEARCH_SEGMENTS
            // (`PlanTask::new`).
            // wcet-bound: MAX_SEARCH_SEGMENTS
            for step in 0..count.min(self.search_segments) {
                self.closer(p, (first + step) % m, m, extend, &mut best);
            }
        } else {
            // WCET: count <= m <= CAP (= ECU_PATH_ROWS in the ECU).
            // wcet-bound: ECU_PATH_ROWS
            for step in 0..count {
                self.closer(p, (first + step) % m, m, extend, &mut best);
            }
        }
        best
    }

    /// Keeps segment `i` in `best` when it is closer to `p` than `best` (the first
    /// of equals stays).
    #[inline(always)]
    fn closer(
        &self,
        p: [T; 2],
        i: usize,
        m: usize,
        extend: bool,
        best: &mut Option<(T, usize, T)>,
    ) {
        let (d2, t) = self.segment_distance(p, i, m, extend);
        let better = match *best {
            None => true,
            Some((bd, _, _)) => d2 < bd,
        };
        if better {
            *best = Some((d2, i, t));
        }
    }

    /// The squared distance from `p` to segment `i` of the `m` segments, m², and
    /// the distance `t` along it of the closest point, m (an open path's end
    /// segments extended when `extend`).
    #[inline(always)]
    fn segment_distance(&self, p: [T; 2], i: usize, m: usize, extend: bool) -> (T, T) {
        let a = self.xy[i];
        let d = self.dir(i);
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
        (ex * ex + ey * ey, t)
    }

    /// The point `t` m along segment `i` as seen from `p`: its abscissa (unwrapped
    /// to the lap of `hint`, else wrapped to `[0, L)`), m, the signed lateral
    /// offset of `p`, m, and the foot point `[x, y]`, m.
    #[inline(always)]
    fn foot(&self, p: [T; 2], i: usize, t: T, hint: Option<T>) -> (T, T, [T; 2]) {
        let a = self.xy[i];
        let d = self.dir(i);
        let foot = [a[0] + d[0] * t, a[1] + d[1] * t];
        let lateral = d[0] * (p[1] - foot[1]) - d[1] * (p[0] - foot[0]);
        let s = self.s[i] + t;
        let s = match hint {
            Some(h) => self.unwrap_s(s, h),
            None => self.wrap_s(s),
        };
        (s, lateral, foot)
    }

    fn project_impl(&self, p: [T; 2], s_hint_m: Option<T>, extend: bool) -> Option<Projection<T>> {
        let m = self.segment_count();
        if m == 0 || !p[0].is_finite() || !p[1].is_finite() {
            return None;
        }
        let hint = s_hint_m.filter(|h| h.is_finite());
        let (first, count) = self.search_window(hint);
        let (_, i, t) = self.closest(p, first, count, hint.is_some(), extend)?;
        let (s, lateral, foot) = self.foot(p, i, t, hint);
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
