//! The two tasks together on a kinematic stand-in for the car: publication,
//! faults (failed plans, non-finite measurements) and the controlled stop.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::bicycle::BicycleGeometry;
use firmware::low_level::{LowLevelConfig, Mode};
use firmware::mpc::{MpcError, MpcSettings};
use firmware::plan::Plan;
use firmware::state_estimate::StateEstimate;
use firmware::tasks::{ControlTask, PlanTask, StopReason, CONTROL_PERIOD_US, PLAN_PERIOD_US};

const CAP: usize = 512;

struct Car {
    xi: [f64; 6],
    geometry: BicycleGeometry<f64>,
}

impl Car {
    /// A crude longitudinal model (torque / (m·r)) on the kinematic bicycle.
    fn step(&mut self, torque_total: f64, delta: f64, dt: f64) {
        let a = torque_total / (1500.0 * 0.3);
        let u = [a, (delta - self.xi[5]) / dt];
        self.xi = self.geometry.discretize(&self.xi, &u, dt).x_next;
        if self.xi[3] < 0.0 {
            self.xi[3] = 0.0;
        }
    }
    fn estimate(&self, t_us: u64) -> StateEstimate<f64> {
        StateEstimate {
            stamp_us: t_us,
            x_m: self.xi[1],
            y_m: self.xi[2],
            psi_rad: self.xi[4],
            vx_mps: self.xi[3],
            vy_mps: 0.0,
            yaw_rate_radps: 0.0,
            delta_rad: self.xi[5],
            ..StateEstimate::zeroed()
        }
    }
}

/// The built-in car as the firmware is told of it (the control tasks' tests).
fn vehicle() -> firmware::vehicle_config::VehicleConfig<f64> {
    firmware::vehicle_config::VehicleConfig::reference()
}

fn setup() -> (Box<PlanTask<f64, CAP>>, ControlTask<f64>, Car) {
    let geometry = firmware::vehicle_config::VehicleConfig::reference().geometry();
    let mut planner = Box::new(PlanTask::new(MpcSettings::paper(geometry, 0.6, 1.8), 1.0));
    let rows: Vec<[f64; 4]> = (0..400)
        .map(|i| [i as f64 * 2.0 - 20.0, 0.0, 4.0, 4.0])
        .collect();
    planner.path.load_track(&rows, false).unwrap();
    let control = ControlTask::new(LowLevelConfig::default()).unwrap();
    let car = Car {
        xi: [0.0, 0.0, 0.0, 15.0, 0.0, 0.0],
        geometry,
    };
    (planner, control, car)
}

/// Runs the loop for `seconds`; `fail_plans_from_s` makes every later plan fail
/// (the planner is handed a non-finite friction); `nan_at_s` feeds one non-finite
/// estimate.
type Outcome = (
    Box<PlanTask<f64, CAP>>,
    ControlTask<f64>,
    Car,
    Vec<(f64, Mode, f64)>,
);

fn run(seconds: f64, fail_plans_from_s: Option<f64>, nan_at_s: Option<f64>) -> Outcome {
    let (mut planner, mut control, mut car) = setup();
    let mut shared = Plan::zeroed();
    let mut trace = Vec::new();
    let mut t_us = 0u64;
    while (t_us as f64) * 1e-6 < seconds {
        let t = t_us as f64 * 1e-6;
        let mut est = car.estimate(t_us);
        if nan_at_s.is_some_and(|s| (t - s).abs() < 5e-3) {
            est.vx_mps = f64::NAN;
        }
        if t_us.is_multiple_of(PLAN_PERIOD_US) {
            if fail_plans_from_s.is_some_and(|s| t >= s) {
                planner.mu = f64::NAN;
            }
            if planner.run(&est).is_ok() {
                planner.publish(&mut shared);
            }
        }
        let act = control.run(&est, &shared, t_us);
        trace.push((t, act.mode, car.xi[3]));
        for _ in 0..10 {
            car.step(act.wheel_torque_nm.iter().sum(), act.delta_rad, 1e-3);
        }
        t_us += CONTROL_PERIOD_US;
    }
    (planner, control, car, trace)
}

