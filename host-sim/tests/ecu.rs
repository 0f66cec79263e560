//! The firmware side of the closed loop: the modelled ECU ([`SimulatedEcu`]) behind
//! the [`Ecu`] trait, its cost model, its deadlines on slow ECUs.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::state_estimate::StateEstimate;
use host_sim::closed_loop::{
    self, vehicle_config, ControlOutput, CostModel, Ecu, RunResult, SimOptions, SimulatedEcu,
};
use host_sim::run::{simulate, Precision};
use host_sim::scenario::Scenario;
use host_sim::vehicle::VehicleParams;

/// The state at the start of the paper track, at `v` m/s.
fn start_estimate(scenario: &Scenario, v: f64, t_us: u64) -> StateEstimate<f32> {
    let p = scenario.start_pose;
    StateEstimate {
        stamp_us: t_us,
        x_m: p[0] as f32,
        y_m: p[1] as f32,
        psi_rad: p[2] as f32,
        vx_mps: v as f32,
        vy_mps: 0.0,
        yaw_rate_radps: 0.0,
        delta_rad: 0.0,
    }
}

/// Calls the ECU every 10 ms from 0 to `until_us` on the start state.
fn calls(
    ecu: &mut SimulatedEcu<f32>,
    scenario: &Scenario,
    until_us: u64,
) -> Vec<ControlOutput<f32>> {
    (0..=until_us / 10_000)
        .map(|k| {
            let t = k * 10_000;
            ecu.control(t, &start_estimate(scenario, 15.0, t)).unwrap()
        })
        .collect()
}

/// The paper scenario with obstacles on an ECU clocked at `mhz`.
fn paper_at(mhz: f64, duration_s: f64) -> RunResult {
    let opts = SimOptions {
        ecu_clock_hz: mhz * 1e6,
        max_duration_s: duration_s,
        ..SimOptions::default()
    };
    simulate(
        &Scenario::paper(true),
        &VehicleParams::default(),
        &opts,
        Precision::F32,
        false,
    )
    .unwrap()
}

#[test]
fn plans_are_reported_when_they_finish_and_published_then() {
    let scenario = Scenario::paper(true);
    let opts = SimOptions::default();
    let mut ecu = SimulatedEcu::<f32>::new(&scenario, &VehicleParams::default(), &opts).unwrap();
    let out = calls(&mut ecu, &scenario, 200_000);
    let reported: Vec<_> = out
        .iter()
        .enumerate()
        .flat_map(|(k, o)| o.plans.iter().map(move |p| (k as u64 * 10_000, p.clone())))
        .collect();
    // Releases at 0, 100 and 200 ms; the last has not finished by 200 ms.
    assert_eq!(reported.len(), 2, "{reported:?}");
    for (i, (t_call, p)) in reported.iter().enumerate() {
        assert_eq!(p.activation, i as u32 + 1);
        assert_eq!(p.release_us, i as u64 * 100_000);
        assert!(p.finish_us > p.release_us && p.finish_us <= *t_call);
        assert!(
            *t_call < p.finish_us + 10_000,
            "reported at the first call after"
        );
        assert_eq!(p.status, "optimal");
        assert!(p.published && !p.deadline_miss);
        assert_eq!(p.cycles, p.instructions * opts.cycles_per_instruction);
    }
    // The cold start takes its passes, the next one is warm.
    assert_eq!(reported[0].1.passes, 3);
    assert_eq!(reported[1].1.passes, 1);
    assert_eq!(ecu.active_plan().stamp_us, 100_000);
    assert!(out.iter().all(|o| o.skipped_releases == 0));
    assert!(out
        .iter()
        .all(|o| o.cycles == o.instructions * opts.cycles_per_instruction));
}

