//! The ECU's own deadline bookkeeping (`firmware::deadline`): releases,
//! completions, response times, misses, overruns, skipped releases, the control
//! task's consecutive-miss rule and its watchdog on the plan task.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::deadline::*;
use firmware::tasks::{CONTROL_PERIOD_US, PLAN_PERIOD_US};

/// One activation: released, completed `response_us` after its release with
/// `cycles` of its own, ended `tail_us` after its completion; the next release.
fn activation(
    m: &mut DeadlineMonitor,
    response_us: u64,
    cycles: u64,
    tail_us: u64,
) -> (Completion, NextRelease) {
    let release = m.start();
    let c = m.complete(release + response_us, cycles);
    let n = m.next_release(release + response_us + tail_us);
    (c, n)
}

#[test]
fn releases_are_multiples_of_the_period_and_on_time_activations_count_nothing() {
    let mut m = DeadlineMonitor::control();
    assert_eq!(m.period_us(), CONTROL_PERIOD_US);
    assert_eq!((m.release_index(), m.release_us()), (0, 0));
    for k in 0..100u64 {
        assert_eq!(m.release_us(), k * CONTROL_PERIOD_US);
        let (c, n) = activation(&mut m, 60, 3_600, 5);
        assert_eq!(
            c,
            Completion {
                response_us: 60,
                missed: false,
                overrun: false
            }
        );
        assert_eq!(n.index, k + 1);
        assert_eq!(n.release_us, (k + 1) * CONTROL_PERIOD_US);
        assert_eq!(n.skipped, 0);
    }
    let c = m.counts();
    assert_eq!((c.releases, c.completions), (100, 100));
    assert_eq!(
        (c.deadline_misses, c.skipped_releases, c.budget_overruns),
        (0, 0, 0)
    );
    assert_eq!(c.max_response_us, 60);
    assert!(!m.safe_stop());
}

#[test]
fn a_response_time_over_the_period_is_a_miss_and_exactly_the_period_is_not() {
    let mut m = DeadlineMonitor::plan();
    let (c, _) = activation(&mut m, PLAN_PERIOD_US, 1, 0);
    assert!(
        !c.missed,
        "a plan published exactly at its deadline is in time"
    );
    let (c, n) = activation(&mut m, PLAN_PERIOD_US + 1, 1, 0);
    assert!(c.missed);
    assert_eq!(c.response_us, PLAN_PERIOD_US + 1);
    // It ended 1 µs past the next release: that release is skipped.
    assert_eq!(n.skipped, 1);
    assert_eq!(n.release_us, 3 * PLAN_PERIOD_US);
    let counts = m.counts();
    assert_eq!(
        counts.deadline_misses, 2,
        "the late completion and the skip"
    );
    assert_eq!(counts.skipped_releases, 1);
    assert_eq!(counts.max_response_us, PLAN_PERIOD_US as u32 + 1);
    // No miss limit on the plan task.
    assert!(!m.safe_stop());
}

#[test]
fn budget_overruns_are_counted_apart_from_misses() {
    let mut m = DeadlineMonitor::control();
    let (c, _) = activation(&mut m, 100, CONTROL_BUDGET_CYCLES, 0);
    assert!(!c.overrun, "the budget itself is allowed");
    let (c, _) = activation(&mut m, 100, CONTROL_BUDGET_CYCLES + 1, 0);
    assert!(c.overrun && !c.missed);
    let mut p = DeadlineMonitor::plan();
    let (c, _) = activation(&mut p, 99_000, PLAN_BUDGET_CYCLES + 1, 0);
    assert!(c.overrun && !c.missed);
    assert_eq!(m.counts().budget_overruns, 1);
    assert_eq!(m.counts().deadline_misses, 0);
    assert_eq!(p.counts().budget_overruns, 1);
}

#[test]
fn releases_that_fall_while_the_task_runs_past_its_completion_are_skipped() {
    // A plan published in time (40 ms) that then adopts a window until 230 ms:
    // the releases at 100 and 200 ms fell while it ran; the next is at 300 ms.
    let mut m = DeadlineMonitor::plan();
    let (c, n) = activation(&mut m, 40_000, 1, 190_000);
    assert!(!c.missed);
    assert_eq!(n.skipped, 2);
    assert_eq!((n.index, n.release_us), (3, 300_000));
    assert_eq!(m.counts().skipped_releases, 2);
    assert_eq!(m.counts().deadline_misses, 2);
    // Ending exactly at a release does not skip it.
    let (_, n) = activation(&mut m, 50_000, 1, 50_000);
    assert_eq!((n.skipped, n.release_us), (0, 400_000));
    // The releases that ran.
    assert_eq!(m.counts().releases, 2);
}