#[test]
fn plans_are_published_and_followed() {
    let (planner, control, car, trace) = run(8.0, None, None);
    assert_eq!(planner.stats.activations, 80);
    assert_eq!(planner.stats.published, 80);
    assert_eq!(planner.stats.failures, 0);
    assert_eq!(control.stats.safe_actuations, 0);
    assert!(trace.iter().skip(1).all(|(_, m, _)| *m == Mode::Following));
    assert!(car.xi[2].abs() < 0.05, "lateral {}", car.xi[2]);
    assert!(car.xi[3] > 20.0, "speeds up on the straight: {}", car.xi[3]);
    assert_eq!(control.stop_reason(), None);
}

#[test]
fn failed_plans_are_not_published_and_the_car_stops_under_control() {
    let (planner, control, car, trace) = run(20.0, Some(3.0), None);
    assert_eq!(planner.stats.published, 30, "plans until t = 3 s only");
    assert_eq!(planner.stats.failures, planner.stats.activations - 30);
    assert_eq!(planner.last_error, Some(MpcError::InvalidFriction));
    // The last good plan is followed to its end, then the controlled stop.
    let first_stop = trace
        .iter()
        .find(|(_, m, _)| *m == Mode::Stopping)
        .unwrap()
        .0;
    assert!(
        first_stop > 3.0 && first_stop < 3.0 + 3.3,
        "stop began at {first_stop}"
    );
    assert!(car.xi[3] < 0.1, "stopped: {}", car.xi[3]);
    assert!(car.xi[2].abs() < 0.3, "on the road: {}", car.xi[2]);
    assert_eq!(control.stats.safe_actuations, 0);
    // The stop has its reason.
    assert_eq!(control.stop_reason(), Some(StopReason::PlanRanOut));
}

#[test]
fn non_finite_measurements_are_refused_counted_and_kept_safe() {
    let (planner, control, car, trace) = run(6.0, None, Some(4.0));
    assert_eq!(control.stats.non_finite_estimates, 1);
    assert_eq!(control.stats.safe_actuations, 1);
    // The NaN came on a planning instant (4.0 s): that plan was refused too.
    assert_eq!(planner.stats.non_finite_estimates, 1);
    assert_eq!(planner.stats.published, planner.stats.activations - 1);
    assert!(trace
        .iter()
        .any(|(t, m, _)| (*t - 4.0).abs() < 5e-3 && *m == Mode::Safe));
    assert!(car.xi.iter().all(|v| v.is_finite()));
    assert!(car.xi[2].abs() < 0.05);
}

#[test]
fn a_failed_activation_keeps_its_work_counters() {
    let (mut planner, _, car) = setup();
    // One QP iteration cannot solve the cold start: the activation fails...
    planner.settings.qp_max_iter = 1;
    let err = planner.run(&car.estimate(0)).unwrap_err();
    assert!(matches!(err, MpcError::Qp(_)), "{err:?}");
    // ...but what it did is still counted (the ECU spent that time).
    let r = *planner.last_report();
    assert_eq!((r.passes, r.qp_iterations), (1, 1), "{r:?}");
    assert!(r.rows > 0, "{r:?}");
    // A successful activation's counters replace them.
    planner.settings.qp_max_iter = 200;
    let ok = planner.run(&car.estimate(0)).unwrap();
    assert_eq!(planner.last_report(), &ok);
    assert!(ok.qp_iterations > 1);
}

