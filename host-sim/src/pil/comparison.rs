//! The PIL run against the in-process run of the same scenario: the first row where
//! they differ, and why, from what the two runs recorded.
//!
//! A log row holds the plant's state at a control release and the actuation the
//! ECU computed on it. The state at a row follows from the state at the row before
//! and the actuations the plant applied in between, each from the plant step in
//! which it was sent ([`crate::closed_loop::timeline`]). So at the first row that
//! differs:
//!
//! * the state is the same and the actuation differs: the control task computed
//!   another result from the same state (a plan published in another period, a
//!   plan of other values, or the control task's own arithmetic);
//! * the state differs, every earlier actuation being the same: an earlier
//!   actuation was applied from another plant step, because it was sent at another
//!   instant.

use crate::closed_loop::plan_activation::PlanActivation;
use crate::closed_loop::timeline::{LogRow, RunResult};

/// The first difference between the PIL trajectory and the in-process one.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Comparison {
    /// Log rows compared (10 ms each).
    pub rows_compared: usize,
    /// The two trajectories are equal bit for bit on every compared row.
    pub identical: bool,
    /// Time of the first differing row, s.
    pub first_divergence_s: Option<f64>,
    /// Why, as far as the two runs' records tell.
    pub cause: String,
}

/// The plant's state in a log row differs between the two runs (bit for bit).
fn state_differs(a: &LogRow, b: &LogRow) -> bool {
    a.x_m.to_bits() != b.x_m.to_bits()
        || a.y_m.to_bits() != b.y_m.to_bits()
        || a.psi_rad.to_bits() != b.psi_rad.to_bits()
        || a.v_mps.to_bits() != b.v_mps.to_bits()
}

/// The actuation in a log row (steering and the four wheel torques) differs.
fn actuation_differs(a: &LogRow, b: &LogRow) -> bool {
    let act = |r: &LogRow| {
        [
            r.delta_rad,
            r.torque_fl_nm,
            r.torque_fr_nm,
            r.torque_rl_nm,
            r.torque_rr_nm,
        ]
        .map(f64::to_bits)
    };
    act(a) != act(b)
}

/// Compares the PIL run with the in-process one, row by row.
pub fn compare(pil: &RunResult, host: &RunResult) -> Comparison {
    let n = pil.log.len().min(host.log.len());
    let first = (0..n).find(|&i| {
        let (a, b) = (&pil.log[i], &host.log[i]);
        state_differs(a, b) || actuation_differs(a, b)
    });
    let Some(i) = first else {
        return Comparison {
            rows_compared: n,
            identical: pil.log.len() == host.log.len(),
            first_divergence_s: None,
            cause: if pil.log.len() == host.log.len() {
                "none: identical bit for bit".into()
            } else {
                format!("equal on the first {n} rows; the runs ended at different times")
            },
        };
    };
    let cause = if state_differs(&pil.log[i], &host.log[i]) {
        applied_elsewhere(pil, host, i)
    } else {
        computed_otherwise(pil, host, i)
    };
    Comparison {
        rows_compared: n,
        identical: false,
        first_divergence_s: Some(pil.log[i].t_s),
        cause,
    }
}

/// Why the state at row `i` differs when every earlier row (states and actuations)
/// is the same: an earlier actuation applied from another plant step.
fn applied_elsewhere(pil: &RunResult, host: &RunResult, i: usize) -> String {
    let step = (0..i).find(|&j| match (pil.actuations.get(j), host.actuations.get(j)) {
        (Some(p), Some(h)) => p.applied_us != h.applied_us,
        _ => false,
    });
    match step {
        Some(j) => {
            let (p, h) = (&pil.actuations[j], &host.actuations[j]);
            format!(
                "the actuation computed at {:.2} s (the same values on both) was applied at a different plant step: from {:.3} s on the ECU and {:.3} s in the in-process run (send instants differ: host {} µs, ECU {} µs)",
                p.release_us as f64 * 1e-6,
                p.applied_us as f64 * 1e-6,
                h.applied_us as f64 * 1e-6,
                h.sent_us,
                p.sent_us
            )
        }
        None => "every earlier actuation is the same on both, with the same values applied from the same plant steps, yet the plant's state differs: not explained by the ECU (the plant or its inputs differ between the two runs)".into(),
    }
}

