//! The firmware side of the closed loop: the modelled ECU ([`SimulatedEcu`]) behind
//! the [`Ecu`] trait, its cost model, its deadlines on slow ECUs, when an answer
//! acts on the plant; and (`real_ecu_*`, ignored: they need `cargo ecu-lockstep` and fail
//! without it; `.ci/run` runs them with `cargo test -p host-sim --test ecu --
//! --ignored`) the ECU application's panic and fault handlers.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::state_estimate::StateEstimate;
use host_sim::closed_loop::cost_model::CostModel;
use host_sim::closed_loop::ecu::{ControlCompletion, ControlOutput, Ecu, SimulatedEcu};
use host_sim::closed_loop::simulate::simulate;
use host_sim::closed_loop::timeline::{self, RunResult};
use host_sim::closed_loop::{Precision, SimOptions};
use host_sim::model::vehicle::VehicleParams;
use host_sim::world::scenario::Scenario;

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
        // The wheels rolling at the car's speed.
        wheel_speed_mps: [v as f32; 4],
        specific_force_x_mps2: f32::NAN,
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
    // The cold start takes its passes (the ECU's settings), the next one is warm.
    assert_eq!(
        reported[0].1.passes,
        u32::from(firmware::mpc::COLD_START_PASSES)
    );
    assert_eq!(reported[1].1.passes, 1);
    assert_eq!(ecu.active_plan().stamp_us, 100_000);
    assert!(out.iter().all(|o| o.skipped_releases == 0));
    assert!(out
        .iter()
        .all(|o| o.cycles == o.instructions * opts.cycles_per_instruction));
}

#[test]
fn a_window_of_the_road_is_adopted_by_an_activation_of_its_own() {
    let opts = SimOptions::default();
    let r = paper_at(168.0, 30.0);
    let acts = &r.plan_activations;
    let windows: Vec<usize> = (0..acts.len()).filter(|&i| acts[i].window).collect();
    assert!(windows.len() >= 2, "{} windows in 30 s", windows.len());
    let adoption = opts.cost_model.window_instructions();
    for &i in &windows {
        let w = &acts[i];
        // It adopts instead of planning: no MPC step, nothing published, not a
        // failure; its time is the adoption's.
        assert_eq!(w.status, "window");
        assert!(!w.published && !w.deadline_miss);
        assert_eq!((w.passes, w.qp_iterations), (0, 0));
        // The adoption, and the window's last frame read before it (`route_job`).
        let route = opts.cost_model.route_frame_instructions();
        assert_eq!(w.instructions, adoption + route);
        assert_eq!(w.window_instructions, adoption + route);
        assert_eq!(w.route_frames, 1);
        // Received and adopted by the first release after it arrived (the previous
        // activation planned); the next release plans on the new window, warm.
        assert!(acts[i - 1].published && !acts[i - 1].window);
        let next = &acts[i + 1];
        assert_eq!(next.release_us, w.release_us + 100_000);
        assert!(next.published && next.passes == 1, "{next:?}");
    }
    assert_eq!(r.summary.plan_failures, 0);
    assert_eq!(r.summary.plan_deadline_misses, 0);
    // Every other activation planned.
    assert!(acts.iter().all(|a| a.window || a.passes >= 1));
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
    let counted = m.plan_instructions(&host_sim::closed_loop::cost_model::report_of(p));
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
    assert!(s.plan_p50_instructions > 0.0 && s.plan_p50_instructions <= s.plan_max_instructions);
}

