//! Scenarios: a track, its obstacles, the road friction (and its patches) and the
//! initial state; the built-in `paper` scenario, and resolution of the command-line choices
//! `--track paper|FILE` and `--obstacles none|paper|FILE`.
//!
//! # The `paper` track
//!
//! In the spirit of the test track of Polack et al. (ACC 2018, Section V):
//! long straights alternating with small-radius curves, down to 10 m. A closed
//! anticlockwise loop of straights and circular arcs joined tangentially,
//! starting at the origin heading along +x, half-width [`PAPER_HALF_WIDTH_M`]
//! on both sides, sampled every [`PAPER_SPACING_M`] at most. See
//! [`paper_pieces`] for the list. Two straights (the westward top straight and
//! the southward back straight) have their lengths solved from the others so
//! the loop closes exactly (a 2x2 linear system; the heading closes because the
//! turns add up to 360 degrees).
//!
//! # The `paper` obstacles
//!
//! Boxes placed in the track frame (arc length along the exact centre line,
//! lateral offset positive left, length along the road, width across), listed
//! in [`PAPER_OBSTACLES`]. Each leaves at least [`PAPER_MIN_FREE_WIDTH_M`]
//! of free road on one side.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

use crate::world::obstacle_file::{
    load_obstacles_path, obstacles_to_csv_string, vehicle_footprint, Obstacle, ObstacleError,
};
use crate::world::road_friction::MuPatch;
use crate::world::road_grade::GradePatch;
use crate::world::track::{pose_along, Track, TrackError, TrackPiece};

/// Half-width of the `paper` track on each side of the centre line (m).
pub const PAPER_HALF_WIDTH_M: f64 = 4.0;

/// Maximum spacing of the `paper` track's points (m).
pub const PAPER_SPACING_M: f64 = 1.0;

/// Road friction coefficient of the paper's simulations (-).
pub const PAPER_MU: f64 = 1.0;

/// Initial speed of the paper's simulations (m/s).
pub const PAPER_INITIAL_SPEED_MPS: f64 = 15.0;

/// Width of the paper's car (m), used to check the obstacle placement.
pub const CAR_WIDTH_M: f64 = 1.8;

/// Free road width (m) each `paper` obstacle leaves on at least one side:
/// the car's width plus 1 m of margin.
pub const PAPER_MIN_FREE_WIDTH_M: f64 = CAR_WIDTH_M + 1.0;

/// A box obstacle placed in the track frame of the `paper` track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxPlacement {
    /// Obstacle id.
    pub id: &'static str,
    /// Index into [`paper_pieces`] of the piece it stands on.
    pub piece: usize,
    /// Distance from the start of that piece to the box centre (m).
    pub offset_m: f64,
    /// Lateral offset of the box centre from the centre line (m, + left).
    pub lateral_m: f64,
    /// Length along the road (m).
    pub length_m: f64,
    /// Width across the road (m).
    pub width_m: f64,
}

/// The `paper` obstacles. Free side = the side with at least
/// [`PAPER_MIN_FREE_WIDTH_M`] of road (half-width 4 m).
pub const PAPER_OBSTACLES: [BoxPlacement; 6] = [
    // Parked car on the start straight, right of centre: free left (5.3 m).
    BoxPlacement {
        id: "parked_car_right",
        piece: 0,
        offset_m: 70.0,
        lateral_m: -2.2,
        length_m: 4.5,
        width_m: 1.8,
    },
    // Cone on the east straight, left of centre: free right (5.0 m).
    BoxPlacement {
        id: "cone_left",
        piece: 2,
        offset_m: 40.0,
        lateral_m: 1.5,
        length_m: 1.0,
        width_m: 1.0,
    },
    // Box across the centre line on the top straight: free left (3.25 m).
    BoxPlacement {
        id: "box_across_centre",
        piece: 7,
        offset_m: 60.0,
        lateral_m: -0.5,
        length_m: 2.0,
        width_m: 2.5,
    },
    // Cones right of centre after the hairpin: free left (5.25 m).
    BoxPlacement {
        id: "cones_after_hairpin",
        piece: 9,
        offset_m: 30.0,
        lateral_m: -2.0,
        length_m: 2.0,
        width_m: 1.5,
    },
    // Parked car left of centre on the south straight: free right (5.2 m).
    BoxPlacement {
        id: "parked_car_left",
        piece: 11,
        offset_m: 30.0,
        lateral_m: 2.1,
        length_m: 4.5,
        width_m: 1.8,
    },
    // Car just past the exit of the R30 left curve, left of centre:
    // free right (4.3 m).
    BoxPlacement {
        id: "car_curve_exit",
        piece: 15,
        offset_m: 6.0,
        lateral_m: 1.2,
        length_m: 4.2,
        width_m: 1.8,
    },
];

