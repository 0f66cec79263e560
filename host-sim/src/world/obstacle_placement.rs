//! Obstacles placed on any track: a box at an arc length and a lateral offset, and
//! random boxes (`--obstacles random:N`, N per km) drawn reproducibly from a seed,
//! each on the road and each refused and drawn again when the firmware's own check
//! says it blocks the road (no room for the car on either side,
//! [`firmware::obstacles::ObstacleError::RoadBlocked`]).
//!
//! # The random draw
//!
//! `round(N × lap length / 1 km)` boxes, at most [`firmware::obstacles::MAX_OBSTACLES`]
//! (the planner's capacity), spread along the lap: box `k` in the `k`-th of equal
//! slices of the lap after the first [`START_CLEAR_M`] (the car starts there), at
//! a uniform position in the middle 60 % of its slice (so two boxes are never
//! closer than 40 % of a slice). Its size is one of a cone (1 × 1 m), a box
//! (2 × 1.5 m) or a parked car (4.5 × 1.8 m), uniformly; its centre's lateral
//! offset is uniform across the road's half-widths less half its width. A box the
//! firmware says blocks the road is drawn again (size and offset, up to 20 times,
//! then left out: the row's `obstacle_count` says how many were placed).

use anyhow::{anyhow, Result};
use firmware::obstacles::{Obstacle as FwObstacle, ObstacleManager, MAX_OBSTACLES};
use firmware::reference_path::ReferencePath;

use crate::model::vehicle::{vehicle_config, VehicleParams};
use crate::world::disturbance::SplitMix64;
use crate::world::obstacle_file::Obstacle;
use crate::world::route::HOST_PATH_CAP;
use crate::world::track::Track;

/// Road kept clear of random obstacles after the start, m.
pub const START_CLEAR_M: f64 = 150.0;

/// The candidate sizes `(length along the road, width across)`, m.
const SIZES: [(f64, f64); 3] = [(1.0, 1.0), (2.0, 1.5), (4.5, 1.8)];

/// Segment `(i, j)` and fraction along it of arc length `s_m` (wrapped on a closed
/// track); `arcs` is [`Track::arc_lengths`].
fn locate(track: &Track, arcs: &[f64], s_m: f64) -> (usize, usize, f64) {
    let n = track.points.len();
    let total = track.length();
    let q = if track.closed && total > 0.0 {
        s_m.rem_euclid(total)
    } else {
        s_m
    };
    let nseg = track.segment_count().max(1);
    let i = arcs
        .partition_point(|&a| a <= q)
        .saturating_sub(1)
        .min(nseg - 1);
    let j = (i + 1) % n.max(1);
    let (a, b) = (track.points[i], track.points[j]);
    let len = (b[0] - a[0]).hypot(b[1] - a[1]).max(1e-9);
    (i, j, ((q - arcs[i]) / len).clamp(0.0, 1.0))
}

/// Half-widths `[right, left]` of the road at arc length `s_m`, m; `arcs` is
/// [`Track::arc_lengths`].
pub fn widths_at(track: &Track, arcs: &[f64], s_m: f64) -> [f64; 2] {
    let (i, j, f) = locate(track, arcs, s_m);
    [
        track.w_right[i] + f * (track.w_right[j] - track.w_right[i]),
        track.w_left[i] + f * (track.w_left[j] - track.w_left[i]),
    ]
}

/// Position, heading and half-widths `[right, left]` of the centre line at arc
/// length `s_m` (wrapped on a closed track), m and rad.
pub fn pose_at(track: &Track, s_m: f64) -> ([f64; 2], f64, [f64; 2]) {
    let arcs = track.arc_lengths();
    let (i, j, f) = locate(track, &arcs, s_m);
    let (a, b) = (track.points[i], track.points[j]);
    let p = [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])];
    (
        p,
        (b[1] - a[1]).atan2(b[0] - a[0]),
        widths_at(track, &arcs, s_m),
    )
}