#[test]
fn run_is_run_with_the_simulated_ecu() {
    let scenario = Scenario::paper(true);
    let v = VehicleParams::default();
    let opts = SimOptions {
        max_duration_s: 2.0,
        ..SimOptions::default()
    };
    let a = timeline::run::<f32>(&scenario, &v, &opts, |_, _| {}).unwrap();
    let mut ecu = SimulatedEcu::<f32>::new(&scenario, &v, &opts).unwrap();
    let b = timeline::run_with(&scenario, &v, &opts, &mut ecu, |_, _| {}).unwrap();
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
fn a_slow_ecu_misses_its_largest_plans_deadlines_and_still_drives_the_lap() {
    // At 15 MHz a period is 1.5 M modelled cycles: the window adoptions (about
    // 2.2 M) and the largest planning steps (up to about 1.5 M, and a route
    // frame's 0.25 M when the activation reads one first, with the control task's
    // preemptions) finish after the next release, a deadline miss (not a budget
    // overrun); the releases that fell meanwhile are skipped, and a late plan,
    // younger than 200 ms, is published (an adoption publishes nothing). The other
    // activations meet their deadlines.
    let r = paper_at(15.0, 200.0);
    let s = &r.summary;
    println!(
        "15 MHz: {} plan deadline misses, {} skipped releases, {} budget overruns, {} collisions, {}",
        s.plan_deadline_misses,
        s.plan_skipped_releases,
        s.plan_budget_overruns,
        s.collisions,
        s.stop_reason
    );
    assert!(s.completed, "{}", s.stop_reason);
    assert_eq!(s.collisions, 0);
    let late: Vec<_> = r
        .plan_activations
        .iter()
        .filter(|p| p.deadline_miss)
        .collect();
    let late_plans = late.iter().filter(|p| !p.window).count();
    assert!(late_plans > 0, "no planning step was late at 15 MHz");
    assert!(late.iter().any(|p| p.window), "no adoption was late");
    for p in &late {
        assert_eq!(
            p.published, !p.window,
            "a late plan younger than 200 ms is published, an adoption publishes nothing: {p:?}"
        );
        assert!(p.finish_us > p.release_us + 100_000, "{p:?}");
        assert!(p.cycles < s.plan_budget_cycles, "a miss without an overrun");
    }
    assert_eq!(s.plan_budget_overruns, 0);
    // The releases that fell while a late activation ran were skipped, not
    // queued: the next activation is the first release not yet past when it
    // finished (a route frame read or an adoption after a late plan can push it
    // past two releases), numbered as if the skipped ones had run.
    for w in r.plan_activations.windows(2) {
        if w[0].deadline_miss {
            assert!(w[1].release_us >= w[0].release_us + 200_000, "{:?}", w[1]);
            assert!(w[1].release_us >= w[0].finish_us, "{:?} {:?}", w[0], w[1]);
            assert!(
                w[1].release_us < w[0].finish_us + 100_000 + 10_000,
                "{:?} {:?}",
                w[0],
                w[1]
            );
            assert_eq!(
                u64::from(w[1].activation - w[0].activation),
                (w[1].release_us - w[0].release_us) / 100_000,
                "{:?}",
                w[1]
            );
        }
    }
    assert!(s.plan_skipped_releases >= late.len() as u64);
    // Only the largest planning steps are late.
    let plans = r.plan_activations.iter().filter(|p| !p.window).count();
    assert!(late_plans * 10 < plans, "{late_plans} of {plans} late");
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

/// The modelled ECU with the answer of the activation released at `at_us` sent
/// `sent_after_us` µs after its release and completed `completed_after_us` after
/// it; with `lagged`, each completion is reported by the next output, as the ECU
/// in QEMU reports it (its frame cannot carry its own completion).
struct LateAnswer {
    inner: SimulatedEcu<f32>,
    at_us: u64,
    sent_after_us: u64,
    completed_after_us: u64,
    lagged: bool,
    previous: Option<ControlCompletion>,
}

impl Ecu<f32> for LateAnswer {
    fn control(
        &mut self,
        t_us: u64,
        est: &StateEstimate<f32>,
    ) -> anyhow::Result<ControlOutput<f32>> {
        let mut out = self.inner.control(t_us, est)?;
        if t_us == self.at_us {
            out.sent_us = t_us + self.sent_after_us;
            out.completion = Some(ControlCompletion {
                release_us: t_us,
                completed_us: t_us + self.completed_after_us,
            });
        }
        if self.lagged {
            out.completion = std::mem::replace(&mut self.previous, out.completion);
        }
        Ok(out)
    }

    fn active_plan(&self) -> &firmware::plan::Plan<f32> {
        self.inner.active_plan()
    }

    fn set_window(&mut self, w: &host_sim::world::route::Window) -> anyhow::Result<()> {
        self.inner.set_window(w)
    }
}

fn run_with_answer(
    at_us: u64,
    sent_after_us: u64,
    completed_after_us: u64,
    lagged: bool,
) -> RunResult {
    let scenario = Scenario::paper(true);
    let v = VehicleParams::default();
    let opts = SimOptions {
        max_duration_s: 3.0,
        ..SimOptions::default()
    };
    let mut ecu = LateAnswer {
        inner: SimulatedEcu::<f32>::new(&scenario, &v, &opts).unwrap(),
        at_us,
        sent_after_us,
        completed_after_us,
        lagged,
        previous: None,
    };
    timeline::run_with(&scenario, &v, &opts, &mut ecu, |_, _| {}).unwrap()
}

/// [`run_with_answer`] completed when sent (the modelled ECU's answers).
fn run_with_answer_sent(at_us: u64, delay_us: u64) -> RunResult {
    run_with_answer(at_us, delay_us, delay_us, false)
}

#[test]
fn an_answer_acts_from_the_plant_step_it_was_sent_in_so_only_a_late_one_changes_the_trajectory() {
    let at_us = 1_500_000;
    let nominal = run_with_answer_sent(at_us, 0);
    // Sent within the first plant step (1 ms) after its release: the same
    // trajectory bit for bit.
    let early = run_with_answer_sent(at_us, 999);
    assert_eq!(nominal.log, early.log);
    // Sent 4.5 ms late: it acts from the step at 4 ms; until then the plant holds
    // the previous answer. The trajectory is the same up to the release and
    // differs after it.
    let late = run_with_answer_sent(at_us, 4_500);
    let k = (at_us / 10_000) as usize;
    assert_eq!(nominal.log[..=k], late.log[..=k]);
    assert_ne!(nominal.log[k + 1], late.log[k + 1]);
    // A response time of 4.5 ms is within the 10 ms deadline: no miss. Past it,
    // one.
    assert_eq!(late.summary.control_deadline_misses, 0);
    let missed = run_with_answer_sent(at_us, 10_001);
    assert_eq!(missed.summary.control_deadline_misses, 1);
}

#[test]
fn the_plant_applies_an_answer_from_its_send_instant_and_its_deadline_is_judged_from_its_completion(
) {
    // As the ECU in QEMU: an answer sent (handed to its link) 0.5 ms after its
    // release completes when its frame has been written, here 10.2 ms after the
    // release, and the next output reports that completion.
    let at_us = 1_500_000;
    let nominal = run_with_answer(at_us, 500, 500, true);
    let late = run_with_answer(at_us, 500, 10_200, true);
    // The plant acts on the send instant only: the same trajectory bit for bit.
    assert_eq!(nominal.log, late.log);
    // The deadline on the completion: one miss, counted when it is reported.
    assert_eq!(nominal.summary.control_deadline_misses, 0);
    assert_eq!(late.summary.control_deadline_misses, 1);
    // Exactly at the deadline is in time (a response over the period misses).
    let at_deadline = run_with_answer(at_us, 500, 10_000, true);
    assert_eq!(at_deadline.summary.control_deadline_misses, 0);
    // A completion of the last activation, never reported, is not counted: the
    // ECU's own counts, in its frames, cannot hold it either.
    let duration_us = 3_000_000;
    let unreported = run_with_answer(duration_us, 500, 10_200, true);
    assert_eq!(unreported.summary.control_deadline_misses, 0);
    let reported = run_with_answer(duration_us, 500, 10_200, false);
    assert_eq!(reported.summary.control_deadline_misses, 1);
}

/// An ECU that reports its plans' positions only, as the ECU in QEMU does: the
/// modelled ECU, its plans' speeds and steering hidden.
struct PositionsOnly {
    inner: SimulatedEcu<f32>,
    plan: firmware::plan::Plan<f32>,
}

impl Ecu<f32> for PositionsOnly {
    fn control(
        &mut self,
        t_us: u64,
        est: &StateEstimate<f32>,
    ) -> anyhow::Result<ControlOutput<f32>> {
        let out = self.inner.control(t_us, est)?;
        self.plan = *self.inner.active_plan();
        for n in self.plan.nodes.iter_mut() {
            n.v_mps = 0.0;
            n.delta_rad = 0.0;
        }
        Ok(out)
    }

    fn active_plan(&self) -> &firmware::plan::Plan<f32> {
        &self.plan
    }

    fn set_window(&mut self, w: &host_sim::world::route::Window) -> anyhow::Result<()> {
        self.inner.set_window(w)
    }

    fn reports_plan_states(&self) -> bool {
        false
    }
}

#[test]
fn the_plans_lateral_acceleration_is_null_where_the_ecu_does_not_report_it() {
    let scenario = Scenario::paper(false);
    let v = VehicleParams::default();
    let opts = SimOptions {
        max_duration_s: 12.0,
        ..SimOptions::default()
    };
    // The modelled ECU: measured (the first bend starts at 120 m).
    let measured = paper_at(168.0, 12.0).summary.max_abs_plan_ay_mps2;
    assert!(measured.is_some_and(|ay| ay > 1.0), "{measured:?}");
    let mut ecu = PositionsOnly {
        inner: SimulatedEcu::<f32>::new(&scenario, &v, &opts).unwrap(),
        plan: firmware::plan::Plan::zeroed(),
    };
    let r = timeline::run_with(&scenario, &v, &opts, &mut ecu, |_, _| {}).unwrap();
    assert_eq!(r.summary.max_abs_plan_ay_mps2, None);
    let json = serde_json::to_value(&r.summary).unwrap();
    assert!(json["max_abs_plan_ay_mps2"].is_null(), "{json}");
    // Its CSV cell (a column of sweep.csv) is empty, as the sweep's readers expect.
    let mut w = csv::Writer::from_writer(Vec::new());
    w.serialize(&r.summary).unwrap();
    let bytes = w.into_inner().unwrap();
    let mut rd = csv::Reader::from_reader(bytes.as_slice());
    let k = rd
        .headers()
        .unwrap()
        .iter()
        .position(|h| h == "max_abs_plan_ay_mps2")
        .unwrap();
    assert_eq!(&rd.records().next().unwrap().unwrap()[k], "");
}

#[test]
fn the_modelled_ecu_reports_no_ecu_counts_and_the_summary_writes_null() {
    let r = paper_at(168.0, 1.0);
    let s = &r.summary;
    for v in [
        s.ecu_plan_deadline_misses,
        s.ecu_skipped_releases,
        s.ecu_plan_budget_overruns,
        s.ecu_control_deadline_misses,
        s.ecu_control_skipped_releases,
        s.ecu_control_budget_overruns,
        s.ecu_watchdog_trips,
    ] {
        assert_eq!(v, None);
    }
    let json: serde_json::Value = serde_json::to_value(s).unwrap();
    assert!(json["ecu_plan_deadline_misses"].is_null());
    assert!(json["ecu_watchdog_trips"].is_null());
    assert_eq!(json["plan_skipped_releases"], 0);
    assert_eq!(json["control_skipped_releases"], 0);
}

#[test]
fn the_host_counts_skipped_releases_from_the_end_of_an_activation() {
    use host_sim::pil::deadlines::skipped_between;
    // Ends before or exactly at the next release: nothing skipped.
    assert_eq!(skipped_between(0, 40_000, 100_000), 0);
    assert_eq!(skipped_between(0, 100_000, 100_000), 0);
    // Published at 90 ms but route frames received until 130 ms: the release at 100 ms
    // fell while it ran (the ECU counts from the same end).
    assert_eq!(skipped_between(0, 130_000, 100_000), 1);
    assert_eq!(skipped_between(300_000, 500_000, 100_000), 1);
    assert_eq!(skipped_between(300_000, 500_001, 100_000), 2);
    // The same as the ECU's monitor.
    for end in (0..2_000_000u64).step_by(7_919) {
        let mut m = firmware::deadline::DeadlineMonitor::plan();
        m.start();
        assert_eq!(
            m.next_release(end).skipped,
            skipped_between(0, end, 100_000),
            "{end}"
        );
    }
}

// ---------------------------------------------------------------------------
// The real ECU application (`cargo ecu-lockstep`): ignored by `cargo test`; `.ci/run`
// runs them after building it, and they fail when it is missing.
// ---------------------------------------------------------------------------

fn real_ecu_elf() -> std::path::PathBuf {
    let elf =
        host_sim::pil::built_ecu_elf(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(".."));
    assert!(
        elf.is_file(),
        "build the ECU application first: cargo ecu-lockstep ({} is missing)",
        elf.display()
    );
    elf
}

/// `llvm-objdump` of the `llvm-tools` component.
fn llvm_objdump() -> std::path::PathBuf {
    let out = std::process::Command::new("rustc")
        .args(["--print", "sysroot"])
        .output()
        .expect("rustc");
    let sysroot = String::from_utf8(out.stdout).unwrap();
    let found = walk(std::path::Path::new(sysroot.trim()).join("lib/rustlib"))
        .into_iter()
        .find(|p| p.file_name().is_some_and(|n| n == "llvm-objdump"));
    found.expect("llvm-objdump: rustup component add llvm-tools")
}

fn walk(dir: std::path::PathBuf) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir(&dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(walk(p));
            } else {
                out.push(p);
            }
        }
    }
    out
}