#[test]
fn a_completion_stamped_before_its_release_is_a_zero_response() {
    let mut m = DeadlineMonitor::control();
    m.next_release(25_000); // now at release 3 (30 ms): 10 and 20 ms skipped
    assert_eq!(m.release_us(), 30_000);
    let c = m.complete(29_000, 0);
    assert_eq!(c.response_us, 0);
    assert!(!c.missed);
}

#[test]
fn k_consecutive_control_misses_latch_the_safe_stop() {
    assert_eq!(CONTROL_MISS_LIMIT, 3);
    // Two late answers, then one in time: the run of misses restarts.
    let mut m = DeadlineMonitor::control();
    activation(&mut m, 10_500, 1, 0);
    // It ended 500 µs past release 1: skipped (the second miss).
    assert_eq!(m.consecutive_misses(), 2);
    assert!(!m.safe_stop());
    activation(&mut m, 100, 1, 0);
    assert_eq!(m.consecutive_misses(), 0);
    assert!(!m.safe_stop());
    // Late answers that end before the next release: one miss each.
    let mut m = DeadlineMonitor::new(CONTROL_PERIOD_US, CONTROL_BUDGET_CYCLES, 3);
    let r = m.start();
    m.complete(r + 10_001, 1);
    m.next_release(r + 10_001); // skips release 1 (10 ms)
    assert_eq!(m.consecutive_misses(), 2);
    let r = m.start();
    assert_eq!(r, 20_000);
    assert!(!m.safe_stop());
    let c = m.complete(r + 10_001, 1);
    assert!(c.missed);
    assert_eq!(m.consecutive_misses(), 3);
    assert!(m.safe_stop(), "the third consecutive miss latches it");
    // Latched: activations in time do not release it.
    m.next_release(r + 10_001);
    for _ in 0..10 {
        activation(&mut m, 100, 1, 0);
    }
    assert!(m.safe_stop());
    assert_eq!(m.consecutive_misses(), 0);
}

#[test]
fn after_k_consecutive_misses_the_control_output_is_zero_torque_with_the_steering_held() {
    use firmware::low_level::{Actuation, Mode};
    let computed = Actuation {
        wheel_torque_nm: [120.0f32, 120.0, 0.0, 0.0],
        delta_rad: 0.05,
        mode: Mode::Following,
        ..Actuation::safe(0.05f32, 0.0)
    };
    let held = 0.031f32;
    let mut m = DeadlineMonitor::control();
    // A late answer (miss 1) that skips the next release (miss 2): still the
    // computed actuation.
    let r = m.start();
    m.complete(r + CONTROL_PERIOD_US + 1, 1);
    m.next_release(r + CONTROL_PERIOD_US + 1);
    assert_eq!(m.consecutive_misses(), CONTROL_MISS_LIMIT - 1);
    let (out, stopped) = control_output(&m, computed, held);
    assert!(!stopped);
    assert_eq!(out, computed);
    // The next answer late too: the K-th consecutive miss latches the stop, and
    // this very answer goes out safe.
    let r = m.start();
    m.complete(r + CONTROL_PERIOD_US + 1, 1);
    assert!(m.safe_stop());
    for _ in 0..5 {
        let (out, stopped) = control_output(&m, computed, held);
        assert!(stopped);
        assert_eq!(out.wheel_torque_nm, [0.0; 4], "zero torque");
        assert_eq!(out.torque_total_nm, 0.0);
        assert_eq!(out.delta_rad, held, "steering held");
        assert_eq!(out.mode, Mode::Safe);
        activation(&mut m, 100, 1, 0);
    }
}

#[test]
fn one_long_overrun_skips_enough_releases_to_latch_the_safe_stop() {
    // A control activation that answers in time but stays busy 25 ms: the
    // releases at 10 and 20 ms are skipped (2 misses); a third consecutive miss
    // (the next answer late) latches the safe stop.
    let mut m = DeadlineMonitor::control();
    let (c, n) = activation(&mut m, 100, 1, 24_900);
    assert!(!c.missed);
    assert_eq!((n.skipped, n.release_us), (2, 30_000));
    assert!(!m.safe_stop());
    let (c, _) = activation(&mut m, 10_200, 1, 0);
    assert!(c.missed);
    assert!(m.safe_stop());
    let counts = m.counts();
    // 2 skipped + the late answer + the release it skipped (40 ms) = 4.
    assert_eq!(counts.deadline_misses, 4);
    assert_eq!(counts.skipped_releases, 3);
}