#[test]
fn a_late_plan_is_published_but_one_older_than_two_periods_is_dropped() {
    use firmware::tasks::MAX_PLAN_AGE_US;
    let (mut planner, _, car) = setup();
    let mut shared = Plan::zeroed();
    // Released at 1 s, finished 150 ms later: late, still published.
    planner.run(&car.estimate(1_000_000)).unwrap();
    assert!(planner.publish_at(&mut shared, 1_150_000));
    assert_eq!(shared.stamp_us, 1_000_000);
    assert_eq!(planner.stats.stale, 0);
    // Released at 2 s, finished just past the age limit: dropped, the shared plan
    // untouched, counted.
    planner.run(&car.estimate(2_000_000)).unwrap();
    assert!(!planner.publish_at(&mut shared, 2_000_000 + MAX_PLAN_AGE_US + 1));
    assert_eq!(shared.stamp_us, 1_000_000);
    assert_eq!(planner.stats.stale, 1);
    assert!(planner.pending().is_none(), "a dropped plan is not kept");
    // Exactly at the limit it is still published.
    planner.run(&car.estimate(3_000_000)).unwrap();
    assert!(planner.publish_at(&mut shared, 3_000_000 + MAX_PLAN_AGE_US));
    assert_eq!(shared.stamp_us, 3_000_000);
}

#[test]
fn the_mpc_starts_from_the_last_plans_open_loop_steering() {
    let (mut planner, _, car) = setup();
    let est = car.estimate(0);
    // No plan yet: the measured steering.
    assert_eq!(planner.initial_steering(&est), est.delta_rad);
    planner.run(&est).unwrap();
    let plan = *planner.pending().unwrap();
    // 0.3 s later, with a measured steering the plan never had (the yaw loop's
    // feedback): the plan's steering, interpolated between nodes 1 and 2.
    let mut later = car.estimate(300_000);
    later.delta_rad = 0.07;
    let open_loop = 0.5 * (plan.nodes[1].delta_rad + plan.nodes[2].delta_rad);
    let gain = f64::from(firmware::tasks::STEER_FEEDBACK_GAIN);
    let want = open_loop + gain * (0.07 - open_loop);
    let got = planner.initial_steering(&later);
    assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    assert_ne!(got, later.delta_rad);
    // And the MPC's plan starts there.
    planner.run(&later).unwrap();
    assert!((planner.pending().unwrap().nodes[0].delta_rad - want).abs() < 1e-12);
    // Beyond the last plan's horizon, before its stamp, a non-finite measurement,
    // or after a reset: the measurement.
    let mut stale = car.estimate(300_000 + 3_200_000);
    stale.delta_rad = 0.07;
    assert_eq!(planner.initial_steering(&stale), 0.07);
    let mut early = car.estimate(0);
    early.delta_rad = 0.05;
    assert_eq!(planner.initial_steering(&early), 0.05);
    let mut nan = car.estimate(400_000);
    nan.delta_rad = f64::NAN;
    assert!(planner.initial_steering(&nan).is_nan());
    planner.reset();
    assert_eq!(planner.initial_steering(&later), 0.07);
}

