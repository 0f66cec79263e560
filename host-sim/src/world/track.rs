//! Tracks: centre line and half-widths of a road, loaded from the CSV format of
//! the public racetrack database or generated from straight and arc pieces.
//!
//! # File format
//!
//! ```text
//! # x_m,y_m,w_tr_right_m,w_tr_left_m
//! -2.447973,0.125932,6.187,6.476
//! ...
//! ```
//!
//! One centre-line point per row: `x_m`, `y_m` in metres (world frame), then the
//! distance from the centre line to the right and to the left road edge, in
//! metres, looking along the direction of travel (the row order).
//!
//! - The header line is optional, with or without its leading `#`. When present
//!   it must name the columns as above (case and surrounding spaces ignored).
//! - Files with only the two columns `x_m,y_m` are accepted: both half-widths
//!   then default to [`DEFAULT_HALF_WIDTH_M`] (3.5 m each side).
//! - Later lines starting with `#` are comments.
//! - A track is a closed loop unless the caller says otherwise (`closed`). On a
//!   closed track a last point equal to the first (within [`SAME_POINT_M`]) is
//!   tolerated and dropped, since the loop closes by itself.
//! - Rejected, with the file and line named: unparsable or non-finite numbers,
//!   negative widths, fewer than 3 points, two consecutive equal points (a
//!   zero-length segment).
//!
//! # Geometry
//!
//! Arc length `s` (m) runs along the polyline through the points, from the first
//! point; on a closed track it includes the segment from the last point back to
//! the first and wraps into `[0, length)`. The lateral offset (m) is positive to
//! the left of the direction of travel, like `w_left`.

use crate::world::csv_value::{csv_lines, CsvLine};
use std::io::Read;
use std::path::Path;

/// Half-width (m) used on both sides when a track file has only `x_m,y_m`.
pub const DEFAULT_HALF_WIDTH_M: f64 = 3.5;

/// Two points closer than this (m) are the same point.
pub const SAME_POINT_M: f64 = 1e-6;

/// Half-length (m) of the arc-length window searched around a hint by
/// [`Track::project`].
pub const PROJECTION_WINDOW_M: f64 = 30.0;

/// The header the database uses, written by [`Track::to_csv_string`].
pub const TRACK_HEADER: &str = "# x_m,y_m,w_tr_right_m,w_tr_left_m";

const COLUMN_NAMES: [&str; 4] = ["x_m", "y_m", "w_tr_right_m", "w_tr_left_m"];

