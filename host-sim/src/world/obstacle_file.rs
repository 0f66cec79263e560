//! Static obstacles: polygon files, and the polygon geometry the simulator
//! uses to measure clearance and detect collisions.
//!
//! # File format
//!
//! ```text
//! id,x_m,y_m
//! car1,10.0,-3.0
//! car1,14.5,-3.0
//! car1,14.5,-1.2
//! car1,10.0,-1.2
//! cone,40.0,1.0
//! ```
//!
//! One row per polygon vertex: the obstacle's `id` (any text without a comma),
//! then `x_m`, `y_m` in metres (world frame). Decisions:
//!
//! - The header line `id,x_m,y_m` is optional (a leading `#` is allowed).
//!   Lines after the first that start with `#` are comments.
//! - Vertices are grouped by `id` in file order, and form the polygon in that
//!   order (either orientation). An obstacle may have **1 vertex** (a point,
//!   e.g. a cone or post), **2** (a segment, e.g. a barrier) or **3 or more**
//!   (a polygon): the firmware's obstacle parabola only needs the vertices.
//! - The rows of one id must be contiguous: an id that appears again after
//!   other ids is an error (a file that splits a polygon is more likely a
//!   mistake than an intent; merging would silently reorder its vertices).
//! - Rejected, with the file and line named: unparsable or non-finite
//!   coordinates, an empty id, a split id, and a self-intersecting polygon
//!   (two non-adjacent edges crossing; its inside is ambiguous).
//! - A file with no rows gives no obstacles.

use crate::world::csv_value::{csv_lines, CsvLine};
use std::io::Read;
use std::path::Path;

/// A static obstacle: a point, segment or polygon.
#[derive(Debug, Clone, PartialEq)]
pub struct Obstacle {
    /// Identifier, from the file's `id` column.
    pub id: String,
    /// Vertices `[x, y]` (m, world frame), in polygon order; at least one.
    pub vertices: Vec<[f64; 2]>,
}

/// Why an obstacle file could not be loaded. Each message names the file (or
/// the name given to [`load_obstacles_reader`]) and the line.
#[derive(Debug, thiserror::Error)]
pub enum ObstacleError {
    /// The file could not be opened or read.
    #[error("{file}: cannot read the obstacle file: {cause}")]
    Io {
        /// File name.
        file: String,
        /// Why (in the message; not a `source()`, so a chain prints it once).
        cause: std::io::Error,
    },
    /// The CSV structure itself is broken (e.g. invalid UTF-8).
    #[error("{file}: line {line}: not a readable CSV line ({cause}); save the obstacles as plain comma-separated text")]
    Csv {
        /// File name.
        file: String,
        /// 1-based line number.
        line: u64,
        /// Why (in the message; not a `source()`, so a chain prints it once).
        cause: csv::Error,
    },
    /// A header that is not `id,x_m,y_m`.
    #[error(
        "{file}: line {line}: unexpected header `{found}`; expected `id,x_m,y_m` (or no header)"
    )]
    BadHeader {
        /// File name.
        file: String,
        /// 1-based line number.
        line: u64,
        /// The header found.
        found: String,
    },
    /// A row without exactly 3 columns.
    #[error("{file}: line {line}: {found} columns; each row is one vertex `id,x_m,y_m`")]
    WrongColumns {
        /// File name.
        file: String,
        /// 1-based line number.
        line: u64,
        /// Columns found.
        found: usize,
    },
    /// An empty id.
    #[error("{file}: line {line}: empty id; give every vertex the name of its obstacle")]
    EmptyId {
        /// File name.
        file: String,
        /// 1-based line number.
        line: u64,
    },
    /// A cell that is not a finite number.
    #[error(transparent)]
    Value(#[from] crate::world::csv_value::CsvValueError),
    /// The rows of one id are not contiguous.
    #[error("{file}: line {line}: obstacle `{id}` already ended at line {previous_line}, other obstacles came between; keep all rows of one obstacle together (or give this one another id)")]
    SplitId {
        /// File name.
        file: String,
        /// 1-based line of the row that restarts the id.
        line: u64,
        /// 1-based line of the last earlier row of that id.
        previous_line: u64,
        /// The id.
        id: String,
    },
    /// Two non-adjacent edges of a polygon cross.
    #[error("{file}: obstacle `{id}` (lines {first_line}-{last_line}) is self-intersecting: edges {edge_a} and {edge_b} cross; list its vertices in order around the outline")]
    SelfIntersecting {
        /// File name.
        file: String,
        /// The id.
        id: String,
        /// 1-based line of its first vertex.
        first_line: u64,
        /// 1-based line of its last vertex.
        last_line: u64,
        /// Index (0-based, from vertex i to i+1) of one crossing edge.
        edge_a: usize,
        /// Index of the other.
        edge_b: usize,
    },
}