/// The front tyres' grip check: a car steered at 0.1 rad at 15 m/s (the kinematic
/// `a_y` 8.5 m/s²) that turns at 4 m/s² (the steering's lateral force lost: the
/// front wheels locked, spinning or sliding) is saturated after
/// `UNDERSTEER_CONFIRM_S`, and the braking torque then leaves room for the lateral
/// force the steering asks (the friction ellipse at its floor, 0.3 of the grip); a
/// car that turns as steered is not saturated.
#[test]
fn understeer_saturates_the_front_and_the_brakes_leave_the_steering_its_grip() {
    let car = vehicle();
    let mut plan = Plan::zeroed();
    plan.dt_s = 0.2;
    for (k, n) in plan.nodes.iter_mut().enumerate() {
        // Braking hard from 15 m/s.
        n.v_mps = (15.0 - 6.0 * 0.2 * k as f64).max(0.0);
        n.delta_rad = 0.1;
    }
    for (a, n) in plan.inputs.iter_mut().zip(plan.nodes.iter()) {
        a[0] = if n.v_mps > 0.0 { -6.0 } else { 0.0 };
    }
    let run = |yaw_rate: f64| {
        let mut control = car.control_task(1.0).unwrap();
        let mut torque = 0.0;
        for k in 0..10u64 {
            let e = StateEstimate {
                stamp_us: k * CONTROL_PERIOD_US,
                x_m: 0.0,
                y_m: 0.0,
                psi_rad: 0.0,
                vx_mps: 15.0,
                vy_mps: 0.0,
                yaw_rate_radps: yaw_rate,
                delta_rad: 0.1,
                ..StateEstimate::zeroed()
            };
            torque = control
                .run(&e, &plan, k * CONTROL_PERIOD_US)
                .torque_total_nm;
        }
        (control.front_saturated(), torque)
    };
    // Saturated at a small front slip angle (0.1 − 1.1·4/15² ≈ 0.08 rad: the
    // wheels locked or spinning, not sliding sideways): the steering is free.
    let mut control = car.control_task(1.0).unwrap();
    for k in 0..10u64 {
        let e = StateEstimate {
            stamp_us: k * CONTROL_PERIOD_US,
            vx_mps: 15.0,
            yaw_rate_radps: 4.0 / 15.0,
            delta_rad: 0.1,
            ..StateEstimate::zeroed()
        };
        control.run(&e, &plan, k * CONTROL_PERIOD_US);
    }
    assert!(control.front_saturated() && !control.steering_held());
    // V²·tan δ/L = 225·0.1003/2.7 = 8.4 m/s².
    let (gripping, t_grip) = run(8.0 / 15.0);
    let (sliding, t_slide) = run(4.0 / 15.0);
    assert!(!gripping);
    assert!(sliding);
    // Braking: the torque within 0.3 of the grip while sliding (the ellipse at
    // 8.4 m/s² of the 8.8 the grip has), less than for the car that grips at
    // 8 m/s² (0.42 of it). Judged on the measured 4 m/s², the sliding car would
    // brake with 0.89 of the grip, twice as hard.
    assert!(t_grip < 0.0 && t_slide < 0.0, "{t_grip} {t_slide}");
    assert!(
        t_slide.abs() < 0.8 * t_grip.abs(),
        "braking {t_slide} N·m sliding against {t_grip} N·m gripping"
    );
}

/// Front tyres that slide sideways at a large angle hold the steering: a car at
/// 15 m/s steered at 0.25 rad that turns at 3 m/s² (front slip angle
/// 0.25 − atan(1.1·0.2/15) ≈ 0.235 rad) is held, the plan's growing steering
/// not followed; the same car with the front axle's lateral velocity 2.6 m/s
/// (slip angle 0.25 − atan(2.82/15) ≈ 0.064 rad, under `FRONT_SLIP_HOLD_RAD`)
/// steers towards the plan, and so does a car turning as steered; steered left
/// or right.
#[test]
fn front_tyres_sliding_at_a_large_angle_hold_the_steering() {
    use firmware::tasks::FRONT_SLIP_HOLD_RAD;
    let car = vehicle();
    let run = |vy: f64, yaw_rate: f64, side: f64| {
        // The plan steers further, 0.1 rad per node from 0.25, on the yaw the car
        // will have (no yaw error: the steering is the plan's).
        let mut plan = Plan::zeroed();
        plan.dt_s = 0.2;
        for (k, n) in plan.nodes.iter_mut().enumerate() {
            n.v_mps = 15.0;
            n.delta_rad = side * (0.25 + 0.1 * k as f64).min(0.55);
            n.psi_rad = side * yaw_rate * 0.2;
        }
        for (u, w) in plan.inputs.iter_mut().zip(plan.nodes.windows(2)) {
            u[1] = (w[1].delta_rad - w[0].delta_rad) / 0.2;
        }
        let mut control = car.control_task(1.0).unwrap();
        let mut steering = Vec::new();
        for k in 0..20u64 {
            let e = StateEstimate {
                stamp_us: k * CONTROL_PERIOD_US,
                vx_mps: 15.0,
                vy_mps: side * vy,
                yaw_rate_radps: side * yaw_rate,
                delta_rad: side * 0.25,
                ..StateEstimate::zeroed()
            };
            steering.push(side * control.run(&e, &plan, k * CONTROL_PERIOD_US).delta_rad);
        }
        (control.steering_held(), steering)
    };
    // Left and right alike (the steering's side flipped, and what it measures).
    for side in [1.0, -1.0] {
        let (held, s) = run(0.0, 3.0 / 15.0, side);
        assert!(held);
        // From the confirmation on (the 6th activation), no further than it was.
        assert!(s[5] > s[0], "{s:?}");
        assert!(s[6..].iter().all(|&d| d == s[5]), "{s:?}");
        let alpha = 0.25f64 - ((2.6f64 + 1.1 * 0.2) / 15.0).atan();
        assert!(alpha < f64::from(FRONT_SLIP_HOLD_RAD), "{alpha}");
        let (held, s_small) = run(2.6, 3.0 / 15.0, side);
        assert!(!held);
        assert!(s_small[19] > s[19] + 0.05, "{s_small:?} against {s:?}");
        // Turning as steered (V·ψ̇ = V²·tan δ/L): not saturated, not held.
        let (held, s_grip) = run(0.0, 15.0 * 0.2553 / 2.7, side);
        assert!(!held);
        assert!(s_grip[19] > s[19] + 0.05);
    }
}