/// Direct calls and branches to other functions in the disassembly, by function.
fn call_graph(disassembly: &str) -> std::collections::HashMap<String, Vec<String>> {
    let mut graph: std::collections::HashMap<String, Vec<String>> = Default::default();
    let mut current: Option<String> = None;
    for line in disassembly.lines() {
        let t = line.trim_end();
        if let Some(name) = t.strip_suffix(">:").and_then(|l| l.split_once(" <")) {
            current = Some(name.1.to_string());
            graph.entry(name.1.to_string()).or_default();
            continue;
        }
        let Some(f) = &current else { continue };
        let mut words = t.split_whitespace();
        let (Some(_addr), Some(op)) = (words.next(), words.next()) else {
            continue;
        };
        if !(op.starts_with('b') && op != "bic" && !op.starts_with("bfi") && op != "bkpt") {
            continue;
        }
        // `bl 0x8006fc0 <ecu::safe_stop::h…> @ imm = #0x3a80`, `b.w 0x… <f+0x10>`.
        if let Some(at) = t.find(" <") {
            let rest = t[at + 2..].split(" @ ").next().unwrap_or("");
            let target = rest.strip_suffix('>').unwrap_or(rest);
            let target = match target.rfind("+0x") {
                Some(i) => &target[..i],
                None => target,
            };
            if target != f {
                graph.entry(f.clone()).or_default().push(target.to_string());
            }
        }
        if op.starts_with("blx") && !t.contains('<') {
            // An indirect call: the graph would not be complete.
            graph
                .entry(f.clone())
                .or_default()
                .push("<indirect>".to_string());
        }
    }
    graph
}

