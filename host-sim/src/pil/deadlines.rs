//! Deadlines, counted twice: the host counts the ECU's skipped releases from the
//! frames' stamps ([`skipped_between`]) and its budget overruns from their ticks
//! ([`TickOverruns`]); the ECU counts them itself ([`firmware::deadline`]);
//! [`count_mismatches`] says where the two differ.

use crate::closed_loop::summary::Summary;

/// Releases of a task of period `period_us` skipped by an activation released at
/// `release_us` that ended at `end_us` (µs): those after its release and before
/// the first not yet past at its end (one exactly at the end is not past).
pub fn skipped_between(release_us: u64, end_us: u64, period_us: u64) -> u32 {
    let next_due = release_us + period_us;
    if end_us <= next_due {
        0
    } else {
        (end_us - next_due).div_ceil(period_us) as u32
    }
}

/// The plan events the ECU's frames carry, checked as they come: at most one per
/// plan activation, in the activations' order. The timing analysis rests on it:
/// it charges the control task's activations whose frame carries an event at
/// most once per plan activation (`wcet::ecu_app::EcuBuild::light_activations`),
/// so a run that shows otherwise stops with the reason.
#[derive(Debug, Default, Clone)]
pub struct EventOrder {
    /// The last event's activation number.
    last: Option<u32>,
}

impl EventOrder {
    /// Records an event of plan `activation`; an error when that activation, or
    /// a later one, already had its event.
    pub fn check(&mut self, activation: u32) -> Result<(), String> {
        if let Some(last) = self.last {
            if activation <= last {
                return Err(format!(
                    "the ECU sent an event of plan activation {activation} after one of activation {last}: \
                     at most one event per plan activation, in order, is what the timing analysis \
                     charges the control task's frames for (wcet::ecu_app::EcuBuild::light_activations)"
                ));
            }
        }
        self.last = Some(activation);
        Ok(())
    }
}

/// Where the ECU's own deadline counts differ from the host's: the summary's
/// misses and skipped releases (counted by the driver from the frames' stamps)
/// and the host's count of budget overruns on the ECU's clock; one line each,
/// empty when they agree (or when there is no ECU count).
pub fn count_mismatches(s: &Summary, ticks: &TickOverruns) -> Vec<String> {
    let pairs = [
        (
            "plan deadline misses",
            s.ecu_plan_deadline_misses,
            s.plan_deadline_misses,
        ),
        (
            "plan skipped releases",
            s.ecu_skipped_releases,
            s.plan_skipped_releases,
        ),
        (
            "plan budget overruns (ECU clock)",
            s.ecu_plan_budget_overruns,
            ticks.plan,
        ),
        (
            "control deadline misses",
            s.ecu_control_deadline_misses,
            s.control_deadline_misses,
        ),
        (
            "control skipped releases",
            s.ecu_control_skipped_releases,
            s.control_skipped_releases,
        ),
        (
            "control budget overruns (ECU clock)",
            s.ecu_control_budget_overruns,
            ticks.control,
        ),
    ];
    pairs
        .iter()
        .filter_map(|&(name, ecu, host)| match ecu {
            Some(e) if e != host => Some(format!("{name}: ECU {e}, host {host}")),
            _ => None,
        })
        .collect()
}

/// The host's own count, from the frames' raw ticks, of the ECU's budget
/// overruns on the ECU's clock (its ticks of a task's own execution over the
/// budget in cycles), to compare with the ECU's (the summary's
/// `*_budget_overruns` are the host's estimate for the real part: instructions ×
/// cycles per instruction).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TickOverruns {
    /// Plan activations whose ticks exceeded the plan budget.
    pub plan: u64,
    /// Control activations whose ticks exceeded the control budget, each counted
    /// with its completion, which the next frame reports (as the ECU counts it).
    pub control: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plan_event_repeated_or_out_of_order_is_refused() {
        let mut order = EventOrder::default();
        assert!(order.check(0).is_ok());
        // Activations that published no event in between are fine.
        assert!(order.check(3).is_ok());
        assert!(order.check(3).is_err_and(|e| e.contains("activation 3")));
        assert!(order.check(2).is_err());
        assert!(order.check(4).is_ok());
    }
}
