//! Processor in the loop: the ECU application (`cargo ecu-lockstep`) in QEMU against the
//! simulator's plant. Deterministic (QEMU's `-icount`: the firmware's clock counts
//! its own instructions), so each assertion is on a reproducible run.
//!
//! They need `qemu-system-arm` and the ECU application built first, so they are
//! ignored by `cargo test`; `.ci/run` builds the application and runs them:
//! `cargo ecu-lockstep && cargo test -p end-to-end --test pil -- --ignored`. Run without
//! the application they fail, saying how to build it.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::PathBuf;

use firmware::link::{Refusal, RefusalCounts};
use host_sim::closed_loop::cost_model::CostModel;
use host_sim::closed_loop::disturbed_ecu::DisturbedEcu;
use host_sim::closed_loop::ecu::SimulatedEcu;
use host_sim::closed_loop::timeline::{run, run_with, RunResult};
use host_sim::closed_loop::SimOptions;
use host_sim::model::vehicle::VehicleParams;
use host_sim::pil::comparison::compare;
use host_sim::pil::deadlines::{count_mismatches, TickOverruns};
use host_sim::pil::link_fault::{FaultKinds, LinkChannel, LinkFault, LinkFaultKind, LinkFaultSpec};
use host_sim::pil::qemu::{InjectedFrames, LinkCounters, PilOptions, QemuEcu};
use host_sim::world::disturbance::Disturbances;
use host_sim::world::obstacle_file::{load_obstacles_reader, Obstacle};
use host_sim::world::scenario::{paper_pose_at, Scenario};
use host_sim::world::track::Track;

fn elf() -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let elf = host_sim::pil::built_ecu_elf(&root);
    assert!(
        elf.exists(),
        "build the ECU application first: cargo ecu-lockstep ({} is missing)",
        elf.display()
    );
    elf
}

fn pil_options(name: &str, shift: u32) -> PilOptions {
    PilOptions {
        elf: elf(),
        qemu: "qemu-system-arm".into(),
        icount_shift: shift,
        work_dir: std::env::temp_dir().join(format!("pil-test-{name}-{}", std::process::id())),
        frame_timeout_s: 60.0,
        cycles_per_instruction: SimOptions::default().cycles_per_instruction,
        trace: None,
        link_key: firmware::link::LINK_KEY,
        link_fault: None,
    }
}

/// `duration_s` of the paper scenario with the ECU in QEMU at `2^shift` ns per
/// instruction; the run's result and what the ECU reported at the end.
fn drive(
    scenario: &Scenario,
    shift: u32,
    duration_s: f64,
    name: &str,
) -> (
    RunResult,
    firmware::link::DoneFrame,
    LinkCounters,
    TickOverruns,
) {
    let opts = SimOptions {
        max_duration_s: duration_s,
        ..SimOptions::default()
    };
    drive_with(scenario, &opts, shift, name)
}

/// [`drive`] with the simulator's options `opts`.
fn drive_with(
    scenario: &Scenario,
    opts: &SimOptions,
    shift: u32,
    name: &str,
) -> (
    RunResult,
    firmware::link::DoneFrame,
    LinkCounters,
    TickOverruns,
) {
    let (r, done, counters, ticks, _) = drive_pil(scenario, opts, &pil_options(name, shift));
    (r, done, counters, ticks)
}

/// The run of `scenario` with the ECU in QEMU as `pil` says; with what the ECU
/// reported at the end, the link's counters and the link fault's frames.
fn drive_pil(
    scenario: &Scenario,
    opts: &SimOptions,
    pil: &PilOptions,
) -> (
    RunResult,
    firmware::link::DoneFrame,
    LinkCounters,
    TickOverruns,
    InjectedFrames,
) {
    let vehicle = VehicleParams::default();
    let mut ecu = QemuEcu::start(scenario, &vehicle, opts, pil).unwrap();
    let r = run_with(scenario, &vehicle, opts, &mut ecu, |_, _| {}).unwrap();
    let ticks = ecu.tick_overruns;
    let injected = ecu.injected;
    let (done, counters) = ecu.stop().unwrap();
    (r, done, counters, ticks, injected)
}

