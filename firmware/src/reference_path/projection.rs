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
