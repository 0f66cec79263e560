//! The PIL run against the in-process run of the same scenario: the first row where
//! their trajectories differ, and why, as far as the plan activations tell.

use crate::closed_loop::plan_activation::PlanActivation;
use crate::closed_loop::timeline::RunResult;

/// The first difference between the PIL trajectory and the in-process one.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Comparison {
    /// Log rows compared (10 ms each).
    pub rows_compared: usize,
    /// The two trajectories are equal bit for bit on every compared row.
    pub identical: bool,
    /// Time of the first differing row, s.
    pub first_divergence_s: Option<f64>,
    /// Why, as far as the activations tell.
    pub cause: String,
}

/// Compares the PIL run with the in-process one, row by row.
pub fn compare(pil: &RunResult, host: &RunResult) -> Comparison {
    let n = pil.log.len().min(host.log.len());
    let first = (0..n).find(|&i| {
        let (a, b) = (&pil.log[i], &host.log[i]);
        a.x_m.to_bits() != b.x_m.to_bits()
            || a.y_m.to_bits() != b.y_m.to_bits()
            || a.psi_rad.to_bits() != b.psi_rad.to_bits()
            || a.v_mps.to_bits() != b.v_mps.to_bits()
            || a.delta_rad.to_bits() != b.delta_rad.to_bits()
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
    let t_us = (pil.log[i].t_s * 1e6).round() as u64;
    // Publication slot: the first control instant at or after the finish.
    let slot = |a: &PlanActivation| a.finish_us.div_ceil(10_000) * 10_000;
    let cause = pil
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
        })
        .unwrap_or_else(|| {
            // Same outcome and same publication period: compare the plans themselves.
            let t_div = pil.log[i].t_s;
            let diff = pil.plans.iter().filter(|p| p.t_publish_s <= t_div).find_map(|p| {
                let h = host
                    .plans
                    .iter()
                    .find(|h| (h.t_release_s - p.t_release_s).abs() < 1e-9)?;
                let d = p
                    .xy
                    .iter()
                    .zip(h.xy.iter())
                    .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
                    .fold(0.0f64, f64::max);
                (d > 0.0).then_some((p.t_release_s, d))
            });
            match diff {
                Some((t, d)) => format!(
                    "the plan released at {t:.1} s has the same QP work counters and publication period on both, but its nodes differ by up to {d:.3} m: the same f32 code gives different results on the Cortex-M4F and on the host (rounding of a step both compute; not a timing difference)"
                ),
                None => "every plan published so far is the same on both (positions bit for bit), so the control task's f32 results differ between the Cortex-M4F and the host (rounding in a step both compute; not a timing difference)".into(),
            }
        });
    Comparison {
        rows_compared: n,
        identical: false,
        first_divergence_s: Some(pil.log[i].t_s),
        cause,
    }
}