/// The ECU's own deadline counts are there and equal the host's.
fn assert_counts_agree(r: &RunResult, ticks: &TickOverruns) {
    let s = &r.summary;
    let mismatches = count_mismatches(s, ticks);
    assert!(mismatches.is_empty(), "{mismatches:?}");
    assert_eq!(s.ecu_plan_deadline_misses, Some(s.plan_deadline_misses));
    assert_eq!(s.ecu_skipped_releases, Some(s.plan_skipped_releases));
    assert_eq!(
        s.ecu_control_deadline_misses,
        Some(s.control_deadline_misses)
    );
    assert_eq!(
        s.ecu_control_skipped_releases,
        Some(s.control_skipped_releases)
    );
    assert_eq!(s.ecu_plan_budget_overruns, Some(ticks.plan));
    assert_eq!(s.ecu_control_budget_overruns, Some(ticks.control));
    assert!(s.ecu_watchdog_trips.is_some());
}

#[test]
#[ignore = "needs qemu-system-arm and `cargo ecu-lockstep`; .ci/run runs it"]
fn the_ecu_in_the_loop_drives_round_the_obstacles_within_its_deadlines() {
    let (r, done, link, ticks) = drive(&Scenario::paper(true), 4, 25.0, "obstacles");
    let s = &r.summary;
    println!("{}", serde_json::to_string_pretty(s).unwrap());
    // Past the first obstacles, on the road, every deadline met on the ECU's clock:
    // the ECU's own counts, equal to the host's count from the frames' stamps.
    assert!(s.distance_m > 300.0, "drove only {} m", s.distance_m);
    assert_eq!(s.collisions, 0);
    assert!(s.max_abs_lateral_error_m < 3.0);
    assert_eq!(s.plan_failures, 0);
    // The plan events carry positions only: the plans' a_y is not measured.
    assert_eq!(s.max_abs_plan_ay_mps2, None);
    assert_counts_agree(&r, &ticks);
    assert_eq!(s.ecu_plan_deadline_misses, Some(0));
    assert_eq!(s.ecu_skipped_releases, Some(0));
    assert_eq!(s.ecu_control_deadline_misses, Some(0));
    assert_eq!(s.ecu_control_skipped_releases, Some(0));
    assert_eq!(s.ecu_plan_budget_overruns, Some(0));
    // The control task's own work (about 1,870 instructions since the mass and
    // resistance estimator) is over its 5,000-cycle budget on this clock (an
    // instruction is 2.69 cycles at shift 4): counted alike, not a deadline miss.
    assert_eq!(s.ecu_control_budget_overruns, Some(ticks.control));
    assert_eq!(s.ecu_watchdog_trips, Some(0));
    // Windows of the road arrived (on the route channel) and were adopted.
    assert!(r.plan_activations.iter().any(|a| a.window));
    // Every release ran and was reported (the last one may still be running when
    // the run ends), with its instructions measured.
    let reported = r.plan_activations.len() as u64;
    assert!(reported + 1 >= s.plan_activations && reported <= s.plan_activations);
    assert!(r.plan_activations.iter().all(|a| a.instructions > 1e5));
    // The first step is a cold start, with the ECU's passes (one: the next steps,
    // warm, linearise about its plan), from no working set: it adds constraints.
    let cold = &r.plan_activations[0];
    assert_eq!(
        cold.passes,
        u32::from(firmware::mpc::COLD_START_PASSES),
        "{cold:?}"
    );
    assert!(cold.qp_added > 0, "{cold:?}");
    // The ECU says which steps were cold: the first only (no step failed here).
    assert!(!cold.warm, "{cold:?}");
    assert!(r.plan_activations[1..]
        .iter()
        .filter(|a| !a.window)
        .all(|a| a.warm));
    // The control task's own work, measured on the ECU.
    assert!(s.control_max_instructions > 100.0 && s.control_max_instructions <= 2_000.0);
    // The cost model (fitted on PIL laps) undercounts no activation by more than 5 %.
    let e = CostModel::default().error_on(&r.plan_activations);
    assert!(
        e.max_under_pct <= 5.0,
        "model undercounts by {} %",
        e.max_under_pct
    );
    // The link lost nothing; the painted stack was used but not exhausted.
    assert_eq!((link.rejected, link.stale, done.rejected_frames), (0, 0, 0));
    assert!(done.stack_high_water_bytes > 1_000);
    assert!(done.stack_high_water_bytes < done.stack_size_bytes);
}