/// Why a track could not be loaded. Each message names the file (or the name
/// given to [`Track::from_csv_reader`]) and, where there is one, the line.
#[derive(Debug, thiserror::Error)]
pub enum TrackError {
    /// The file could not be opened or read.
    #[error("{file}: cannot read the track file: {cause}")]
    Io {
        /// File name.
        file: String,
        /// Why (in the message; not a `source()`, so a chain prints it once).
        cause: std::io::Error,
    },
    /// The CSV structure itself is broken (e.g. invalid UTF-8).
    #[error("{file}: line {line}: not a readable CSV line ({cause}); save the track as plain comma-separated text")]
    Csv {
        /// File name.
        file: String,
        /// 1-based line number.
        line: u64,
        /// Why (in the message; not a `source()`, so a chain prints it once).
        cause: csv::Error,
    },
    /// A header line that does not name the expected columns.
    #[error("{file}: line {line}: unexpected header `{found}`; expected `# x_m,y_m,w_tr_right_m,w_tr_left_m` (or `x_m,y_m` for a centre line without widths)")]
    BadHeader {
        /// File name.
        file: String,
        /// 1-based line number.
        line: u64,
        /// The header as found.
        found: String,
    },
    /// A row with a number of columns other than the header's (or 2 or 4).
    #[error("{file}: line {line}: {found} columns, expected {expected} (x_m,y_m[,w_tr_right_m,w_tr_left_m]); every row needs the same columns")]
    WrongColumns {
        /// File name.
        file: String,
        /// 1-based line number.
        line: u64,
        /// Columns found.
        found: usize,
        /// Columns expected.
        expected: usize,
    },
    /// A cell that is not a finite number.
    #[error(transparent)]
    Value(#[from] crate::world::csv_value::CsvValueError),
    /// A negative half-width.
    #[error("{file}: line {line}: column `{column}` is {value} m; a half-width is a distance from the centre line and must be >= 0")]
    NegativeWidth {
        /// File name.
        file: String,
        /// 1-based line number.
        line: u64,
        /// Column name.
        column: &'static str,
        /// The value found (m).
        value: f64,
    },
    /// Too few points for a path.
    #[error("{file}: {found} distinct point(s); a track needs at least 3 centre-line points")]
    TooFewPoints {
        /// File name.
        file: String,
        /// Points found.
        found: usize,
    },
    /// Two consecutive points at the same place (a zero-length segment).
    #[error("{file}: lines {first_line} and {second_line} are the same point ({x}, {y}); remove one of them (a zero-length segment has no direction)")]
    RepeatedPoint {
        /// File name.
        file: String,
        /// 1-based line of the first of the two points.
        first_line: u64,
        /// 1-based line of the second.
        second_line: u64,
        /// x of the point (m).
        x: f64,
        /// y of the point (m).
        y: f64,
    },
}

/// A road: centre-line points and the half-widths at each point.
///
/// Invariants established by the loaders (and assumed by the geometry
/// methods): all vectors have the same length, at least 3 points, all values
/// finite, widths >= 0, no two consecutive points equal (including last-first
/// on a closed track).
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// Name: the file stem, or the built-in name.
    pub name: String,
    /// Centre-line points `[x, y]` (m), in the direction of travel.
    pub points: Vec<[f64; 2]>,
    /// Distance from centre line to the right road edge at each point (m).
    pub w_right: Vec<f64>,
    /// Distance from centre line to the left road edge at each point (m).
    pub w_left: Vec<f64>,
    /// Whether the last point connects back to the first.
    pub closed: bool,
}

/// One piece of an analytically defined track: a straight or a circular arc,
/// joined tangentially to the previous piece.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrackPiece {
    /// A straight of the given length (m).
    Straight {
        /// Length (m), > 0.
        length_m: f64,
    },
    /// A circular arc.
    Arc {
        /// Radius (m), > 0.
        radius_m: f64,
        /// Heading change (rad): positive turns left, negative right.
        angle_rad: f64,
    },
}

impl TrackPiece {
    /// Length of the piece along the centre line (m).
    pub fn length(&self) -> f64 {
        match *self {
            TrackPiece::Straight { length_m } => length_m,
            TrackPiece::Arc {
                radius_m,
                angle_rad,
            } => radius_m * angle_rad.abs(),
        }
    }

    /// Curvature of the piece (1/m), positive turning left.
    pub fn curvature(&self) -> f64 {
        match *self {
            TrackPiece::Straight { .. } => 0.0,
            TrackPiece::Arc {
                radius_m,
                angle_rad,
            } => angle_rad.signum() / radius_m,
        }
    }

    /// Pose `[x (m), y (m), heading (rad)]` reached after travelling `d` metres
    /// (0 <= d <= length) along this piece from `start`. Exact (closed form).
    pub fn pose_at(&self, start: [f64; 3], d: f64) -> [f64; 3] {
        let [x, y, th] = start;
        match *self {
            TrackPiece::Straight { .. } => [x + d * th.cos(), y + d * th.sin(), th],
            TrackPiece::Arc {
                radius_m,
                angle_rad,
            } => {
                let sg = angle_rad.signum();
                let a = sg * d / radius_m;
                // Centre of the circle, to the left (sg > 0) or right of the heading.
                let cx = x - sg * radius_m * th.sin();
                let cy = y + sg * radius_m * th.cos();
                let t = th + a;
                [
                    cx + sg * radius_m * t.sin(),
                    cy - sg * radius_m * t.cos(),
                    t,
                ]
            }
        }
    }

    /// Pose at the end of the piece.
    pub fn end_pose(&self, start: [f64; 3]) -> [f64; 3] {
        self.pose_at(start, self.length())
    }
}

