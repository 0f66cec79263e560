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