#[test]
#[ignore = "needs qemu-system-arm and `cargo ecu-lockstep`; .ci/run runs it"]
fn an_ecu_too_slow_for_its_tasks_counts_the_misses_as_the_host_does_and_latches_the_safe_actuation()
{
    // 2^9 = 512 ns per instruction (86 of the 168 MHz part's cycles): a plan
    // activation over ~0.2 M instructions (100 ms), control interference
    // included, finishes past its deadline on the ECU's own clock, and one that
    // runs past the next release skips it. The control activations that send a
    // plan event with its MAC (up to ~28.5 k instructions, 14.6 ms here) overrun
    // their 10 ms period too: after CONTROL_MISS_LIMIT consecutive misses the
    // control task latches the safe actuation (zero torque, steering held). The
    // test holds the ECU to counting what happened as the host does and to
    // latching the safe actuation. (At 2^7 the paper track's plans are on time; at
    // 2^8 they miss and the control task does not: docs/limitations.md.)
    let (r, _, _, ticks) = drive(&Scenario::paper(true), 9, 12.0, "slow");
    let s = &r.summary;
    println!("{}", serde_json::to_string_pretty(s).unwrap());
    // The ECU counted misses and skipped releases itself, as many as the host.
    assert_counts_agree(&r, &ticks);
    assert!(
        s.ecu_plan_deadline_misses.unwrap() >= 3,
        "{:?} misses",
        s.ecu_plan_deadline_misses
    );
    assert!(s.ecu_skipped_releases.unwrap() >= 1);
    assert!(r.plan_activations.iter().any(|a| a.deadline_miss));
    // The control activations are over their 5,000-cycle budget on this clock
    // (an instruction is 86 of its cycles), and some miss their deadline.
    assert!(
        s.ecu_control_budget_overruns.unwrap() > s.control_activations / 2,
        "{:?} of {}",
        s.ecu_control_budget_overruns,
        s.control_activations
    );
    assert!(
        s.ecu_control_deadline_misses.unwrap() >= u64::from(firmware::deadline::CONTROL_MISS_LIMIT),
        "{:?}",
        s.ecu_control_deadline_misses
    );
    // The consecutive misses latched the safe actuation, which the host applied.
    assert!(
        s.control_safe_actuations >= 1,
        "{}",
        s.control_safe_actuations
    );
    assert_eq!(s.collisions, 0);
}

#[test]
#[ignore = "needs qemu-system-arm and `cargo ecu-lockstep`; .ci/run runs it"]
fn an_ecu_slower_still_skips_control_releases_and_counts_them_as_the_host_does() {
    // 2^10 = 1,024 ns per instruction: a control activation, its PIL link
    // included, takes longer than several control periods, so the control task
    // overruns at every release and skips the releases that fall during each
    // overrun; the plan task, below it, gets no new plan out for more than
    // PLAN_WATCHDOG_PERIODS plan periods and the watchdog trips. The ECU's counts
    // equal the host's. (The plan task's own misses and skips are the test
    // above's.)
    let (r, _, _, ticks) = drive(&Scenario::paper(true), 10, 8.0, "slower");
    let s = &r.summary;
    println!("{}", serde_json::to_string_pretty(s).unwrap());
    assert_counts_agree(&r, &ticks);
    assert!(
        s.ecu_control_skipped_releases.unwrap() >= s.control_activations,
        "{:?} control releases skipped in {} activations",
        s.ecu_control_skipped_releases,
        s.control_activations
    );
    assert!(
        s.ecu_control_deadline_misses.unwrap() >= s.control_activations,
        "{:?}",
        s.ecu_control_deadline_misses
    );
    assert_eq!(s.ecu_watchdog_trips, Some(1));
}