fn straight(length_m: f64) -> TrackPiece {
    TrackPiece::Straight { length_m }
}

fn arc(radius_m: f64, angle_rad: f64) -> TrackPiece {
    TrackPiece::Arc {
        radius_m,
        angle_rad,
    }
}

/// Index in [`paper_pieces`] of the top straight whose length closes the loop.
const TOP_STRAIGHT: usize = 7;
/// Index in [`paper_pieces`] of the back straight whose length closes the loop.
const BACK_STRAIGHT: usize = 15;

fn paper_pieces_with(top_m: f64, back_m: f64) -> Vec<TrackPiece> {
    vec![
        straight(120.0),       // 0: start straight, east
        arc(30.0, FRAC_PI_2),  // 1: left 90, R30 -> north
        straight(100.0),       // 2: east straight, north
        arc(25.0, -FRAC_PI_4), // 3: S-bend, right 45, R25
        arc(25.0, FRAC_PI_4),  // 4: S-bend, left 45, R25 -> north
        straight(80.0),        // 5: north
        arc(20.0, FRAC_PI_2),  // 6: left 90, R20 -> west
        straight(top_m),       // 7: top straight, west (solved)
        arc(10.0, PI),         // 8: hairpin, left 180, R10 -> east
        straight(50.0),        // 9: east, 20 m below the top straight
        arc(15.0, -FRAC_PI_2), // 10: right 90, R15 -> south
        straight(60.0),        // 11: south
        arc(20.0, -FRAC_PI_2), // 12: right 90, R20 -> west
        straight(50.0),        // 13: west
        arc(30.0, FRAC_PI_2),  // 14: left 90, R30 -> south
        straight(back_m),      // 15: back straight, south (solved)
        arc(25.0, FRAC_PI_2),  // 16: left 90, R25 -> east, back at start
    ]
}

fn end_of(pieces: &[TrackPiece]) -> [f64; 3] {
    pieces
        .iter()
        .fold([0.0, 0.0, 0.0], |pose, p| p.end_pose(pose))
}

/// The pieces of the `paper` track, from the origin heading along +x
/// (anticlockwise loop, total turn +360 degrees):
///
/// | # | piece | |
/// |---|---|---|
/// | 0 | straight 120 m | start straight, east |
/// | 1 | left 90 deg, R 30 m | |
/// | 2 | straight 100 m | north |
/// | 3, 4 | right 45 deg then left 45 deg, R 25 m | S-bend |
/// | 5 | straight 80 m | north |
/// | 6 | left 90 deg, R 20 m | |
/// | 7 | straight ~134.6 m (solved) | top straight, west |
/// | 8 | left 180 deg, R 10 m | hairpin |
/// | 9 | straight 50 m | east, 20 m beside the top straight |
/// | 10 | right 90 deg, R 15 m | |
/// | 11 | straight 60 m | south |
/// | 12 | right 90 deg, R 20 m | |
/// | 13 | straight 50 m | west |
/// | 14 | left 90 deg, R 30 m | |
/// | 15 | straight ~95.4 m (solved) | back straight, south |
/// | 16 | left 90 deg, R 25 m | back to the start |
pub fn paper_pieces() -> Vec<TrackPiece> {
    // The end position is affine in the two free lengths:
    // end(a, b) = end(0, 0) + a u_top + b u_back. Solve end(a, b) = 0.
    let base = paper_pieces_with(0.0, 0.0);
    let e0 = end_of(&base);
    let heading_at = |k: usize| end_of(&base[..k])[2];
    let (t1, t2) = (heading_at(TOP_STRAIGHT), heading_at(BACK_STRAIGHT));
    let (u1, u2) = ([t1.cos(), t1.sin()], [t2.cos(), t2.sin()]);
    let det = u1[0] * u2[1] - u1[1] * u2[0];
    let a = (-e0[0] * u2[1] + e0[1] * u2[0]) / det;
    let b = (-u1[0] * e0[1] + u1[1] * e0[0]) / det;
    paper_pieces_with(a, b)
}

/// Pose `[x (m), y (m), heading (rad)]` on the exact centre line of the
/// `paper` track at arc length `s` (m, clamped to the loop).
pub fn paper_pose_at(s: f64) -> [f64; 3] {
    pose_along(&paper_pieces(), [0.0, 0.0, 0.0], s)
}

/// The built-in `paper` track (closed, name `paper`).
pub fn paper_track() -> Track {
    Track::from_pieces(
        "paper",
        [0.0, 0.0, 0.0],
        &paper_pieces(),
        PAPER_SPACING_M,
        PAPER_HALF_WIDTH_M,
        true,
    )
}