/// A `length × width` box (m) centred `lateral_m` left of the centre line at arc
/// length `s_m`, aligned with the road.
pub fn box_at(track: &Track, id: &str, s_m: f64, lateral_m: f64, size: (f64, f64)) -> Obstacle {
    let (p, h, _) = pose_at(track, s_m);
    let (sn, cs) = h.sin_cos();
    let c = [p[0] - sn * lateral_m, p[1] + cs * lateral_m];
    let (hl, hw) = (0.5 * size.0, 0.5 * size.1);
    let corner = |u: f64, v: f64| [c[0] + cs * u - sn * v, c[1] + sn * u + cs * v];
    Obstacle {
        id: id.to_string(),
        vertices: vec![
            corner(-hl, -hw),
            corner(hl, -hw),
            corner(hl, hw),
            corner(-hl, hw),
        ],
    }
}

/// The firmware's view of the track and its obstacle check for one car and friction.
pub struct RoadCheck {
    path: Box<ReferencePath<f64, HOST_PATH_CAP>>,
    settings: firmware::obstacles::ObstacleSettings<f64>,
}

impl RoadCheck {
    /// The check for `track`, the car `vehicle` and the planner's friction `mu`.
    pub fn new(track: &Track, vehicle: &VehicleParams, mu: f64) -> Result<Self> {
        let mut path: Box<ReferencePath<f64, HOST_PATH_CAP>> = Box::new(ReferencePath::new());
        path.load_track(&track.rows(), track.closed)
            .map_err(|e| anyhow!("track {}: the planner refused it: {e:?}", track.name))?;
        Ok(Self {
            path,
            settings: vehicle_config::<f64>(vehicle).obstacle_settings(mu),
        })
    }

    /// True when the firmware finds room for the car beside `o`.
    pub fn leaves_room(&self, o: &Obstacle) -> bool {
        let Ok(fw) = FwObstacle::from_vertices(0, &o.vertices) else {
            return false;
        };
        let mut m = ObstacleManager::new();
        // Any refusal (blocked road, an obstacle the manager cannot use) counts.
        m.update(&self.settings, &self.path, &[fw]).is_ok()
    }
}

/// `per_km` random boxes per km on `track`, from `seed` (module docs).
pub fn random_obstacles(track: &Track, per_km: f64, seed: u64, check: &RoadCheck) -> Vec<Obstacle> {
    let mut rng = SplitMix64::new(seed ^ 0x6F62_7374_6163_6C65);
    let total = track.length();
    let usable = (total - START_CLEAR_M - 50.0).max(0.0);
    let count = ((per_km * total / 1000.0).round() as usize).min(MAX_OBSTACLES);
    if count == 0 || usable <= 0.0 {
        return Vec::new();
    }
    let slice = usable / count as f64;
    let mut out = Vec::new();
    for k in 0..count {
        let s = START_CLEAR_M + slice * (k as f64 + rng.range(0.2, 0.8));
        let (_, _, w) = pose_at(track, s);
        for _ in 0..20 {
            let size = SIZES[(rng.uniform() * SIZES.len() as f64) as usize % SIZES.len()];
            let lo = -(w[0] - 0.5 * size.1).max(0.0);
            let hi = (w[1] - 0.5 * size.1).max(0.0);
            let o = box_at(track, &format!("random_{k}"), s, rng.range(lo, hi), size);
            if check.leaves_room(&o) {
                out.push(o);
                break;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn random_obstacles_are_reproducible_on_the_road_and_leave_room() -> Result<()> {
        let track = crate::world::scenario::Scenario::paper(false).track;
        let car = VehicleParams::default();
        let check = RoadCheck::new(&track, &car, 1.0)?;
        let a = random_obstacles(&track, 3.0, 11, &check);
        let b = random_obstacles(&track, 3.0, 11, &check);
        let c = random_obstacles(&track, 3.0, 12, &check);
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert!(!a.is_empty());
        let proj = track.projector();
        for o in &a {
            assert!(check.leaves_room(o));
            for v in &o.vertices {
                let (_, lat) = proj.project(*v, None);
                assert!(lat.abs() <= 4.0 + 1e-6, "{} off the road: {lat}", o.id);
            }
        }
        Ok(())
    }
}