#[test]
#[ignore = "needs qemu-system-arm and `cargo ecu-lockstep`; .ci/run runs it"]
fn a_pil_set_up_with_an_obstacle_that_blocks_the_road_is_refused_with_what_to_change() {
    // The simulator checks every obstacle against the whole track before it sends
    // the ECU its first window (the ECU's own refusal, `SetupError::ObstacleBlocksRoad`,
    // is tested in firmware/tests/setup.rs).
    let mut scenario = Scenario::paper(false);
    let p = paper_pose_at(60.0);
    let (c, s) = (p[2].cos(), p[2].sin());
    // A 2 m deep wall 12 m wide across the road.
    let vertices = [[-1.0, -6.0], [1.0, -6.0], [1.0, 6.0], [-1.0, 6.0]]
        .iter()
        .map(|[a, b]| [p[0] + a * c - b * s, p[1] + a * s + b * c])
        .collect();
    scenario.obstacles = vec![Obstacle {
        id: "wall".into(),
        vertices,
    }];
    let opts = SimOptions::default();
    let Err(e) = QemuEcu::start(
        &scenario,
        &VehicleParams::default(),
        &opts,
        &pil_options("wall", 4),
    ) else {
        panic!("the set-up must be refused");
    };
    let msg = format!("{e:#}");
    assert!(msg.contains(r#"obstacle "wall" blocks the road"#), "{msg}");
    assert!(
        msg.contains("move it, make it narrower, or widen the track"),
        "{msg}"
    );
}

/// A hairpin circuit: two 80 m straights joined by 180° bends of 12 m radius
/// (closed, points 1 m apart, 4 m of road either side of the centre line), and six
/// 1.5 m × 1.5 m boxes along the straights, 1.2 m off the centre line on
/// alternate sides.
fn hairpin_with_boxes(mu: f64) -> Scenario {
    let (straight, r) = (80.0, 12.0);
    let bend = (std::f64::consts::PI * r) as usize;
    let mut points = Vec::new();
    for i in 0..80 {
        points.push([f64::from(i), 0.0]);
    }
    for i in 0..bend {
        let a = -std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * i as f64 / bend as f64;
        points.push([straight + r * a.cos(), r + r * a.sin()]);
    }
    for i in 0..80 {
        points.push([straight - f64::from(i), 2.0 * r]);
    }
    for i in 0..bend {
        let a = std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * i as f64 / bend as f64;
        points.push([r * a.cos(), r + r * a.sin()]);
    }
    let mut csv = String::from("# x_m,y_m,w_tr_right_m,w_tr_left_m\n");
    for [x, y] in points {
        csv.push_str(&format!("{x},{y},4,4\n"));
    }
    let track = Track::from_csv_reader(csv.as_bytes(), "hairpin", true).unwrap();
    let mut boxes = String::from("id,x_m,y_m\n");
    for k in 0..6 {
        let cx = 30.0 + 12.0 * f64::from(k / 2);
        let cy = if k % 2 == 0 { 1.2 } else { 2.0 * r - 1.2 };
        for [dx, dy] in [[-0.75, -0.75], [0.75, -0.75], [0.75, 0.75], [-0.75, 0.75]] {
            boxes.push_str(&format!("b{k},{},{}\n", cx + dx, cy + dy));
        }
    }
    let obstacles = load_obstacles_reader(boxes.as_bytes(), "boxes").unwrap();
    Scenario {
        name: "hairpin".into(),
        start_pose: track.start_pose(),
        track,
        obstacles,
        mu,
        mu_patches: Vec::new(),
        grade_patches: Vec::new(),
        initial_speed_mps: 15.0,
    }
}

#[test]
#[ignore = "needs qemu-system-arm and `cargo ecu-lockstep`; .ci/run runs it"]
fn a_cold_start_into_braking_is_the_in_process_run_bit_for_bit_from_the_first_activation() {
    // Started at 15 m/s towards a 12 m hairpin at μ 0.5: the first activation has
    // no plan yet and brakes (the safe actuation). Its answer must act from the
    // same plant step as in the in-process run: the ECU's first release is a tick
    // of its monotonic as every other (with the timeline started at the tick in
    // which the set-up ended, this set-up sent it 1,044 µs after its release, and
    // the plant applied it a step late).
    let scenario = hairpin_with_boxes(0.5);
    let opts = SimOptions {
        max_duration_s: 3.0,
        mu_road: 0.5,
        mu_planner: 0.5,
        ..SimOptions::default()
    };
    let (pil, _, link, ticks) = drive_with(&scenario, &opts, 4, "hairpin");
    let vehicle = VehicleParams::default();
    let host = run::<f32>(&scenario, &vehicle, &opts, |_, _| {}).unwrap();
    // The scenario is the one meant: braking at the first activation.
    let first = &pil.log[0];
    assert_eq!(first.control_mode, "safe");
    assert!(first.torque_fl_nm < 0.0, "{first:?}");
    // Every answer, the first included, sent within the plant step of its release.
    for (a, b) in pil.actuations.iter().zip(&host.actuations) {
        assert_eq!(a.applied_us, a.release_us, "{a:?}");
        assert_eq!(a.applied_us, b.applied_us);
    }
    let c = compare(&pil, &host);
    assert!(c.identical, "{c:?}");
    assert_eq!(pil.log.len(), host.log.len());
    assert!(pil.log.len() >= 300);
    assert_counts_agree(&pil, &ticks);
    assert_eq!((link.rejected, link.stale), (0, 0));
}

#[test]
#[ignore = "needs qemu-system-arm and `cargo ecu-lockstep`; .ci/run runs it"]
fn forged_replayed_and_corrupted_sensor_frames_are_refused_by_reason_and_never_acted_on() {
    // The paper scenario with its obstacles; the link fault covers the instant the
    // first window of the road after the start is handed over (the route frames it
    // announces reach the ECU only in the first frame it accepts after the fault).
    let scenario = Scenario::paper(true);
    let vehicle = VehicleParams::default();
    // A window goes a frame per plan release (14 for the paper track's): the
    // first one sent while driving is adopted within 12 s.
    let probe = SimOptions {
        max_duration_s: 12.0,
        ..SimOptions::default()
    };
    let clean = run::<f32>(&scenario, &vehicle, &probe, |_, _| {}).unwrap();
    let first_window_us = clean
        .plan_activations
        .iter()
        .find(|a| a.window)
        .expect("a window of the road within 12 s")
        .release_us;
    const FRAMES: u32 = 20;
    let start_us = first_window_us - 100_000;
    let opts = SimOptions {
        max_duration_s: (first_window_us as f64 * 1e-6 + 1.5).ceil(),
        ..SimOptions::default()
    };
    for kind in LinkFaultKind::ALL {
        let fault = LinkFault {
            spec: LinkFaultSpec {
                channel: LinkChannel::Sensor,
                kinds: FaultKinds::One(kind),
                frames: FRAMES,
            },
            start_us,
        };
        let pil = PilOptions {
            link_fault: Some(fault),
            ..pil_options(kind.name(), 4)
        };
        let (r, done, link, ticks, injected) = drive_pil(&scenario, &opts, &pil);
        let s = &r.summary;
        println!("{}: {injected:?}, ECU {:?}", kind.name(), done.refused);
        // Each injected frame refused for its reason, counted by the ECU (its
        // Done frame and its last actuation frame, in summary.json), none acted on.
        let expected = FaultKinds::One(kind).refusals(FRAMES);
        assert_eq!(injected.injected, expected);
        assert_eq!(injected.refused_as_expected, u64::from(FRAMES));
        assert_eq!(injected.acted_on, 0);
        assert_eq!(injected.legitimate_refused, 0);
        assert_eq!(done.refused, expected);
        assert_eq!(done.rejected_frames, FRAMES);
        let of = |r: Refusal| Some(u64::from(expected.of(r)));
        assert_eq!(s.ecu_frames_refused_auth, of(Refusal::Auth));
        assert_eq!(s.ecu_frames_refused_replay, of(Refusal::Replay));
        assert_eq!(s.ecu_frames_refused_corrupt, of(Refusal::Corrupt));
        // The host refused none of the ECU's frames; none answered another.
        assert_eq!((link.rejected, link.stale), (0, 0));
        assert_eq!(link.refused, RefusalCounts::new());
        // The refused periods ran the dropout policy, the safe actuation (the rows
        // are the control instants), and the control task followed again from the
        // first frame after them.
        let at_us = |t_s: f64| (t_s * 1e6).round() as u64;
        let safe: Vec<bool> = r
            .log
            .iter()
            .filter(|row| fault.covers(at_us(row.t_s)))
            .map(|row| row.control_mode == "safe")
            .collect();
        assert_eq!(safe, vec![true; FRAMES as usize]);
        assert!(r
            .log
            .iter()
            .filter(|row| at_us(row.t_s) >= fault.end_us())
            .all(|row| row.control_mode != "safe"));
        // The window announced during the fault was adopted after it.
        let adopted = r
            .plan_activations
            .iter()
            .find(|a| a.window)
            .expect("the window adopted");
        assert!(adopted.release_us >= fault.end_us(), "{adopted:?}");
        // Bit for bit the in-process run with no estimate in the same periods and
        // the window withheld until after them: nothing else of the injected
        // frames reached the control or the plan.
        let d = Disturbances {
            dropout: fault.dropout(),
            ..Disturbances::default()
        };
        let mut modelled = DisturbedEcu::<f32>::new(&scenario, &vehicle, &opts, d).unwrap();
        let host = run_with(&scenario, &vehicle, &opts, &mut modelled, |_, _| {}).unwrap();
        let c = compare(&r, &host);
        assert!(c.identical, "{}: {c:?}", kind.name());
        assert_eq!(
            s.control_safe_actuations,
            host.summary.control_safe_actuations
        );
        assert!(s.control_safe_actuations >= u64::from(FRAMES));
        assert_counts_agree(&r, &ticks);
        assert_eq!(s.collisions, 0);
    }
}

#[test]
#[ignore = "needs qemu-system-arm and `cargo ecu-lockstep`; .ci/run runs it"]
fn line_noise_before_sensor_frames_is_refused_as_a_run_and_the_frames_after_it_are_acted_on() {
    // The paper scenario with its obstacles; from 1 s, each of 20 sensor frames
    // comes after a run of noise longer than any frame.
    let scenario = Scenario::paper(true);
    let vehicle = VehicleParams::default();
    const FRAMES: u32 = 20;
    let fault = LinkFault {
        spec: format!("noise:{FRAMES}").parse().unwrap(),
        start_us: 1_000_000,
    };
    let opts = SimOptions {
        max_duration_s: 3.0,
        ..SimOptions::default()
    };
    let pil = PilOptions {
        link_fault: Some(fault),
        ..pil_options("noise", 4)
    };
    let (r, done, link, ticks, injected) = drive_pil(&scenario, &opts, &pil);
    let s = &r.summary;
    // Each run refused as corrupt and counted by the ECU; each frame after it
    // taken (its answer refuses nothing).
    let expected = FaultKinds::One(LinkFaultKind::Noise).refusals(FRAMES);
    assert_eq!(expected.of(Refusal::Corrupt), FRAMES);
    assert_eq!(injected.injected, expected);
    assert_eq!(injected.refused_as_expected, u64::from(FRAMES));
    assert_eq!(injected.acted_on, 0);
    assert_eq!(injected.legitimate_refused, 0);
    assert_eq!(done.refused, expected);
    assert_eq!(
        s.ecu_frames_refused_corrupt,
        Some(u64::from(expected.of(Refusal::Corrupt)))
    );
    assert_eq!((link.rejected, link.stale), (0, 0));
    // No dropout: no safe actuation in the noisy periods, and bit for bit the
    // in-process run without any fault.
    let at_us = |t_s: f64| (t_s * 1e6).round() as u64;
    let noisy: Vec<_> = r
        .log
        .iter()
        .filter(|row| fault.covers(at_us(row.t_s)))
        .collect();
    assert_eq!(noisy.len(), FRAMES as usize);
    assert!(noisy.iter().all(|row| row.control_mode != "safe"));
    assert!(fault.dropout().is_none());
    let mut host_ecu = SimulatedEcu::<f32>::new(&scenario, &vehicle, &opts).unwrap();
    let host = run_with(&scenario, &vehicle, &opts, &mut host_ecu, |_, _| {}).unwrap();
    let c = compare(&r, &host);
    assert!(c.identical, "{c:?}");
    assert_counts_agree(&r, &ticks);
}

#[test]
#[ignore = "needs qemu-system-arm and `cargo ecu-lockstep`; .ci/run runs it"]
fn forged_replayed_and_corrupted_route_frames_are_refused_and_lose_only_their_window() {
    // The paper scenario with its obstacles; three frames of the first window
    // sent while driving replaced, from its third frame (two legitimate ones
    // before, for the replay).
    let scenario = Scenario::paper(true);
    let vehicle = VehicleParams::default();
    let opts = SimOptions {
        max_duration_s: 30.0,
        ..SimOptions::default()
    };
    let clean = run::<f32>(&scenario, &vehicle, &opts, |_, _| {}).unwrap();
    let route_releases: Vec<u64> = clean
        .plan_activations
        .iter()
        .filter(|a| a.route_frames > 0)
        .map(|a| a.release_us)
        .collect();
    // The first window's frames: up to the activation that adopts it.
    let lost = clean
        .plan_activations
        .iter()
        .find(|a| a.window)
        .expect("a window adopted in the run without the fault")
        .release_us;
    let route_releases: Vec<u64> = route_releases.into_iter().filter(|&t| t <= lost).collect();
    assert!(route_releases.len() > 5, "{route_releases:?}");
    const FRAMES: u32 = 3;
    let fault = LinkFault {
        spec: "route-mix:3".parse().unwrap(),
        start_us: route_releases[2],
    };
    assert_eq!(fault.spec.frames, FRAMES);
    let pil = PilOptions {
        link_fault: Some(fault),
        ..pil_options("route-fault", 4)
    };
    let (r, done, link, ticks, mut injected) = drive_pil(&scenario, &opts, &pil);
    injected.judge_by_counts(&done.refused);
    println!(
        "route-mix:3: {injected:?}, ECU {:?} of {}",
        done.refused, done.rejected_frames
    );
    // One frame of each kind, each refused for its reason by the ECU, none
    // acted on; the window's later frames refused as out of order (counted, with
    // no reason).
    let expected = FaultKinds::Mix.refusals(FRAMES);
    assert_eq!(injected.injected, expected);
    assert_eq!(done.refused, expected);
    assert_eq!(injected.refused_as_expected, u64::from(FRAMES));
    assert_eq!((injected.acted_on, injected.legitimate_refused), (0, 0));
    let window_frames = route_releases.len() as u32;
    assert!(
        done.rejected_frames > FRAMES && done.rejected_frames <= window_frames,
        "{} rejected of a window of {window_frames} frames",
        done.rejected_frames
    );
    assert_eq!((link.rejected, link.stale), (0, 0));
    // The window the frames belonged to was never adopted; the next one was,
    // after it, and the car went on with no more safe actuations than without
    // the fault.
    let adopted: Vec<u64> = r
        .plan_activations
        .iter()
        .filter(|a| a.window)
        .map(|a| a.release_us)
        .collect();
    assert!(!adopted.contains(&lost), "{adopted:?}");
    assert!(adopted.iter().any(|&t| t > lost), "{adopted:?}");
    assert_eq!(
        r.summary.control_safe_actuations,
        clean.summary.control_safe_actuations
    );
    assert_eq!(r.summary.collisions, 0);
    // Bit for bit the in-process run that drops the same frames.
    let mut modelled = SimulatedEcu::<f32>::new(&scenario, &vehicle, &opts).unwrap();
    modelled.refuse_route_frames(fault.route_frames().unwrap());
    let host = run_with(&scenario, &vehicle, &opts, &mut modelled, |_, _| {}).unwrap();
    let c = compare(&r, &host);
    assert!(c.identical, "{c:?}");
    assert_counts_agree(&r, &ticks);
}