/// The built-in `paper` obstacles: the boxes of [`PAPER_OBSTACLES`] as
/// rectangles aligned with the road.
pub fn paper_obstacles() -> Vec<Obstacle> {
    let pieces = paper_pieces();
    PAPER_OBSTACLES
        .iter()
        .map(|b| {
            let s0: f64 = pieces.iter().take(b.piece).map(TrackPiece::length).sum();
            let [x, y, th] = pose_along(&pieces, [0.0, 0.0, 0.0], s0 + b.offset_m);
            let (cx, cy) = (x - b.lateral_m * th.sin(), y + b.lateral_m * th.cos());
            Obstacle {
                id: b.id.to_string(),
                vertices: vehicle_footprint(cx, cy, th, b.length_m, b.width_m).to_vec(),
            }
        })
        .collect()
}

/// The built-in track as a track file, as shipped in `host-sim/tracks/paper.csv`.
pub fn paper_track_csv() -> String {
    paper_track().to_csv_string()
}

/// The built-in obstacles as an obstacle file, as shipped in
/// `host-sim/tracks/paper_obstacles.csv`.
pub fn paper_obstacles_csv() -> String {
    obstacles_to_csv_string(&paper_obstacles())
}

/// What a simulation runs on.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Name, `paper` or the track's name.
    pub name: String,
    /// The road.
    pub track: Track,
    /// Static obstacles (possibly none).
    pub obstacles: Vec<Obstacle>,
    /// Road friction coefficient (-).
    pub mu: f64,
    /// Patches of road with their own friction (`--mu-patch`; see
    /// [`crate::world::road_friction`]); none by default.
    pub mu_patches: Vec<MuPatch>,
    /// Stretches of road that rise or fall (`--grade`; see
    /// [`crate::world::road_grade`]); level by default.
    pub grade_patches: Vec<GradePatch>,
    /// Initial longitudinal speed (m/s).
    pub initial_speed_mps: f64,
    /// Initial pose `[x (m), y (m), heading (rad)]`: on the centre line at
    /// s = 0, heading along the track.
    pub start_pose: [f64; 3],
}

/// Why a scenario could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The track file is bad.
    #[error(transparent)]
    Track(#[from] TrackError),
    /// The obstacle file is bad.
    #[error(transparent)]
    Obstacles(#[from] ObstacleError),
    /// `--obstacles paper` with a track other than `paper`.
    #[error("the `paper` obstacles are placed on the `paper` track; with the track `{track}` use `--obstacles none` or an obstacle file")]
    PaperObstaclesNeedPaperTrack {
        /// The track argument given.
        track: String,
    },
    /// `paper` track asked for as an open track.
    #[error("the built-in `paper` track is a closed loop; `--open` only applies to track files")]
    PaperTrackIsClosed,
}

impl Scenario {
    /// The paper's scenario: the `paper` track, friction 1, 15 m/s, starting
    /// at s = 0 heading along +x; with the `paper` obstacles or none.
    pub fn paper(with_obstacles: bool) -> Scenario {
        Scenario {
            name: "paper".to_string(),
            track: paper_track(),
            obstacles: if with_obstacles {
                paper_obstacles()
            } else {
                Vec::new()
            },
            mu: PAPER_MU,
            mu_patches: Vec::new(),
            grade_patches: Vec::new(),
            initial_speed_mps: PAPER_INITIAL_SPEED_MPS,
            start_pose: [0.0, 0.0, 0.0],
        }
    }
}

/// Sets up a scenario from the command-line strings: `track_arg` is `paper`
/// or a track file path; `obstacles_arg` is `none`, `paper` (only with the
/// `paper` track) or an obstacle file path; `closed` says whether a track file
/// is a closed loop (the `paper` track always is: `closed = false` with it is
/// an error). Friction and initial speed are the paper's (1, 15 m/s); the
/// start pose is the track's first point, heading to its second.
pub fn resolve(
    track_arg: &str,
    obstacles_arg: &str,
    closed: bool,
) -> Result<Scenario, ScenarioError> {
    let is_paper = track_arg == "paper";
    if is_paper && !closed {
        return Err(ScenarioError::PaperTrackIsClosed);
    }
    let track = if is_paper {
        paper_track()
    } else {
        Track::from_csv_path(track_arg, closed)?
    };
    let obstacles = match obstacles_arg {
        "none" => Vec::new(),
        "paper" if is_paper => paper_obstacles(),
        "paper" => {
            return Err(ScenarioError::PaperObstaclesNeedPaperTrack {
                track: track_arg.to_string(),
            })
        }
        path => load_obstacles_path(path)?,
    };
    Ok(Scenario {
        name: track.name.clone(),
        start_pose: track.start_pose(),
        track,
        obstacles,
        mu: PAPER_MU,
        mu_patches: Vec::new(),
        grade_patches: Vec::new(),
        initial_speed_mps: PAPER_INITIAL_SPEED_MPS,
    })
}