/// Loads an obstacle file (see the module docs for the format).
pub fn load_obstacles_path(path: impl AsRef<Path>) -> Result<Vec<Obstacle>, ObstacleError> {
    let path = path.as_ref();
    let file = path.display().to_string();
    let f = std::fs::File::open(path).map_err(|cause| ObstacleError::Io {
        file: file.clone(),
        cause,
    })?;
    load_obstacles_reader(f, &file)
}

/// Loads obstacles from any reader; `name` stands for the file in errors.
pub fn load_obstacles_reader(
    reader: impl Read,
    name: &str,
) -> Result<Vec<Obstacle>, ObstacleError> {
    let file = name;
    // (obstacle, first line, last line)
    let mut out: Vec<(Obstacle, u64, u64)> = Vec::new();
    let x_numeric = |r: &csv::StringRecord| r.get(1).is_some_and(|x| x.parse::<f64>().is_ok());
    for item in csv_lines(reader, x_numeric) {
        let (line, rec) = match item {
            Err((line, cause)) => {
                return Err(ObstacleError::Csv {
                    file: file.to_string(),
                    line,
                    cause,
                })
            }
            Ok(CsvLine::Header { line, names, found }) => {
                if names != ["id", "x_m", "y_m"] {
                    return Err(ObstacleError::BadHeader {
                        file: file.to_string(),
                        line,
                        found,
                    });
                }
                continue;
            }
            Ok(CsvLine::Row { line, record }) => (line, record),
        };
        let head = rec.get(0).unwrap_or("");
        if rec.len() != 3 {
            return Err(ObstacleError::WrongColumns {
                file: file.to_string(),
                line,
                found: rec.len(),
            });
        }
        if head.is_empty() {
            return Err(ObstacleError::EmptyId {
                file: file.to_string(),
                line,
            });
        }
        let x =
            crate::world::csv_value::finite_metres(file, line, "x_m", rec.get(1).unwrap_or(""))?;
        let y =
            crate::world::csv_value::finite_metres(file, line, "y_m", rec.get(2).unwrap_or(""))?;
        match out.last_mut() {
            Some((o, _, last)) if o.id == head => {
                o.vertices.push([x, y]);
                *last = line;
            }
            _ => {
                if let Some((_, _, prev)) = out.iter().find(|(o, _, _)| o.id == head) {
                    return Err(ObstacleError::SplitId {
                        file: file.to_string(),
                        line,
                        previous_line: *prev,
                        id: head.to_string(),
                    });
                }
                out.push((
                    Obstacle {
                        id: head.to_string(),
                        vertices: vec![[x, y]],
                    },
                    line,
                    line,
                ));
            }
        }
    }
    for (o, first_line, last_line) in &out {
        if let Some((edge_a, edge_b)) = self_intersection(&o.vertices) {
            return Err(ObstacleError::SelfIntersecting {
                file: file.to_string(),
                id: o.id.clone(),
                first_line: *first_line,
                last_line: *last_line,
                edge_a,
                edge_b,
            });
        }
    }
    Ok(out.into_iter().map(|(o, _, _)| o).collect())
}

/// Writes obstacles as an `id,x_m,y_m` file (with header, six decimals).
pub fn obstacles_to_csv_string(obstacles: &[Obstacle]) -> String {
    let mut out = String::from("id,x_m,y_m\n");
    for o in obstacles {
        for v in &o.vertices {
            out.push_str(&format!("{},{:.6},{:.6}\n", o.id, v[0], v[1]));
        }
    }
    out
}