/// Every function reachable from `root` in `graph`, each with its caller on the
/// way ("" for the root).
fn reachable<'a>(
    graph: &'a std::collections::HashMap<String, Vec<String>>,
    root: &'a str,
) -> std::collections::HashMap<&'a str, &'a str> {
    let mut parent: std::collections::HashMap<&str, &str> = Default::default();
    let mut stack = vec![root];
    parent.insert(root, "");
    while let Some(f) = stack.pop() {
        for g in graph.get(f).into_iter().flatten() {
            if !parent.contains_key(g.as_str()) {
                parent.insert(g.as_str(), f);
                stack.push(g.as_str());
            }
        }
    }
    parent
}

#[test]
#[ignore = "needs the ECU application (`cargo ecu-lockstep`) and llvm-objdump; .ci/run runs it"]
fn real_ecu_panic_and_fault_handlers_cannot_reach_the_panic_handler_again() {
    let elf = real_ecu_elf();
    let out = std::process::Command::new(llvm_objdump())
        .args(["-d", "--demangle", "--no-show-raw-insn"])
        .arg(&elf)
        .output()
        .unwrap();
    assert!(out.status.success());
    let graph = call_graph(&String::from_utf8_lossy(&out.stdout));
    let roots: Vec<&String> = graph
        .keys()
        .filter(|n| {
            n.ends_with("rust_begin_unwind")
                || n.as_str() == "HardFault"
                || n.as_str() == "NonMaskableInt"
                || n.starts_with("ecu::safe_stop")
        })
        .collect();
    println!("roots: {roots:?}");
    assert!(roots.iter().any(|n| n.ends_with("rust_begin_unwind")));
    assert!(roots.iter().any(|n| n.as_str() == "HardFault"));
    assert!(roots.iter().any(|n| n.as_str() == "NonMaskableInt"));
    assert!(roots.iter().any(|n| n.starts_with("ecu::safe_stop")));
    let panicky = |n: &str| {
        n.ends_with("rust_begin_unwind") || n.contains("core::panicking") || n == "<indirect>"
    };
    // The analysis finds such chains where they exist: the plan task's dispatcher
    // (bounds checks in the MPC) reaches the panic handler.
    let reach = |root: &'static str| reachable(&graph, root);
    let plan = reach("USART1");
    assert!(
        plan.keys().any(|f| panicky(f)),
        "USART1 reaches no panic: the call graph is wrong ({} functions)",
        plan.len()
    );
    for root in roots {
        // Everything reachable from the root, and the path to it.
        let parent = reachable(&graph, root.as_str());
        println!("{root}: {} functions reachable", parent.len());
        assert!(parent.len() > 1, "{root} calls nothing: the graph is wrong");
        if root.starts_with("ecu::safe_stop") {
            // It encodes and authenticates the fault frame: the link's encoder
            // (not inlined) and BLAKE2s's compression are in its graph.
            assert!(parent
                .keys()
                .any(|f| f.starts_with("firmware::link::framing::encode")));
            assert!(parent
                .keys()
                .any(|f| f.starts_with("blake2::Blake2sVarCore::compress")));
        }
        if let Some(f) = parent.keys().find(|f| **f != root.as_str() && panicky(f)) {
            let mut chain = vec![*f];
            while let Some(p) = parent.get(chain[chain.len() - 1]).filter(|p| !p.is_empty()) {
                chain.push(p);
            }
            panic!("{root} can reach {f}: {}", chain.join(" <- "));
        }
    }
}