#[test]
fn the_traction_limit_counts_the_load_the_cars_own_acceleration_takes_off_the_front() {
    let car = vehicle();
    let control = car.control_task(1.0).unwrap();
    let fc = *control.friction_config();
    // Before any sample the mass's uncertainty is its largest.
    let u = fc.longitudinal.mass_uncertainty_max;
    let g = f64::from(firmware::G);
    let grip = g * f64::from(firmware::tasks::TORQUE_GRIP_FRACTION);
    for ay in [0.0, 2.0, 4.0] {
        let inside = grip * (1.0 - 2.0 * ay / g * fc.cg_height_over_track);
        let ellipse = (1.0 - (ay / grip).powi(2)).sqrt();
        let inside = inside * ellipse;
        // Exact: `a = inside·(1 − u)·(share − (h/L)·a/g)` solved for `a`, the
        // transfer counted at the inside wheel's grip.
        let y = inside * fc.cg_height_over_wheelbase / g;
        let exact = inside * (1.0 - u) * fc.driven_load_share / (1.0 + y);
        let limit = control.car_model(ay, ay).traction_grip_mps2;
        assert!(limit <= exact, "a_y {ay}: {limit} over {exact}");
        assert!(
            limit >= exact * (1.0 - y.powi(4)) - 1e-12,
            "a_y {ay}: {limit} vs {exact}"
        );
        // The transfer matters: on a straight 15 % below the limit without it.
        let without = inside * (1.0 - u) * fc.driven_load_share;
        assert!(
            limit < without / (1.0 + 0.9 * y),
            "a_y {ay}: {limit} vs {without}"
        );
        if ay == 0.0 {
            assert!(limit < 0.86 * without, "{limit} vs {without}");
        }
    }
}

/// The brake force distribution follows the lateral load transfer: in a left
/// bend (`a_y > 0`) the right (outside) wheels get more of each axle's braking
/// torque, `1/2 + (h/t)·a_y/g`; in a right bend the left ones; on a straight
/// both alike; never less than 0.1 or more than 0.9 of it, whatever `a_y`.
#[test]
fn the_outside_wheels_of_a_bend_get_more_of_the_braking() {
    let car = vehicle();
    let control = car.control_task(1.0).unwrap();
    let k = control.friction_config().cg_height_over_track / f64::from(firmware::G);
    assert!(k > 0.0);
    assert_eq!(control.car_model(0.0, 0.0).brake_left_share, 0.5);
    for ay in [2.0, 5.0] {
        let left = control.car_model(ay, ay).brake_left_share;
        assert!((left - (0.5 - k * ay)).abs() < 1e-6, "a_y {ay}: {left}");
        let right_bend = control.car_model(ay, -ay).brake_left_share;
        assert!(
            (right_bend - (0.5 + k * ay)).abs() < 1e-6,
            "a_y {ay}: {right_bend}"
        );
    }
    assert_eq!(
        control.car_model(0.0, 1.0e3).brake_left_share,
        f64::from(0.1f32)
    );
    assert_eq!(
        control.car_model(0.0, -1.0e3).brake_left_share,
        f64::from(0.9f32)
    );
}

