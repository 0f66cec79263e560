//! The largest curvature over a stretch of the path: exact for the
//! piecewise-linear curvature (the end values and the vertices in between), in
//! one query or as a sliding window ([`CurvatureWindow`]) that scans only the
//! vertices entering it.

use super::*;

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

impl<T: Real, const CAP: usize> ReferencePath<T, CAP> {
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
    /// or at the end of an open path. Not inlined, and over local copies of the
    /// window's fields (written back once): in its own frame the scan's state
    /// stays in registers, where inlined into the MPC step every trip reloaded
    /// and stored it through the stack; its loop calls nothing, so it keeps its
    /// flash lines in the cache. The same steps in the same order as on `win`.
    #[inline(never)]
    fn scan_vertices(&self, win: &mut CurvatureWindow<T>, b: T, g: impl Fn(T) -> T) {
        let segments = self.segment_count();
        let (mut seg, mut pos, mut steps, mut ended) = (win.seg, win.pos, win.steps, win.ended);
        let (mut vmax, mut vpos) = (win.vmax, win.vpos);
        // WCET: `steps` grows by one each pass and the scan stops at n <= CAP
        // (= ECU_PATH_ROWS in the ECU); every other exit is a break.
        // wcet-bound: ECU_PATH_ROWS
        while steps < self.n && !ended {
            if seg >= self.n {
                seg = 0;
            }
            if seg >= segments {
                ended = true;
                break;
            }
            let next = pos + self.seg_len[seg];
            if next >= b {
                break;
            }
            pos = next;
            let v = self.next_vertex(seg);
            if !self.closed && v == 0 {
                ended = true;
                break;
            }
            let kv = g(self.curvature[v]);
            if kv >= vmax {
                vmax = kv;
                vpos = next;
            }
            seg += 1;
            steps += 1;
        }
        (win.seg, win.pos, win.steps, win.ended) = (seg, pos, steps, ended);
        (win.vmax, win.vpos) = (vmax, vpos);
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
}

/// `(a, b)` in increasing order (as given when not comparable).
fn sorted<T: Real>(a: T, b: T) -> (T, T) {
    if a <= b {
        (a, b)
    } else {
        (b, a)
    }
}
