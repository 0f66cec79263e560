//! Conversions between the link's frames ([`firmware::link`]) and the simulator's
//! types: a window's rows as `PathChunk` frames, a plan event's plan, an actuation
//! frame's actuation, and what a refused set-up means.

use firmware::link::{self, Down, PathChunkFrame, PlanEventFrame, PATH_CHUNK_ROWS};
use firmware::low_level::{Actuation, Mode};
use firmware::plan::{Plan, PlanNode, PLAN_DT_S};

/// The plan of a plan event (positions only: what the consistency measure needs).
pub fn plan_of(p: &PlanEventFrame) -> Plan<f32> {
    let mut plan = Plan::zeroed();
    plan.stamp_us = p.release_us;
    plan.dt_s = PLAN_DT_S;
    for (n, xy) in plan.nodes.iter_mut().zip(p.nodes_xy.iter()) {
        *n = PlanNode {
            x_m: xy[0],
            y_m: xy[1],
            ..PlanNode::default()
        };
    }
    plan.v_heur_mps[0] = p.v_heur0_mps;
    plan
}

/// The actuation of an actuator frame (the fields the simulator uses).
pub fn actuation_of(a: &link::ActuationFrame) -> Actuation<f32> {
    Actuation {
        wheel_torque_nm: a.torque_nm,
        delta_rad: a.delta_rad,
        delta_ol_rad: a.delta_ol_rad,
        delta_cl_rad: a.delta_cl_rad,
        v_ref_mps: a.v_ref_mps,
        v_mps: 0.0,
        psi_ref_rad: 0.0,
        yaw_error_rad: 0.0,
        torque_total_nm: a.torque_nm.iter().sum(),
        torque_ff_nm: 0.0,
        plan_age_s: 0.0,
        mode: link::mode_from_code(a.mode).unwrap_or(Mode::Safe),
        new_plan: false,
    }
}

/// What a refused set-up means, and what to change.
pub fn setup_refusal(status: u8, detail: u16) -> String {
    use firmware::link::SetupError as E;
    match E::from_code(status) {
        Some(E::NoConfig) => "a frame came before the configuration (a simulator bug)".into(),
        Some(E::InvalidConfig) => {
            "the vehicle's numbers or the planner's friction are not finite and positive: check the vehicle file and --mu-planner".into()
        }
        Some(E::PathTooLong) => format!(
            "the track has more rows than the ECU's path holds ({detail}): resample the track to fewer points"
        ),
        Some(E::PathChunkOutOfRange) | Some(E::ObstacleOutOfRange) => {
            format!("a set-up frame arrived out of order (at {detail}): a simulator bug")
        }
        Some(E::MissingPathRow) => format!("track row {detail} never arrived"),
        Some(E::InvalidPathRow) => format!(
            "track row {detail} is not finite or has a negative width: fix the track file"
        ),
        Some(E::PathRejected) => {
            "the reference path refused the track (fewer than 3 distinct points or repeated points): fix the track file".into()
        }
        Some(E::TooManyObstacles) => format!("more obstacles than the ECU holds ({detail})"),
        Some(E::MissingObstacle) => format!("obstacle {detail} never arrived"),
        Some(E::InvalidObstacle) => format!(
            "obstacle {detail} was refused (no vertex, too many, or not finite): fix the obstacle file"
        ),
        Some(E::ObstacleBlocksRoad) => format!(
            "obstacle {detail} leaves no room to pass on either side: move it, make it narrower, or widen the track there"
        ),
        Some(E::ClockFailed) => format!(
            "its clock set-up failed ({}): it runs on its internal oscillator and does not start the control loop",
            firmware::clock_tree::ClockError::from_code(detail).map_or("unknown clock error", |e| e.name())
        ),
        Some(E::FrameRefused) => match u8::try_from(detail).ok().and_then(firmware::link::Refusal::from_code) {
            Some(firmware::link::Refusal::Auth) => "it refused a set-up frame as forged: the ECU application was built with another link key than the simulator's (build both with the same ECU_LINK_KEY, or give the ECU's key with --link-key)".into(),
            Some(r) => format!("it refused a set-up frame ({}): the link damaged or repeated a frame; run again", r.name()),
            None => format!("it refused a set-up frame (reason {detail}): is the ECU application of another version?"),
        },
        None => format!("unknown status {status} (detail {detail}): is the ECU application of another version?"),
    }
}

/// The `PathChunk` frames of a window's rows (the first starting at row 0).
pub fn path_chunks(rows: &[[f64; 4]]) -> impl Iterator<Item = Down> + '_ {
    rows.chunks(PATH_CHUNK_ROWS).enumerate().map(|(c, chunk)| {
        let mut f = PathChunkFrame {
            first: (c * PATH_CHUNK_ROWS) as u16,
            count: chunk.len() as u8,
            rows: [[0.0; 4]; PATH_CHUNK_ROWS],
        };
        for (dst, src) in f.rows.iter_mut().zip(chunk) {
            *dst = src.map(|x| x as f32);
        }
        Down::PathChunk(f)
    })
}