/// Traction control and an anti-lock limit from the wheel speeds: a driven
/// front wheel that spins halves the traction grip, a wheel that locks halves
/// the braking grip, from the activation that sees it; wheels that roll (or are
/// not measured) leave both as they were.
#[test]
fn a_spinning_wheel_halves_the_traction_and_a_locked_one_the_braking() {
    let (_, mut control, _) = setup();
    let plan = Plan::<f64>::zeroed();
    let at = |wheels: [f64; 4]| StateEstimate {
        vx_mps: 20.0,
        wheel_speed_mps: wheels,
        ..StateEstimate::zeroed()
    };
    let mut limits = |wheels: [f64; 4]| {
        control.run(&at(wheels), &plan, 0);
        let m = control.car_model(0.0, 0.0);
        (m.traction_grip_mps2, m.braking_grip_mps2)
    };
    let (t0, b0) = limits([f64::NAN; 4]);
    assert_eq!(limits([20.0; 4]), (t0, b0));
    // The front left wheel 5 m/s faster than the ground (slip ratio 0.25, over
    // 0.15·20 + 1 m/s): traction halved.
    let (t, b) = limits([25.0, 20.0, 20.0, 20.0]);
    assert!(
        (t - 0.5 * t0).abs() < 1e-12 && b == b0,
        "{t} {b} vs {t0} {b0}"
    );
    // A rear wheel (undriven) spinning is not traction slip; locking is.
    assert_eq!(limits([20.0, 20.0, 25.0, 20.0]), (t0, b0));
    let (t, b) = limits([20.0, 20.0, 20.0, 15.0]);
    assert!(
        t == t0 && (b - 0.5 * b0).abs() < 1e-12,
        "{t} {b} vs {t0} {b0}"
    );
}

/// The same limits reach the torque commanded: a plan asking 6 m/s² (or −8) of
/// a car at 20 m/s gets the traction (braking) limit; with a driven wheel
/// spinning (any wheel locked) in the estimate, half its grip, in that very
/// activation. The car's model is the one the task reports (resistances
/// included), so the torque is checked against it exactly.
#[test]
fn a_spinning_or_locked_wheel_halves_the_torque_commanded_at_once() {
    let car = vehicle();
    let r = car.wheel_radius_m;
    let plan_asking = |accel: f64| {
        let mut p = Plan::<f64>::zeroed();
        p.dt_s = 0.2;
        for (k, n) in p.nodes.iter_mut().enumerate() {
            n.v_mps = 20.0;
            n.x_m = 20.0 * 0.2 * k as f64;
            n.s_m = n.x_m;
        }
        for u in p.inputs.iter_mut() {
            u[0] = accel;
        }
        p
    };
    // The torque of one activation of a fresh task, and the limit its model
    // gives: traction `(m·a_t + F₀ + c₂·V²)·r`, braking `m·a_b·r/b`.
    let torque = |accel: f64, wheels: [f64; 4]| {
        let mut control = car.control_task(1.0).unwrap();
        let e = StateEstimate {
            vx_mps: 20.0,
            wheel_speed_mps: wheels,
            ..StateEstimate::zeroed()
        };
        let a = control.run(&e, &plan_asking(accel), 0);
        assert_eq!(a.mode, Mode::Following);
        let m = control.car_model(0.0, 0.0);
        let res = m.resistance_n + m.drag_n_per_mps2 * 400.0;
        let traction = (m.mass_kg * m.traction_grip_mps2 + res.max(0.0)) * r;
        let braking = m.mass_kg * m.braking_grip_mps2 * r * m.inverse_brake_gain;
        (a.torque_total_nm, traction, braking)
    };
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9 * b.abs().max(1.0);
    let rolling = [20.0; 4];
    let (t0, traction0, _) = torque(6.0, rolling);
    assert!(close(t0, traction0), "{t0} vs {traction0}");
    let (t, traction, _) = torque(6.0, [20.0, 26.0, 20.0, 20.0]);
    assert!(close(t, traction) && t < 0.6 * t0, "{t} vs {t0}");
    let (b0, _, braking0) = torque(-8.0, rolling);
    assert!(close(b0, -braking0), "{b0} vs {braking0}");
    let (b, _, braking) = torque(-8.0, [20.0, 20.0, 14.0, 20.0]);
    assert!(close(b, -braking) && close(b, 0.5 * b0), "{b} vs {b0}");
    // A locked wheel leaves the traction alone, a spinning one the braking.
    assert!(close(torque(6.0, [20.0, 20.0, 14.0, 20.0]).0, t0));
    assert!(close(torque(-8.0, [26.0, 20.0, 20.0, 20.0]).0, b0));
}