/// The first pair of non-adjacent edges that intersect, as edge indices (edge
/// `i` joins vertex `i` to `i + 1`, the last one back to vertex 0), or `None`.
/// Only polygons (>= 4 vertices) can self-intersect.
pub fn self_intersection(vertices: &[[f64; 2]]) -> Option<(usize, usize)> {
    let n = vertices.len();
    if n < 4 {
        return None;
    }
    for i in 0..n {
        for j in (i + 2)..n {
            if i == 0 && j == n - 1 {
                continue; // adjacent through the closing edge
            }
            let (a, b) = (vertices[i], vertices[(i + 1) % n]);
            let (c, d) = (vertices[j], vertices[(j + 1) % n]);
            if segments_intersect(a, b, c, d) {
                return Some((i, j));
            }
        }
    }
    None
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

fn on_segment(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
    p[0] >= a[0].min(b[0])
        && p[0] <= a[0].max(b[0])
        && p[1] >= a[1].min(b[1])
        && p[1] <= a[1].max(b[1])
}

/// Whether segments `ab` and `cd` (m) share at least one point (touching
/// counts).
pub fn segments_intersect(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let d1 = cross(c, d, a);
    let d2 = cross(c, d, b);
    let d3 = cross(a, b, c);
    let d4 = cross(a, b, d);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(c, d, a))
        || (d2 == 0.0 && on_segment(c, d, b))
        || (d3 == 0.0 && on_segment(a, b, c))
        || (d4 == 0.0 && on_segment(a, b, d))
}

fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

fn segment_distance(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> f64 {
    if segments_intersect(a, b, c, d) {
        return 0.0;
    }
    point_segment_distance(a, c, d)
        .min(point_segment_distance(b, c, d))
        .min(point_segment_distance(c, a, b))
        .min(point_segment_distance(d, a, b))
}

/// Edges of a shape: a point is one degenerate edge, a segment one edge, a
/// polygon its closed outline.
fn edges(v: &[[f64; 2]]) -> impl Iterator<Item = ([f64; 2], [f64; 2])> + '_ {
    let n = v.len();
    let count = match n {
        0 => 0,
        1 | 2 => 1,
        _ => n,
    };
    (0..count).map(move |i| (v[i], v[(i + 1) % n]))
}

/// Whether `p` (m) lies inside or on the polygon `poly` (>= 3 vertices; any
/// orientation; even-odd rule). Always false for points and segments.
pub fn point_in_polygon(p: [f64; 2], poly: &[[f64; 2]]) -> bool {
    if poly.len() < 3 {
        return false;
    }
    let mut inside = false;
    for (a, b) in edges(poly) {
        if point_segment_distance(p, a, b) == 0.0 {
            return true;
        }
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// Whether two shapes (points, segments or simple polygons, vertices in m)
/// overlap or touch: an edge of one crosses an edge of the other, or one lies
/// inside the other. Empty shapes never intersect.
pub fn intersects(a: &[[f64; 2]], b: &[[f64; 2]]) -> bool {
    if a.is_empty() || b.is_empty() {
        return false;
    }
    for (p, q) in edges(a) {
        for (r, s) in edges(b) {
            if segments_intersect(p, q, r, s) {
                return true;
            }
        }
    }
    point_in_polygon(a[0], b) || point_in_polygon(b[0], a)
}

/// Smallest distance (m) between two shapes (points, segments or simple
/// polygons): 0 when they overlap or touch ([`intersects`]), otherwise the
/// smallest edge-to-edge distance. Infinite if either shape is empty.
pub fn distance(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    if intersects(a, b) {
        return 0.0;
    }
    let mut best = f64::INFINITY;
    for (p, q) in edges(a) {
        for (r, s) in edges(b) {
            best = best.min(segment_distance(p, q, r, s));
        }
    }
    best
}

/// The rectangle covered by a vehicle: centred at `(x, y)` (m), its length
/// `length_m` (m) along the heading `psi` (rad, from the x axis,
/// anticlockwise) and its width `width_m` (m) across. Vertices anticlockwise
/// from the front-right corner. The caller passes the centre of the body,
/// which is not the centre of gravity in general.
pub fn vehicle_footprint(x: f64, y: f64, psi: f64, length_m: f64, width_m: f64) -> [[f64; 2]; 4] {
    let (c, s) = (psi.cos(), psi.sin());
    let (hl, hw) = (0.5 * length_m, 0.5 * width_m);
    let corner = |u: f64, v: f64| [x + u * c - v * s, y + u * s + v * c];
    [
        corner(hl, -hw),
        corner(hl, hw),
        corner(-hl, hw),
        corner(-hl, -hw),
    ]
}
