//! What the ECU reports to the simulator: the one-byte codes of the controller's
//! mode and faults, and the record of a plan activation ([`PlanEventFrame`]).
//!
//! The codes are part of the link's format ([`crate::link`]): changing one is a new
//! [`crate::link::LINK_VERSION`].

use crate::link::{PlanEventFrame, PLAN_NODES};
use crate::low_level::{ControlFault, Mode};
use crate::mpc::{MpcError, MpcReport};
use crate::plan::Plan;
use crate::qp::QpStatus;

/// Fault code of the panic handler's safe actuation.
pub const FAULT_PANIC: u8 = 255;

/// Code of a [`Mode`]: 0 following, 1 extrapolating, 2 stopping, 3 safe.
pub fn mode_code(m: Mode) -> u8 {
    match m {
        Mode::Following => 0,
        Mode::Extrapolating => 1,
        Mode::Stopping => 2,
        Mode::Safe => 3,
    }
}

/// The [`Mode`] of a code (`None` for an unknown code).
pub fn mode_from_code(c: u8) -> Option<Mode> {
    match c {
        0 => Some(Mode::Following),
        1 => Some(Mode::Extrapolating),
        2 => Some(Mode::Stopping),
        3 => Some(Mode::Safe),
        _ => None,
    }
}

/// Code of the control task's last fault: 0 none, 1 non-finite estimate,
/// 2 non-finite plan, 3 invalid plan (none yet), 4 numerical, 255 panic.
pub fn fault_code(f: Option<ControlFault>) -> u8 {
    match f {
        None => 0,
        Some(ControlFault::NonFiniteEstimate) => 1,
        Some(ControlFault::NonFinitePlan) => 2,
        Some(ControlFault::InvalidPlan) => 3,
        Some(ControlFault::Numerical) => 4,
    }
}

/// Code of an MPC step's outcome: 0 optimal; 1–4 refused before solving
/// (non-finite state, invalid friction, invalid settings, no path); 10 + the QP
/// status otherwise (see [`status_name`]).
pub fn status_code<R>(r: &Result<R, MpcError>) -> u8 {
    match r {
        Ok(_) => 0,
        Err(MpcError::NonFiniteState) => 1,
        Err(MpcError::InvalidFriction) => 2,
        Err(MpcError::InvalidSettings) => 3,
        Err(MpcError::NoPath) => 4,
        Err(MpcError::Qp(q)) => {
            10 + match q {
                QpStatus::Optimal => 0,
                QpStatus::NotSolved => 1,
                QpStatus::IterationLimit => 2,
                QpStatus::Infeasible => 3,
                QpStatus::NotConvex => 4,
                QpStatus::NumericalError => 5,
                QpStatus::NonFiniteInput => 6,
                QpStatus::InvalidInput => 7,
                QpStatus::WorkingSetFull => 8,
            }
        }
    }
}

/// The name of a [`status_code`] (as in the simulator's logs).
pub fn status_name(code: u8) -> &'static str {
    match code {
        0 => "optimal",
        1 => "non_finite_state",
        2 => "invalid_friction",
        3 => "invalid_settings",
        4 => "no_path",
        10 => "optimal",
        11 => "qp_not_solved",
        12 => "qp_iteration_limit",
        13 => "qp_infeasible",
        14 => "qp_not_convex",
        15 => "qp_numerical_error",
        16 => "qp_non_finite_input",
        17 => "qp_invalid_input",
        18 => "qp_working_set_full",
        _ => "unknown",
    }
}

/// The record of one plan activation: when it ran (µs on the ECU's timeline),
/// its own execution in core clock `ticks` (preemption excluded), its outcome and
/// work counters, and the positions of the plan it computed (zero when none).
#[allow(clippy::too_many_arguments)]
pub fn plan_event<R>(
    activation: u32,
    release_us: u64,
    finish_us: u64,
    ticks: u32,
    result: &Result<R, MpcError>,
    report: &MpcReport<f32>,
    published: bool,
    plan: Option<&Plan<f32>>,
) -> PlanEventFrame {
    let sat16 = |x: u32| x.min(u16::MAX as u32) as u16;
    let mut nodes_xy = [[0.0f32; 2]; PLAN_NODES];
    let mut v_heur0_mps = 0.0;
    if let Some(p) = plan {
        for (xy, n) in nodes_xy.iter_mut().zip(p.nodes.iter()) {
            *xy = [n.x_m, n.y_m];
        }
        v_heur0_mps = p.v_heur_mps[0];
    }
    PlanEventFrame {
        activation,
        release_us,
        finish_us,
        ticks,
        status: status_code(result),
        published,
        passes: report.passes.min(u8::MAX as u32) as u8,
        qp_iterations: sat16(report.qp_iterations),
        qp_added: sat16(report.qp_added),
        qp_removed: sat16(report.qp_removed),
        qp_refactorizations: sat16(report.qp_refactorizations),
        rows: sat16(report.rows),
        active: sat16(report.active_constraints),
        nodes_xy,
        v_heur0_mps,
    }
}