#[test]
fn a_failed_activation_is_charged_from_its_own_counters() {
    let scenario = Scenario::paper(true);
    let opts = SimOptions::default();
    let mut ecu = SimulatedEcu::<f32>::new(&scenario, &VehicleParams::default(), &opts).unwrap();
    // A cap so low that the cold start's first QP cannot finish.
    ecu.plan_task_mut().settings.qp_max_iter = 1;
    let out = calls(&mut ecu, &scenario, 50_000);
    let p = out
        .iter()
        .flat_map(|o| o.plans.iter())
        .next()
        .expect("the activation finished");
    assert_eq!(p.status, "qp_iteration_limit");
    assert!(!p.published);
    assert_eq!((p.passes, p.qp_iterations), (1, 1));
    assert!(p.rows > 0);
    let m = &opts.cost_model;
    let counted = m.plan_instructions(&host_sim::cost_model::report_of(&p.into()));
    // One pass, one iteration: at least the pass and its rows.
    assert!(
        counted
            >= m.margin
                * (m.per_activation
                    + m.per_pass
                    + m.per_row_pass * f64::from(p.rows)
                    + m.per_iteration)
    );
    println!("failed activation: {} instructions ({p:?})", p.instructions);
    assert!((p.instructions - counted).abs() < 1e-6 * counted);
    // More than the one bare pass it used to be charged.
    assert!(p.instructions > m.margin * (m.per_activation + m.per_pass));
    // Nothing was published: control has no plan yet.
    assert_eq!(ecu.active_plan().dt_s, 0.0);
}

#[test]
fn the_bound_covers_the_capped_worst_case() {
    let m = CostModel::default();
    let settings = vehicle_config::<f32>(&VehicleParams::default()).mpc_settings();
    let bound = m.plan_bound_instructions(&settings);
    let iterations = f64::from(settings.qp_max_iter);
    let expected = m.margin
        * (m.per_activation
            + 3.0 * (m.per_pass + firmware::mpc::NC as f64 * m.per_row_pass)
            + iterations * (m.per_iteration + m.per_added + m.per_removed + m.per_refactorization));
    assert!(
        (bound - expected).abs() < 1e-6 * expected,
        "{bound} vs {expected}"
    );
    // Fewer passes or iterations allowed: a smaller bound.
    let mut less = settings;
    less.qp_max_iter = settings.qp_max_iter / 2;
    assert!(m.plan_bound_instructions(&less) < bound);
}

#[test]
fn the_default_ecu_meets_every_deadline_and_reports_every_activation() {
    let r = paper_at(168.0, 5.0);
    let s = &r.summary;
    assert_eq!(s.plan_deadline_misses, 0);
    assert_eq!(s.control_deadline_misses, 0);
    assert_eq!(s.plan_budget_overruns, 0);
    assert_eq!(s.control_budget_overruns, 0);
    assert_eq!(r.control_instructions.len() as u64, s.control_activations);
    assert_eq!(r.plan_costs.len(), r.plan_activations.len());
    // Releases at 0..=5 s; the one at 5 s has not finished when the run ends.
    assert_eq!(s.plan_activations, 51);
    assert_eq!(r.plan_activations.len(), 50);
    assert!(s.plan_max_instructions <= s.plan_bound_instructions);
    assert!(s.plan_p50_instructions > 0.0 && s.plan_p50_instructions <= s.plan_max_instructions);
    assert_eq!(
        s.plan_bound_cycles,
        s.plan_bound_instructions * SimOptions::default().cycles_per_instruction
    );
    // The bound fits the plan budget.
    assert!(s.plan_bound_cycles <= s.plan_budget_cycles);
    let m = CostModel::default();
    assert_eq!(s.control_max_instructions, m.control * m.margin);
}

#[test]
fn run_is_run_with_the_simulated_ecu() {
    let scenario = Scenario::paper(true);
    let v = VehicleParams::default();
    let opts = SimOptions {
        max_duration_s: 2.0,
        ..SimOptions::default()
    };
    let a = closed_loop::run::<f32>(&scenario, &v, &opts, |_, _| {}).unwrap();
    let mut ecu = SimulatedEcu::<f32>::new(&scenario, &v, &opts).unwrap();
    let b = closed_loop::run_with(&scenario, &v, &opts, &mut ecu, |_, _| {}).unwrap();
    assert_eq!(a.log, b.log);
    assert_eq!(a.plan_activations, b.plan_activations);
    assert_eq!(a.plans, b.plans);
}

#[test]
fn a_clock_that_is_not_positive_is_refused() {
    let scenario = Scenario::paper(false);
    for hz in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let opts = SimOptions {
            ecu_clock_hz: hz,
            ..SimOptions::default()
        };
        let e = SimulatedEcu::<f32>::new(&scenario, &VehicleParams::default(), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("ECU clock"), "{e}");
    }
}