/// Pose `[x (m), y (m), heading (rad)]` at arc length `s` (m) along pieces
/// chained from `start`; `s` is clamped to `[0, total length]`.
pub fn pose_along(pieces: &[TrackPiece], start: [f64; 3], s: f64) -> [f64; 3] {
    let mut pose = start;
    let mut rest = s.max(0.0);
    for (i, piece) in pieces.iter().enumerate() {
        let l = piece.length();
        if rest <= l || i + 1 == pieces.len() {
            return piece.pose_at(pose, rest.min(l));
        }
        pose = piece.end_pose(pose);
        rest -= l;
    }
    pose
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

impl Track {
    /// Loads a track file (see the module docs for the format). The track's
    /// name is the file stem.
    pub fn from_csv_path(path: impl AsRef<Path>, closed: bool) -> Result<Track, TrackError> {
        let path = path.as_ref();
        let file = path.display().to_string();
        let f = std::fs::File::open(path).map_err(|cause| TrackError::Io {
            file: file.clone(),
            cause,
        })?;
        let mut track = Track::parse(f, &file, closed)?;
        track.name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or(file);
        Ok(track)
    }

    /// Loads a track from any reader; `name` names the track and stands for
    /// the file in error messages.
    pub fn from_csv_reader(
        reader: impl Read,
        name: &str,
        closed: bool,
    ) -> Result<Track, TrackError> {
        Track::parse(reader, name, closed)
    }

    fn parse(reader: impl Read, file: &str, closed: bool) -> Result<Track, TrackError> {
        let mut columns: Option<usize> = None;
        let mut points = Vec::new();
        let mut w_right = Vec::new();
        let mut w_left = Vec::new();
        let mut lines: Vec<u64> = Vec::new();
        let x_numeric = |r: &csv::StringRecord| r.get(0).is_some_and(|x| x.parse::<f64>().is_ok());
        for item in csv_lines(reader, x_numeric) {
            let (line, rec) = match item {
                Err((line, cause)) => {
                    return Err(TrackError::Csv {
                        file: file.to_string(),
                        line,
                        cause,
                    })
                }
                Ok(CsvLine::Header { line, names, found }) => {
                    let ok = (names.len() == 2 || names.len() == 4)
                        && names.iter().zip(COLUMN_NAMES).all(|(n, e)| n == e);
                    if !ok {
                        return Err(TrackError::BadHeader {
                            file: file.to_string(),
                            line,
                            found,
                        });
                    }
                    columns = Some(names.len());
                    continue;
                }
                Ok(CsvLine::Row { line, record }) => (line, record),
            };
            let expected = match columns {
                Some(c) => c,
                None => {
                    let c = if rec.len() == 2 { 2 } else { 4 };
                    columns = Some(c);
                    c
                }
            };
            if rec.len() != expected {
                return Err(TrackError::WrongColumns {
                    file: file.to_string(),
                    line,
                    found: rec.len(),
                    expected,
                });
            }
            let mut v = [0.0; 4];
            for (i, slot) in v.iter_mut().enumerate().take(expected) {
                *slot = crate::world::csv_value::finite_metres(
                    file,
                    line,
                    COLUMN_NAMES[i],
                    rec.get(i).unwrap_or(""),
                )?;
            }
            if expected == 2 {
                v[2] = DEFAULT_HALF_WIDTH_M;
                v[3] = DEFAULT_HALF_WIDTH_M;
            }
            for i in 2..4 {
                if v[i] < 0.0 {
                    return Err(TrackError::NegativeWidth {
                        file: file.to_string(),
                        line,
                        column: COLUMN_NAMES[i],
                        value: v[i],
                    });
                }
            }
            let p = [v[0], v[1]];
            if let (Some(&prev), Some(&prev_line)) = (points.last(), lines.last()) {
                if dist(prev, p) < SAME_POINT_M {
                    return Err(TrackError::RepeatedPoint {
                        file: file.to_string(),
                        first_line: prev_line,
                        second_line: line,
                        x: p[0],
                        y: p[1],
                    });
                }
            }
            points.push(p);
            w_right.push(v[2]);
            w_left.push(v[3]);
            lines.push(line);
        }
        if closed && points.len() >= 2 {
            if let (Some(&a), Some(&b)) = (points.first(), points.last()) {
                if dist(a, b) < SAME_POINT_M {
                    points.pop();
                    w_right.pop();
                    w_left.pop();
                    lines.pop();
                }
            }
        }
        if points.len() < 3 {
            return Err(TrackError::TooFewPoints {
                file: file.to_string(),
                found: points.len(),
            });
        }
        Ok(Track {
            name: file.to_string(),
            points,
            w_right,
            w_left,
            closed,
        })
    }

    /// Builds a track from tangentially joined pieces starting at
    /// `start = [x (m), y (m), heading (rad)]`, sampled with at most `spacing_m`
    /// between points (each piece is cut into equal steps, its end being the
    /// next piece's start), with constant half-widths `half_width_m` on both
    /// sides. On a closed track the end of the last piece is not emitted (it is
    /// the start again); on an open one it is.
    pub fn from_pieces(
        name: &str,
        start: [f64; 3],
        pieces: &[TrackPiece],
        spacing_m: f64,
        half_width_m: f64,
        closed: bool,
    ) -> Track {
        let spacing = if spacing_m.is_finite() && spacing_m > 0.0 {
            spacing_m
        } else {
            1.0
        };
        let mut points = Vec::new();
        let mut pose = start;
        for piece in pieces {
            let l = piece.length();
            let n = (l / spacing).ceil().max(1.0) as usize;
            for i in 0..n {
                let q = piece.pose_at(pose, l * i as f64 / n as f64);
                points.push([q[0], q[1]]);
            }
            pose = piece.end_pose(pose);
        }
        if !closed {
            points.push([pose[0], pose[1]]);
        }
        let n = points.len();
        Track {
            name: name.to_string(),
            points,
            w_right: vec![half_width_m; n],
            w_left: vec![half_width_m; n],
            closed,
        }
    }

    /// Rows `[x (m), y (m), w_right (m), w_left (m)]`, the layout
    /// `firmware::reference_path::ReferencePath::load_track` takes.
    pub fn rows(&self) -> Vec<[f64; 4]> {
        self.points
            .iter()
            .zip(self.w_right.iter().zip(&self.w_left))
            .map(|(p, (r, l))| [p[0], p[1], *r, *l])
            .collect()
    }

    /// The track in the database's CSV format (header [`TRACK_HEADER`], six
    /// decimals, i.e. micrometres).
    pub fn to_csv_string(&self) -> String {
        let mut out = String::with_capacity(40 * self.points.len() + 40);
        out.push_str(TRACK_HEADER);
        out.push('\n');
        for r in self.rows() {
            out.push_str(&format!(
                "{:.6},{:.6},{:.6},{:.6}\n",
                r[0], r[1], r[2], r[3]
            ));
        }
        out
    }

    /// Number of segments: points - 1, plus the closing one on a closed track.
    pub fn segment_count(&self) -> usize {
        if self.points.len() < 2 {
            0
        } else if self.closed {
            self.points.len()
        } else {
            self.points.len() - 1
        }
    }

    fn segment(&self, i: usize) -> ([f64; 2], [f64; 2]) {
        let n = self.points.len();
        (self.points[i % n], self.points[(i + 1) % n])
    }

    /// Arc length (m) at each point: 0 at the first. O(n).
    pub fn arc_lengths(&self) -> Vec<f64> {
        let mut s = Vec::with_capacity(self.points.len());
        let mut acc = 0.0;
        for (i, p) in self.points.iter().enumerate() {
            if i > 0 {
                acc += dist(self.points[i - 1], *p);
            }
            s.push(acc);
        }
        s
    }

    /// Total length (m) of the centre line, including the closing segment on a
    /// closed track.
    pub fn length(&self) -> f64 {
        (0..self.segment_count())
            .map(|i| {
                let (a, b) = self.segment(i);
                dist(a, b)
            })
            .sum()
    }

    /// A copy with points inserted by linear interpolation (of position and
    /// widths) so that no segment is longer than `max_spacing_m` (m); each long
    /// segment is cut into equal parts. Existing points are kept. A non-positive
    /// or non-finite spacing returns an unchanged copy.
    pub fn resampled(&self, max_spacing_m: f64) -> Track {
        if !(max_spacing_m.is_finite() && max_spacing_m > 0.0) {
            return self.clone();
        }
        let n = self.points.len();
        let mut out = Track {
            name: self.name.clone(),
            points: Vec::new(),
            w_right: Vec::new(),
            w_left: Vec::new(),
            closed: self.closed,
        };
        // Widths missing from a hand-built track read as the default.
        let wr = |k: usize| self.w_right.get(k).copied().unwrap_or(DEFAULT_HALF_WIDTH_M);
        let wl = |k: usize| self.w_left.get(k).copied().unwrap_or(DEFAULT_HALF_WIDTH_M);
        for i in 0..n {
            out.points.push(self.points[i]);
            out.w_right.push(wr(i));
            out.w_left.push(wl(i));
            if i + 1 == n && !self.closed {
                break;
            }
            let j = (i + 1) % n;
            let (a, b) = (self.points[i], self.points[j]);
            let parts = (dist(a, b) / max_spacing_m).ceil() as usize;
            for k in 1..parts {
                let t = k as f64 / parts as f64;
                out.points
                    .push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
                out.w_right.push(wr(i) + t * (wr(j) - wr(i)));
                out.w_left.push(wl(i) + t * (wl(j) - wl(i)));
            }
        }
        out
    }

    /// Signed curvature estimate at each point (1/m, positive turning left):
    /// the Menger curvature of the point and its two neighbours (the circle
    /// through the three points). The two end points of an open track get the
    /// value of their neighbour.
    pub fn curvature(&self) -> Vec<f64> {
        let n = self.points.len();
        let mut k = vec![0.0; n];
        for (i, ki) in k.iter_mut().enumerate() {
            if !self.closed && (i == 0 || i + 1 == n) {
                continue;
            }
            let a = self.points[(i + n - 1) % n];
            let b = self.points[i];
            let c = self.points[(i + 1) % n];
            let cross = (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]);
            let den = dist(a, b) * dist(b, c) * dist(a, c);
            if den > 0.0 {
                *ki = 2.0 * cross / den;
            }
        }
        if !self.closed && n >= 3 {
            k[0] = k[1];
            k[n - 1] = k[n - 2];
        }
        k
    }

    /// Smallest radius of curvature (m) over the points, from
    /// [`Track::curvature`]; infinite for a straight line.
    pub fn min_radius(&self) -> f64 {
        let kmax = self.curvature().iter().fold(0.0_f64, |m, k| m.max(k.abs()));
        if kmax > 0.0 {
            1.0 / kmax
        } else {
            f64::INFINITY
        }
    }

    /// Projects `p = [x, y]` (m) onto the centre line and returns
    /// `(s, lateral)`: arc length of the closest centre-line point (m, in
    /// `[0, length)` on a closed track) and the signed distance to it (m,
    /// positive left of the direction of travel).
    ///
    /// Brute force over segments. With `hint_s = Some(s)` (m, e.g. the previous
    /// result) only segments within [`PROJECTION_WINDOW_M`] of arc length of
    /// the hint (wrapping on a closed loop) are searched, so a track that comes
    /// back near itself does not make the projection jump to the other branch;
    /// if the closest point found lies at the edge of that window the point has
    /// left it, and the whole track is searched instead. Without a hint the
    /// whole track is searched. O(n).
    pub fn project(&self, p: [f64; 2], hint_s: Option<f64>) -> (f64, f64) {
        self.projector().project(p, hint_s)
    }

    /// A [`Projector`]: the track's segment lengths computed once, for projecting
    /// many points (the simulator projects the car every 10 ms).
    pub fn projector(&self) -> Projector<'_> {
        let nseg = self.segment_count();
        let mut s0 = Vec::with_capacity(nseg);
        let mut len = Vec::with_capacity(nseg);
        let mut acc = 0.0;
        for i in 0..nseg {
            let (a, b) = self.segment(i);
            let l = dist(a, b);
            s0.push(acc);
            len.push(l);
            acc += l;
        }
        Projector {
            track: self,
            s0,
            len,
            total: acc,
        }
    }

    /// Pose `[x (m), y (m), heading (rad)]` on the centre line at the first
    /// point, heading towards the second.
    pub fn start_pose(&self) -> [f64; 3] {
        match (self.points.first(), self.points.get(1)) {
            (Some(a), Some(b)) => [a[0], a[1], (b[1] - a[1]).atan2(b[0] - a[0])],
            (Some(a), None) => [a[0], a[1], 0.0],
            _ => [0.0, 0.0, 0.0],
        }
    }
}