#[test]
fn a_monitor_without_a_limit_never_latches() {
    let mut m = DeadlineMonitor::new(1_000, 10, 0);
    for _ in 0..50 {
        activation(&mut m, 5_000, 100, 0);
    }
    assert!(!m.safe_stop());
    assert_eq!(m.counts().budget_overruns, 50);
    // Every activation late by 4 periods: 1 + 4 skipped each.
    assert_eq!(m.counts().deadline_misses, 50 * 5);
}

#[test]
fn the_watchdog_trips_once_after_its_limit_without_a_new_plan_and_rearms() {
    assert_eq!(PLAN_WATCHDOG_US, PLAN_WATCHDOG_PERIODS * PLAN_PERIOD_US);
    let mut w = PlanWatchdog::plan();
    // A plan every 100 ms: never trips.
    let mut plans = 0u32;
    for k in 0..200u64 {
        let t = k * CONTROL_PERIOD_US;
        if k % 10 == 3 {
            plans += 1;
        }
        assert!(!w.check(t, plans), "tripped at {t} µs");
    }
    assert_eq!(w.trips(), 0);
    // The plan task stops publishing: trips once the silence exceeds the limit.
    let last_plan_us = 193 * CONTROL_PERIOD_US;
    let mut tripped_at = None;
    for k in 200..400u64 {
        let t = k * CONTROL_PERIOD_US;
        if w.check(t, plans) && tripped_at.is_none() {
            tripped_at = Some(t);
        }
    }
    assert_eq!(
        tripped_at,
        Some(last_plan_us + PLAN_WATCHDOG_US + CONTROL_PERIOD_US)
    );
    assert_eq!(w.trips(), 1, "counted once per silence");
    assert!(w.tripped());
    // A new plan re-arms it; a second silence trips it again.
    assert!(!w.check(400 * CONTROL_PERIOD_US, plans + 1));
    assert!(!w.tripped());
    for k in 401..500u64 {
        w.check(k * CONTROL_PERIOD_US, plans + 1);
    }
    assert_eq!(w.trips(), 2);
}

#[test]
fn the_watchdog_trips_when_no_plan_ever_comes() {
    let mut w = PlanWatchdog::new(PLAN_WATCHDOG_US);
    assert!(
        !w.check(PLAN_WATCHDOG_US, 0),
        "exactly the limit is allowed"
    );
    assert!(w.check(PLAN_WATCHDOG_US + 1, 0));
    assert_eq!(w.trips(), 1);
}

#[test]
fn the_counts_are_the_same_for_the_same_stamps() {
    // Deterministic: two monitors fed the same stamps agree, counts and state.
    let stamps: Vec<(u64, u64, u64)> = (0..300u64)
        .map(|k| {
            (
                (k * 7_919) % 130_000,
                (k * 104_729) % 20_000_000,
                (k * 31) % 90_000,
            )
        })
        .collect();
    let run = || {
        let mut m = DeadlineMonitor::plan();
        for &(resp, cycles, tail) in &stamps {
            activation(&mut m, resp, cycles, tail);
        }
        m
    };
    let (a, b) = (run(), run());
    assert_eq!(a, b);
    let c = a.counts();
    assert_eq!(c.completions, 300);
    assert_eq!(c.releases, 300);
    assert!(c.deadline_misses >= c.skipped_releases);
    assert!(c.max_response_us < 130_000);
}

#[test]
fn the_plan_budget_is_the_period_less_its_reserve_at_the_core_clock() {
    // 95 ms of the 100 ms period at 168 MHz: the figure the timing report and
    // .ci/expected/wcet.json judge the plan job against.
    assert_eq!(PLAN_BUDGET_CYCLES, 15_960_000);
    let clock = u64::from(firmware::timing::ECU_CLOCK_HZ);
    assert_eq!(
        PLAN_BUDGET_CYCLES * 1_000_000 / clock,
        PLAN_PERIOD_US - PLAN_RESERVE_US
    );
}

proptest::proptest! {
    /// The next release is the first after the current one at or past the job's
    /// end, `max(index + 1, ⌈end / period⌉)`, whatever the period and however late
    /// the job ends (within 2³² µs of the release it skipped to).
    #[test]
    fn the_next_release_is_the_first_not_yet_past(
        period in 1u64..10_000_000,
        start in 0u64..1_000,
        late in 0u64..(u32::MAX as u64),
    ) {
        let mut m = DeadlineMonitor::new(period, 1_000, 0);
        for _ in 0..start % 7 {
            let r = m.start();
            m.next_release(r + 1);
        }
        let index = m.release_index();
        let end = index * period + late;
        let n = m.next_release(end);
        let expected = (index + 1).max(end.div_ceil(period));
        proptest::prop_assert_eq!(n.index, expected);
        proptest::prop_assert_eq!(n.release_us, expected * period);
        proptest::prop_assert_eq!(n.skipped as u64, expected - index - 1);
    }
}