#[test]
#[ignore = "needs the ECU application (`cargo ecu-lockstep`) and llvm-objdump; .ci/run runs it"]
fn real_ecu_has_hardfault_and_nmi_handlers_of_its_own() {
    let elf = real_ecu_elf();
    let out = std::process::Command::new(llvm_objdump())
        .args(["-d", "--demangle", "--no-show-raw-insn"])
        .arg(&elf)
        .output()
        .unwrap();
    assert!(out.status.success());
    let graph = call_graph(&String::from_utf8_lossy(&out.stdout));
    // The vectors' targets are the application's handlers, which call the safe
    // stop's guard, not cortex-m-rt's default infinite loop.
    for handler in ["HardFault", "NonMaskableInt"] {
        let calls = graph.get(handler).cloned().unwrap_or_default();
        assert!(
            calls.iter().any(|c| c.starts_with("ecu::safe_stop")),
            "{handler} does not call ecu::safe_stop: {calls:?}"
        );
    }
}

/// A window of the road goes to the plan task a frame per plan release (one
/// frame on the route channel before the release's sensor frame, `route_job`
/// reading it); the release that reads its last frame (the `Window` frame)
/// adopts it instead of planning. A newer window replaces the frames of an older
/// one not yet sent, whose staging its first chunk restarts: the older one is
/// never adopted. Every other release plans.
#[test]
fn a_window_is_sent_a_frame_per_plan_release_and_adopted_by_the_release_of_its_last_frame() {
    let scenario = Scenario::paper(false);
    let opts = SimOptions::default();
    let mut ecu = SimulatedEcu::<f32>::new(&scenario, &VehicleParams::default(), &opts).unwrap();
    let window = host_sim::world::route::Window {
        rows: scenario.track.rows().into_iter().take(200).collect(),
        origin_m: 0.0,
        closed: false,
    };
    let frames = firmware::link::route_frames(window.rows.len()) as u64;
    assert_eq!(frames, 14);
    let mut reported = Vec::new();
    // A at 150 ms: its frames at the releases 200 ms .. 1.5 s, adopted at 1.5 s.
    // B at 1.55 s: 1.6 s .. 2.9 s. C at 3.05 s: two frames (3.1, 3.2 s), then D at
    // 3.25 s replaces the rest: D's frames 3.3 s .. 4.6 s.
    let given = [150_000, 1_550_000, 3_050_000, 3_250_000];
    for k in 0..=470u64 {
        let t = k * 10_000;
        if given.contains(&t) {
            ecu.set_window(&window).unwrap();
        }
        let out = ecu.control(t, &start_estimate(&scenario, 15.0, t)).unwrap();
        reported.extend(out.plans);
    }
    let adopted: Vec<u64> = reported
        .iter()
        .filter(|p| p.window)
        .map(|p| p.release_us)
        .collect();
    let release_of_last = |given_us: u64| (given_us / 100_000 + frames) * 100_000;
    assert_eq!(
        adopted,
        [
            release_of_last(150_000),
            release_of_last(1_550_000),
            release_of_last(3_250_000)
        ],
        "{reported:?}"
    );
    assert_eq!(adopted, [1_500_000, 2_900_000, 4_600_000]);
    // A route frame read at every release from the first after A to D's last,
    // none when nothing is on the way (at 0 and 100 ms, and 3.0 s).
    for p in &reported {
        let sending = (200_000..=1_500_000).contains(&p.release_us)
            || (1_600_000..=2_900_000).contains(&p.release_us)
            || (3_100_000..=4_600_000).contains(&p.release_us);
        assert_eq!(p.route_frames, u32::from(sending), "{p:?}");
    }
    // Every other release planned.
    assert!(reported
        .iter()
        .filter(|p| !p.window)
        .all(|p| p.status == "optimal" && p.passes >= 1));
    assert_eq!(reported.len(), 47, "releases 0 to 4.6 s reported by 4.7 s");
}

/// A set-up the ECU refuses because its clock set-up failed: the host says so and
/// names the step from the Ready frame's detail, for every clock error.
#[test]
fn a_clock_set_up_refusal_is_named_with_its_step() {
    use firmware::clock_tree::ClockError;
    use firmware::link::SetupError;
    use host_sim::pil::frames::setup_refusal;
    for e in ClockError::ALL {
        let text = setup_refusal(SetupError::ClockFailed.code(), e.code());
        assert!(
            text.contains("clock set-up failed") && text.contains(e.name()),
            "{text}"
        );
    }
    let text = setup_refusal(SetupError::ClockFailed.code(), 0);
    assert!(text.contains("unknown clock error"), "{text}");
}