/// Projection onto a [`Track`] with its segment lengths computed once
/// ([`Track::projector`]); same results as [`Track::project`].
#[derive(Debug, Clone)]
pub struct Projector<'a> {
    track: &'a Track,
    /// Arc length at the start of each segment, m.
    s0: Vec<f64>,
    /// Length of each segment, m.
    len: Vec<f64>,
    /// Track length, m.
    total: f64,
}

impl Projector<'_> {
    /// As [`Track::project`]: `(s, lateral)`, m, of the point `p` (m), searched
    /// near `hint_s` (m) when given.
    pub fn project(&self, p: [f64; 2], hint_s: Option<f64>) -> (f64, f64) {
        let track = self.track;
        let total = self.total;
        if !(total > 0.0 && total.is_finite()) {
            return (0.0, 0.0);
        }
        let circ = |a: f64, b: f64| -> f64 {
            let d = (a - b).abs();
            if track.closed && total > 0.0 {
                let d = d % total;
                d.min(total - d)
            } else {
                d
            }
        };
        let search = |window: Option<f64>| -> Option<(f64, f64, f64)> {
            let mut best: Option<(f64, f64, f64)> = None; // (dist, s, lateral)
            for (i, (&s0, &len)) in self.s0.iter().zip(&self.len).enumerate() {
                let (a, b) = track.segment(i);
                if let Some(h) = window {
                    // Distance in arc length from the hint to this segment.
                    let gap = if track.closed {
                        let rel = (h - s0).rem_euclid(total);
                        if rel <= len {
                            0.0
                        } else {
                            (rel - len).min(total - rel)
                        }
                    } else if h >= s0 && h <= s0 + len {
                        0.0
                    } else {
                        (h - s0).abs().min((h - s0 - len).abs())
                    };
                    let inside = gap <= PROJECTION_WINDOW_M;
                    if !inside {
                        continue;
                    }
                }
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let l2 = dx * dx + dy * dy;
                if l2 <= 0.0 {
                    continue;
                }
                let t = (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0);
                let q = [a[0] + t * dx, a[1] + t * dy];
                // Squared distance to compare; the root only for the result.
                let d2 = (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]);
                if best.is_none_or(|(bd, _, _)| d2 < bd) {
                    let cross = dx * (p[1] - a[1]) - dy * (p[0] - a[0]);
                    let mut s = s0 + t * len;
                    if track.closed && total > 0.0 && s >= total {
                        s -= total;
                    }
                    best = Some((d2, s, if cross >= 0.0 { 1.0 } else { -1.0 }));
                }
            }
            best.map(|(d2, s, sign)| (d2, s, sign * d2.sqrt()))
        };
        let local = hint_s.filter(|h| h.is_finite()).and_then(|h| {
            search(Some(h)).filter(|&(_, s, _)| {
                let at_edge = circ(s, h) >= PROJECTION_WINDOW_M - 1e-9;
                let at_open_end = !track.closed && (s <= 0.0 || s >= total);
                !at_edge || at_open_end
            })
        });
        match local.or_else(|| search(None)) {
            Some((_, s, lat)) => (s, lat),
            None => (0.0, 0.0),
        }
    }
}