/// Why the actuation at row `i` differs when the state there is the same: a plan
/// published in another control period or of other values, or the control task's
/// own arithmetic.
fn computed_otherwise(pil: &RunResult, host: &RunResult, i: usize) -> String {
    let t_us = (pil.log[i].t_s * 1e6).round() as u64;
    // Publication slot: the first control instant at or after the finish.
    let slot = |a: &PlanActivation| a.finish_us.div_ceil(10_000) * 10_000;
    let plan_timing = pil
        .plan_activations
        .iter()
        .zip(host.plan_activations.iter())
        .find(|(p, h)| {
            p.release_us != h.release_us
                || p.status != h.status
                || p.published != h.published
                || slot(p) != slot(h)
        })
        .filter(|(p, _)| p.release_us <= t_us)
        .map(|(p, h)| {
            if p.status != h.status {
                format!(
                    "plan released at {:.1} s: the ECU's MPC returned {} and the host's {} (f32 arithmetic differs between the targets)",
                    p.release_us as f64 * 1e-6, p.status, h.status
                )
            } else {
                format!(
                    "plan released at {:.1} s was published at {:.1} ms on the ECU (measured: {:.0} instructions) and at {:.1} ms by the cost model ({:.0} instructions): a different 10 ms control period",
                    p.release_us as f64 * 1e-6,
                    (slot(p) - p.release_us) as f64 * 1e-3,
                    p.instructions,
                    (slot(h) - h.release_us) as f64 * 1e-3,
                    h.instructions
                )
            }
        });
    if let Some(cause) = plan_timing {
        return cause;
    }
    // Same outcome and same publication period: compare the plans themselves.
    let t_div = pil.log[i].t_s;
    let diff = pil
        .plans
        .iter()
        .filter(|p| p.t_publish_s <= t_div)
        .find_map(|p| {
            let h = host
                .plans
                .iter()
                .find(|h| (h.t_release_s - p.t_release_s).abs() < 1e-9)?;
            let d =
                p.xy.iter()
                    .zip(h.xy.iter())
                    .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
                    .fold(0.0f64, f64::max);
            (d > 0.0).then_some((p.t_release_s, d))
        });
    let (a, b) = (&pil.log[i], &host.log[i]);
    let values = format!(
        "steering ECU {:e}, host {:e} rad; front-left torque ECU {:e}, host {:e} N·m",
        a.delta_rad, b.delta_rad, a.torque_fl_nm, b.torque_fl_nm
    );
    match diff {
        Some((t, d)) => format!(
            "the actuation values differ ({values}) from the same state: the plan released at {t:.1} s has the same QP work counters and publication period on both, but its nodes differ by up to {d:.3} m: the same f32 code gives different results on the Cortex-M4F and on the host (rounding of a step both compute; not a timing difference)"
        ),
        None => format!(
            "the actuation values differ ({values}) from the same state, every plan published so far being the same on both (positions bit for bit): the control task's f32 results differ between the Cortex-M4F and the host (rounding in a step both compute; not a timing difference)"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::closed_loop::timeline::ActuationTiming;

    /// A run of `rows` rows 10 ms apart, each actuation sent 100 µs after its
    /// release and applied from it.
    fn run(rows: usize) -> RunResult {
        let mut r = RunResult::default();
        for k in 0..rows {
            let t_us = k as u64 * 10_000;
            r.log.push(LogRow {
                t_s: t_us as f64 * 1e-6,
                x_m: k as f64,
                v_mps: 15.0,
                delta_rad: 0.01,
                torque_fl_nm: -337.5,
                ..LogRow::default()
            });
            r.actuations.push(ActuationTiming {
                release_us: t_us,
                sent_us: t_us + 100,
                applied_us: t_us,
            });
        }
        r
    }

    #[test]
    fn identical_runs_are_identical() {
        let c = compare(&run(5), &run(5));
        assert!(c.identical);
        assert_eq!(c.first_divergence_s, None);
        assert_eq!(c.rows_compared, 5);
    }

    #[test]
    fn a_state_that_differs_after_an_actuation_sent_in_another_plant_step_names_the_send_instants()
    {
        let host = run(5);
        let mut pil = run(5);
        // The first actuation sent at 1,035 µs: applied from the step at 1 ms.
        pil.actuations[0].sent_us = 1_035;
        pil.actuations[0].applied_us = 1_000;
        pil.log[1].v_mps = 15.001;
        let c = compare(&pil, &host);
        assert!(!c.identical);
        assert_eq!(c.first_divergence_s, Some(0.01));
        assert!(
            c.cause.contains("applied at a different plant step"),
            "{}",
            c.cause
        );
        assert!(
            c.cause
                .contains("send instants differ: host 100 µs, ECU 1035 µs"),
            "{}",
            c.cause
        );
        assert!(c.cause.contains("computed at 0.00 s"), "{}", c.cause);
        assert!(!c.cause.contains("f32"), "{}", c.cause);
    }

    #[test]
    fn a_send_instant_in_the_same_plant_step_is_not_a_cause() {
        let host = run(5);
        let mut pil = run(5);
        // Sent later, within the same step: applied alike; the state differs anyway.
        pil.actuations[0].sent_us = 900;
        pil.log[2].x_m = 2.5;
        let c = compare(&pil, &host);
        assert_eq!(c.first_divergence_s, Some(0.02));
        assert!(c.cause.contains("not explained by the ECU"), "{}", c.cause);
    }

    #[test]
    fn an_actuation_that_differs_from_the_same_state_names_the_values() {
        let host = run(5);
        let mut pil = run(5);
        pil.log[3].torque_fl_nm = -337.25;
        let c = compare(&pil, &host);
        assert_eq!(c.first_divergence_s, Some(0.03));
        assert!(
            c.cause.contains("the actuation values differ"),
            "{}",
            c.cause
        );
        assert!(c.cause.contains("-3.3725e2"), "{}", c.cause);
        assert!(!c.cause.contains("plant step"), "{}", c.cause);
    }

    #[test]
    fn a_plan_published_in_another_period_is_named_before_the_arithmetic() {
        let host = run(5);
        let mut pil = run(5);
        pil.log[3].delta_rad = 0.02;
        let activation = |finish_us| PlanActivation {
            activation: 0,
            release_us: 0,
            finish_us,
            instructions: 1e5,
            cycles: 2.53e5,
            status: "optimal",
            published: true,
            deadline_miss: false,
            passes: 1,
            warm: false,
            qp_iterations: 10,
            qp_added: 5,
            qp_removed: 0,
            qp_refactorizations: 0,
            rows: 100,
            active_constraints: 5,
            window: false,
            window_instructions: 0.0,
            route_frames: 0,
            max_validity_slack_rad: None,
        };
        pil.plan_activations.push(activation(12_000));
        let mut host = host;
        host.plan_activations.push(activation(8_000));
        let c = compare(&pil, &host);
        assert!(
            c.cause.contains("a different 10 ms control period"),
            "{}",
            c.cause
        );
    }
}