#[test]
fn a_slow_ecu_misses_the_cold_start_deadline_and_still_drives_the_lap() {
    // At 30 MHz the 3-pass cold start (about 3.3 M modelled cycles) takes about
    // 110 ms: a deadline miss (not a budget overrun), and the release at 100 ms is
    // skipped; the plan, younger than 200 ms, is published. Warm steps meet their
    // deadlines.
    let r = paper_at(30.0, 200.0);
    let s = &r.summary;
    println!(
        "30 MHz: {} plan deadline misses, {} budget overruns, {} collisions, {}",
        s.plan_deadline_misses, s.plan_budget_overruns, s.collisions, s.stop_reason
    );
    assert!(s.completed, "{}", s.stop_reason);
    assert_eq!(s.collisions, 0);
    assert!(s.plan_deadline_misses >= 1);
    let cold = &r.plan_activations[0];
    assert_eq!(cold.passes, 3);
    assert!(cold.deadline_miss && cold.published, "{cold:?}");
    assert!(cold.finish_us > 100_000);
    assert!(
        cold.cycles < s.plan_budget_cycles,
        "a miss without an overrun"
    );
    assert_eq!(s.plan_budget_overruns, 0);
    // The release at 100 ms fell while the cold start ran: skipped, so the next
    // activation is the third release.
    assert_eq!(r.plan_activations[1].activation, 3);
    assert_eq!(s.plan_deadline_misses, 2);
    assert!(r
        .plan_activations
        .iter()
        .filter(|p| p.passes == 1)
        .all(|p| !p.deadline_miss));
    assert_eq!(s.control_deadline_misses, 0);
}

#[test]
fn an_ecu_too_slow_for_every_plan_stops_the_car_under_control() {
    // At 5 MHz every plan finishes more than 200 ms after its release (warm steps
    // take about 650 ms): each is dropped as too old, control never gets a plan and
    // brings the car to a controlled stop.
    let r = paper_at(5.0, 60.0);
    let s = &r.summary;
    println!(
        "5 MHz: {} of {} plan releases missed, {} failures, {} collisions, {:.0} m, {}",
        s.plan_deadline_misses,
        s.plan_activations,
        s.plan_failures,
        s.collisions,
        s.distance_m,
        s.stop_reason
    );
    assert!(r
        .plan_activations
        .iter()
        .all(|p| p.deadline_miss && !p.published));
    // Every release misses: run late or skipped (the last may still be running).
    assert!(s.plan_deadline_misses + 1 >= s.plan_activations);
    assert_eq!(s.collisions, 0);
    assert!(!s.completed);
    assert!(
        s.stop_reason.starts_with("stood still"),
        "{}",
        s.stop_reason
    );
    assert!(r.log.last().unwrap().v_mps < 0.05);
    assert_eq!(s.control_deadline_misses, 0);
}

#[test]
fn a_control_activation_slower_than_its_period_is_a_deadline_miss() {
    // A control task of 100,000 instructions (134,000 cycles at 1.34) on a 10 MHz
    // ECU takes 13.4 ms > 10 ms: every control activation misses, and each is over
    // its 5,000-cycle budget too.
    let opts = SimOptions {
        ecu_clock_hz: 10e6,
        max_duration_s: 0.5,
        cost_model: CostModel {
            control: 100_000.0 / 1.05,
            ..CostModel::default()
        },
        ..SimOptions::default()
    };
    let r = simulate(
        &Scenario::paper(false),
        &VehicleParams::default(),
        &opts,
        Precision::F32,
        false,
    )
    .unwrap();
    let s = &r.summary;
    assert_eq!(s.control_deadline_misses, s.control_activations);
    assert_eq!(s.control_budget_overruns, s.control_activations);
    // At 168 MHz the same task is over budget but in time.
    let fast = SimOptions {
        ecu_clock_hz: 168e6,
        ..opts
    };
    let r = simulate(
        &Scenario::paper(false),
        &VehicleParams::default(),
        &fast,
        Precision::F32,
        false,
    )
    .unwrap();
    assert_eq!(r.summary.control_deadline_misses, 0);
    assert_eq!(
        r.summary.control_budget_overruns,
        r.summary.control_activations
    );
}