/// The sideslip lag learns only while the control task finds the tyres within
/// their linear range. The control task says so after a plan period of them
/// (`TYRES_LINEAR_PERIODS` control periods) and stops saying so as soon as the
/// front saturates (a car steered at 0.1 rad at 15 m/s that turns at 4 m/s²);
/// the plan task's samples (a car at 15 m/s turning at 3 m/s² whose course
/// points 0.02 rad outwards) raise `λ` only while it does.
#[test]
fn the_sideslip_lag_learns_only_while_the_tyres_are_linear() {
    use firmware::tasks::TYRES_LINEAR_PERIODS;
    let car = vehicle();
    let mut plan = Plan::zeroed();
    plan.dt_s = 0.2;
    for n in plan.nodes.iter_mut() {
        n.v_mps = 15.0;
        n.delta_rad = 0.1;
    }
    let mut control = car.control_task(1.0).unwrap();
    let mut k = 0u64;
    let mut step = |control: &mut ControlTask<f64>, yaw_rate: f64| {
        let e = StateEstimate {
            stamp_us: k * CONTROL_PERIOD_US,
            vx_mps: 15.0,
            yaw_rate_radps: yaw_rate,
            delta_rad: 0.1,
            ..StateEstimate::zeroed()
        };
        control.run(&e, &plan, k * CONTROL_PERIOD_US);
        k += 1;
        control.tyres_linear()
    };
    let (grip, slide) = (8.0 / 15.0, 4.0 / 15.0);
    let periods = usize::from(TYRES_LINEAR_PERIODS);
    assert_eq!(periods, 10);
    // Gripping: linear from the plan period's last control period on.
    let first: Vec<bool> = (0..periods).map(|_| step(&mut control, grip)).collect();
    assert!(first[..periods - 1].iter().all(|l| !l), "{first:?}");
    assert!(first[periods - 1]);
    // Understeer: linear until the front is declared saturated, then not.
    let sliding: Vec<bool> = (0..10).map(|_| step(&mut control, slide)).collect();
    assert!(control.front_saturated());
    assert!(sliding[0] && !sliding[9], "{sliding:?}");
    // Gripping again: a plan period before the tyres count as linear.
    let again: Vec<bool> = (0..periods).map(|_| step(&mut control, grip)).collect();
    assert!(again[..periods - 1].iter().all(|l| !l), "{again:?}");
    assert!(again[periods - 1]);

    let (mut planner, _, car) = setup();
    let mut t_us = 0;
    let mut sample = |planner: &mut PlanTask<f64, CAP>, linear: bool| {
        let mut e = car.estimate(t_us);
        e.yaw_rate_radps = 0.2;
        e.vy_mps = -0.3;
        planner.set_tyres_linear(linear);
        let _ = planner.run(&e);
        t_us += PLAN_PERIOD_US;
        planner.sideslip_lag()
    };
    for _ in 0..5 {
        assert_eq!(sample(&mut planner, false), 0.0);
    }
    let learnt = (0..5).map(|_| sample(&mut planner, true)).last().unwrap();
    assert!(learnt > 0.0, "{learnt}");
    // Beyond the linear range again: λ held where it was.
    assert_eq!(sample(&mut planner, false), learnt);
}
