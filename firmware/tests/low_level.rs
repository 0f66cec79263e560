//! Tests of the low-level controllers (`firmware::low_level`).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::field_reassign_with_default,
    missing_docs
)]

use firmware::low_level::{
    self, control, control_with_model, safe_actuation, wrap_pi, Actuation, CarModel, ControlFault,
    LowLevelConfig, LowLevelConfigError, LowLevelState, Mode,
};
use firmware::pid::{self, PidState};
use firmware::plan::{Plan, PlanNode, HORIZON};
use firmware::state_estimate::StateEstimate;

const DT_U: f64 = 0.2;
const US: u64 = 1_000_000;

/// A straight plan along X at constant speed `v`, stamped at `stamp_us`.
fn straight_plan(stamp_us: u64, v: f64) -> Plan<f64> {
    let mut p = Plan::zeroed();
    p.stamp_us = stamp_us;
    p.dt_s = DT_U;
    for (k, n) in p.nodes.iter_mut().enumerate() {
        n.v_mps = v;
        n.x_m = v * DT_U * k as f64;
        n.s_m = n.x_m;
    }
    p
}

fn est(v: f64, psi: f64) -> StateEstimate<f64> {
    StateEstimate {
        vx_mps: v,
        psi_rad: psi,
        ..StateEstimate::zeroed()
    }
}

fn cfg_no_ff() -> LowLevelConfig<f64> {
    let mut c = LowLevelConfig::default();
    c.accel_feedforward = false;
    c
}

/// Field `k` of a plan node, in the order `s, x, y, V, ψ, δ`.
fn node_field(n: &mut PlanNode<f64>, k: usize) -> &mut f64 {
    [
        &mut n.s_m,
        &mut n.x_m,
        &mut n.y_m,
        &mut n.v_mps,
        &mut n.psi_rad,
        &mut n.delta_rad,
    ]
    .into_iter()
    .nth(k)
    .expect("a node has 6 fields")
}

fn sum(a: &Actuation<f64>) -> f64 {
    a.wheel_torque_nm.iter().sum()
}

#[test]
fn default_config_is_valid_in_both_precisions() {
    assert_eq!(LowLevelConfig::<f64>::default().validate(), Ok(()));
    assert_eq!(LowLevelConfig::<f32>::default().validate(), Ok(()));
    let mut c = LowLevelConfig::<f64>::default();
    c.mass_kg = 0.0;
    assert_eq!(c.validate(), Err(LowLevelConfigError::InvalidVehicle));
    let mut c = LowLevelConfig::<f64>::default();
    c.steer_limit_rad = f64::NAN;
    assert_eq!(c.validate(), Err(LowLevelConfigError::InvalidSteeringLimit));
    let mut c = LowLevelConfig::<f64>::default();
    c.yaw_pid.kp = -1.0;
    assert!(matches!(c.validate(), Err(LowLevelConfigError::YawPid(_))));
    let mut c = LowLevelConfig::<f64>::default();
    c.stop_decel_mps2 = 0.0;
    assert_eq!(c.validate(), Err(LowLevelConfigError::InvalidStopDecel));
}

#[test]
fn traction_goes_to_front_wheels_and_total_equals_pid_output() {
    let cfg = cfg_no_ff();
    let mut st = LowLevelState::new();
    let plan = straight_plan(0, 10.0);
    // Car slower than planned → traction.
    let a = control(&cfg, &mut st, &plan, &est(9.0, 0.0), 0).unwrap();
    let [fl, fr, rl, rr] = a.wheel_torque_nm;
    assert!(fl > 0.0);
    assert_eq!(fl, fr);
    assert_eq!((rl, rr), (0.0, 0.0));
    // The same PID, alone, gives the same total.
    let mut ps = PidState::new();
    let u = pid::update(&cfg.speed_pid, &mut ps, 10.0, 9.0, cfg.period_s).unwrap();
    assert!((sum(&a) - u).abs() < 1e-9, "{} vs {u}", sum(&a));
    assert_eq!(a.torque_total_nm, sum(&a));
    assert_eq!(a.torque_ff_nm, 0.0);
}

#[test]
fn braking_goes_equally_to_all_four_wheels() {
    let cfg = cfg_no_ff();
    let mut st = LowLevelState::new();
    let plan = straight_plan(0, 10.0);
    let a = control(&cfg, &mut st, &plan, &est(11.0, 0.0), 0).unwrap();
    let w = a.wheel_torque_nm;
    assert!(w[0] < 0.0);
    assert!(w.iter().all(|&t| t == w[0]));
    let mut ps = PidState::new();
    let u = pid::update(&cfg.speed_pid, &mut ps, 10.0, 11.0, cfg.period_s).unwrap();
    assert!((sum(&a) - u).abs() < 1e-9);
}

#[test]
fn torque_is_limited_and_feedforward_adds_m_a_r() {
    let cfg = LowLevelConfig::<f64>::default();
    let mut st = LowLevelState::new();
    let mut plan = straight_plan(0, 10.0);
    for u in plan.inputs.iter_mut() {
        u[0] = 2.0;
    }
    // On the planned speed: the torque is the feed-forward alone.
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 0).unwrap();
    assert!((a.torque_ff_nm - 1500.0 * 2.0 * 0.3).abs() < 1e-9);
    assert!((a.torque_total_nm - 900.0).abs() < 1e-9);
    // Far too slow: total traction saturates at the limit.
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(0.0, 0.0), 0).unwrap();
    assert_eq!(a.torque_total_nm, cfg.max_traction_torque_nm);
    // Far too fast: total braking saturates at the limit.
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(30.0, 0.0), 0).unwrap();
    assert!((sum(&a) + cfg.max_braking_torque_nm).abs() < 1e-9);
}

#[test]
fn feedforward_switch_gives_the_papers_pure_pid() {
    let mut plan = straight_plan(0, 10.0);
    for u in plan.inputs.iter_mut() {
        u[0] = -4.0;
    }
    let cfg = cfg_no_ff();
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 0).unwrap();
    assert_eq!(a.torque_ff_nm, 0.0);
    assert_eq!(a.torque_total_nm, 0.0);
    let cfg = LowLevelConfig::<f64>::default();
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 0).unwrap();
    assert!((a.torque_total_nm + 1500.0 * 4.0 * 0.3).abs() < 1e-9);
    // Braking feed-forward goes to the four wheels.
    assert!(a.wheel_torque_nm.iter().all(|&t| t == a.wheel_torque_nm[3]));
}

#[test]
fn speed_integrator_does_not_wind_up_at_the_torque_limit() {
    let cfg = cfg_no_ff();
    let plan = straight_plan(0, 10.0);
    let mut st = LowLevelState::new();
    for k in 0..300u64 {
        let a = control(&cfg, &mut st, &plan, &est(5.0, 0.0), k * 10_000).unwrap();
        assert_eq!(a.torque_total_nm, cfg.max_traction_torque_nm);
    }
    // P alone (900·5 = 4500 N·m) is beyond the 3000 N·m limit: no integration.
    assert_eq!(st.speed_pid.integral, 0.0);
    // Speed error reverses: braking at once.
    let a = control(&cfg, &mut st, &plan, &est(10.5, 0.0), 3_000_000).unwrap();
    assert!(a.torque_total_nm < 0.0);
}

#[test]
fn v_ref_is_linearly_interpolated() {
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(5 * US, 10.0);
    plan.nodes[3].v_mps = 10.0;
    plan.nodes[4].v_mps = 12.0;
    // Midpoint of interval 3: t = 3.5·0.2 = 0.7 s.
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 5 * US + 700_000).unwrap();
    assert!((a.v_ref_mps - 11.0).abs() < 1e-12, "{}", a.v_ref_mps);
    // A quarter of the way.
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 5 * US + 650_000).unwrap();
    assert!((a.v_ref_mps - 10.5).abs() < 1e-12);
    assert_eq!(a.mode, Mode::Following);
}

#[test]
fn delta_ol_starts_at_plan_delta_and_integrates_the_first_rate() {
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(US, 10.0);
    plan.nodes[0].delta_rad = 0.1;
    plan.inputs[0][1] = 0.3;
    for k in 1..=HORIZON {
        plan.nodes[k].delta_rad = 0.1 + 0.3 * DT_U;
    }
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), US).unwrap();
    assert!(a.new_plan);
    assert_eq!(a.delta_ol_rad, 0.1);
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), US + 50_000).unwrap();
    assert!(!a.new_plan);
    assert!((a.delta_ol_rad - (0.1 + 0.3 * 0.05)).abs() < 1e-12);
    // Next interval: rate 0 → holds δ_1.
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), US + 300_000).unwrap();
    assert!((a.delta_ol_rad - (0.1 + 0.3 * DT_U)).abs() < 1e-12);

    // A new plan restarts δ_ol from its own node 0.
    let mut p2 = plan;
    p2.stamp_us = US + 310_000;
    p2.nodes[0].delta_rad = -0.05;
    let a = control(&cfg, &mut st, &p2, &est(10.0, 0.0), US + 310_000).unwrap();
    assert!(a.new_plan);
    assert_eq!(a.delta_ol_rad, -0.05);
    assert_eq!(st.plans_seen, 2);
}

#[test]
fn car_yawed_right_of_plan_steers_left() {
    let cfg = cfg_no_ff();
    let plan = straight_plan(0, 10.0);
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, -0.1), 0).unwrap();
    assert!(a.yaw_error_rad < 0.0);
    assert!(a.delta_cl_rad > 0.0, "δ_cl = {}", a.delta_cl_rad);
    // K_P·0.1 + one integration step K_I·0.1·Δt, no D on the first step.
    assert!((a.delta_cl_rad - (0.1 + 0.5 * 0.1 * 0.01)).abs() < 1e-12);
    // Yawing right at 0.5 rad/s while aligned: projected error −0.1 → steer left.
    let mut st = LowLevelState::new();
    let mut e = est(10.0, 0.0);
    e.yaw_rate_radps = -0.5;
    let a = control(&cfg, &mut st, &plan, &e, 0).unwrap();
    assert!((a.yaw_error_rad + 0.1).abs() < 1e-12);
    assert!(a.delta_rad > 0.0);
    // And the mirror image.
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.1), 0).unwrap();
    assert!(a.delta_rad < 0.0);
}

#[test]
fn yaw_error_is_wrapped() {
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(0, 10.0);
    for n in plan.nodes.iter_mut() {
        n.psi_rad = 3.1;
    }
    let mut st = LowLevelState::new();
    // −3.1 is 0.0832 rad to the left of 3.1 across ±π.
    let a = control(&cfg, &mut st, &plan, &est(10.0, -3.1), 0).unwrap();
    let expected = 2.0 * std::f64::consts::PI - 6.2;
    assert!((a.yaw_error_rad - expected).abs() < 1e-12);
    assert!(a.delta_rad < 0.0);
    assert!((wrap_pi(std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-15);
    assert!((wrap_pi(-std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-15);
    assert!((wrap_pi(7.0f64) - (7.0 - 2.0 * std::f64::consts::PI)).abs() < 1e-12);
    assert!((wrap_pi(-100.0f32) - (-100.0 + 32.0 * std::f32::consts::PI)).abs() < 1e-4);
}

#[test]
fn steering_saturates_at_the_mechanical_limit_without_windup() {
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(0, 10.0);
    for n in plan.nodes.iter_mut() {
        n.delta_rad = 0.55;
    }
    let mut st = LowLevelState::new();
    // Car far right of the plan for 2 s: δ_cl wants +0.3, only 0.05 is left.
    for k in 0..200u64 {
        let a = control(&cfg, &mut st, &plan, &est(10.0, -0.5), k * 10_000).unwrap();
        assert_eq!(a.delta_rad, cfg.steer_limit_rad);
        assert!((a.delta_cl_rad - 0.05).abs() < 1e-12);
    }
    // P alone (0.5) is beyond the window: the integrator did not grow.
    assert_eq!(st.yaw_pid.integral, 0.0);
    // Error reverses: the command leaves the limit at once.
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.1), 2_000_000).unwrap();
    assert!(a.delta_rad < cfg.steer_limit_rad - 0.05);
}

#[test]
fn steering_rate_limit() {
    let mut cfg = cfg_no_ff();
    cfg.steer_rate_limit_radps = 1.0;
    let mut plan = straight_plan(0, 10.0);
    let mut st = LowLevelState::new();
    control(&cfg, &mut st, &plan, &est(10.0, 0.0), 0).unwrap();
    for n in plan.nodes.iter_mut() {
        n.delta_rad = 0.4;
    }
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 10_000).unwrap();
    assert!((a.delta_rad - 0.01).abs() < 1e-12, "{}", a.delta_rad);
}

#[test]
fn stale_plan_stops_the_car() {
    let cfg = cfg_no_ff();
    let plan = straight_plan(0, 12.0);
    let mut st = LowLevelState::new();
    let mut modes = Vec::new();
    let mut last_v = f64::INFINITY;
    let mut reached_zero_at = None;
    for k in 0..1000u64 {
        let now = k * 10_000;
        let a = control(&cfg, &mut st, &plan, &est(12.0, 0.0), now).unwrap();
        if modes.last() != Some(&a.mode) {
            modes.push(a.mode);
        }
        if a.mode == Mode::Stopping {
            assert!(a.v_ref_mps <= last_v);
            assert!(a.v_ref_mps < 12.0);
            last_v = a.v_ref_mps;
            if a.v_ref_mps == 0.0 && reached_zero_at.is_none() {
                reached_zero_at = Some(now);
            }
        } else {
            assert_eq!(a.v_ref_mps, 12.0);
        }
    }
    assert_eq!(
        modes,
        vec![Mode::Following, Mode::Extrapolating, Mode::Stopping]
    );
    // 12 m/s at 3 m/s² → zero 4 s after the end of the 3.2 s plan.
    let t0 = reached_zero_at.unwrap() as f64 * 1e-6;
    assert!((t0 - 7.2).abs() < 0.011, "zero at {t0}");
    assert_eq!(last_v, 0.0);
}

#[test]
fn stopping_with_feedforward_brakes_and_holds_the_last_arc() {
    let cfg = LowLevelConfig::<f64>::default();
    let mut plan = straight_plan(0, 10.0);
    // Last interval turning left at 0.2 rad/s with δ = 0.05.
    for (k, n) in plan.nodes.iter_mut().enumerate() {
        n.psi_rad = 0.04 * k as f64;
        n.delta_rad = 0.05;
    }
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.64), 4_000_000).unwrap();
    assert_eq!(a.mode, Mode::Stopping);
    assert!((a.v_ref_mps - (10.0 - 3.0 * 0.8)).abs() < 1e-9);
    assert!((a.torque_ff_nm + 1500.0 * 3.0 * 0.3).abs() < 1e-9);
    assert!(a.torque_total_nm < 0.0);
    assert_eq!(a.delta_ol_rad, 0.05);
    // ψ^r continues on the arc: at s = 1.0 s, ∫V^r/V_N = 1 − 3/(2·10) = 0.85 s.
    assert!((a.psi_ref_rad - (0.64 + 0.2 * 0.85)).abs() < 1e-9);
    // Long after: the reference is at rest, its yaw stays where the stop ends.
    let a = control(&cfg, &mut st, &plan, &est(0.0, 0.64), 60_000_000).unwrap();
    assert_eq!(a.v_ref_mps, 0.0);
    assert!((a.psi_ref_rad - (0.64 + 0.2 * 10.0 / 6.0)).abs() < 1e-9);
}

#[test]
fn nan_estimate_is_refused_and_safe_actuation_holds_steering() {
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(0, 10.0);
    for n in plan.nodes.iter_mut() {
        n.delta_rad = 0.1;
    }
    let mut st = LowLevelState::new();
    let ok = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 0).unwrap();
    let before = st;
    for bad in [
        est(f64::NAN, 0.0),
        est(10.0, f64::INFINITY),
        StateEstimate {
            yaw_rate_radps: f64::NAN,
            ..est(10.0, 0.0)
        },
    ] {
        assert_eq!(
            control(&cfg, &mut st, &plan, &bad, 10_000),
            Err(ControlFault::NonFiniteEstimate)
        );
        assert_eq!(st, before);
    }
    let safe = safe_actuation(&cfg, &st);
    assert_eq!(safe.mode, Mode::Safe);
    assert_eq!(safe.delta_rad, ok.delta_rad);
    let w = safe.wheel_torque_nm;
    assert!(w.iter().all(|&t| t == w[0] && t < 0.0));
    assert!((sum(&safe) + cfg.safe_brake_torque_nm).abs() < 1e-9);
    // Before any command: steering held at 0.
    let fresh = safe_actuation(&cfg, &LowLevelState::new());
    assert_eq!(fresh.delta_rad, 0.0);
    assert_eq!(
        Actuation::safe(0.2f32, 1000.0).wheel_torque_nm,
        [-250.0f32; 4]
    );
}

#[test]
fn non_finite_values_read_or_an_empty_plan_are_refused() {
    let cfg = cfg_no_ff();
    let e = est(10.0, 0.0);
    type Edit = fn(&mut Plan<f64>);
    // With nodes 0.2 s apart, at 0.25 s the references are sampled between
    // nodes 1 and 2 (input 1) and, a node ahead, between nodes 2 and 3 (input 2);
    // at 4 s, past the 3.2 s horizon, from the last two nodes.
    let read: [(u64, Edit); 8] = [
        (250_000, |p| p.nodes[1].v_mps = f64::NAN),
        (250_000, |p| p.nodes[3].psi_rad = f64::INFINITY),
        (250_000, |p| p.nodes[2].delta_rad = f64::NAN),
        (250_000, |p| p.inputs[1][1] = f64::NAN),
        (250_000, |p| p.inputs[2][0] = f64::NEG_INFINITY),
        (250_000, |p| p.dt_s = f64::NAN),
        (4 * US, |p| p.nodes[HORIZON].v_mps = f64::NAN),
        (4 * US, |p| p.nodes[HORIZON - 1].psi_rad = f64::INFINITY),
    ];
    for (k, (now, edit)) in read.into_iter().enumerate() {
        let mut st = LowLevelState::new();
        let mut plan = straight_plan(0, 10.0);
        edit(&mut plan);
        assert!(!plan.is_finite(), "case {k}");
        assert_eq!(
            control(&cfg, &mut st, &plan, &e, now),
            Err(ControlFault::NonFinitePlan),
            "case {k}"
        );
        assert_eq!(st, LowLevelState::new(), "case {k}: state untouched");
    }
    // A value not read in this period is not the control's to check: the plan
    // task publishes only plans finite throughout (`Plan::is_finite`).
    let mut st = LowLevelState::new();
    let mut plan = straight_plan(0, 10.0);
    plan.nodes[10].y_m = f64::NAN;
    assert!(!plan.is_finite());
    assert!(control(&cfg, &mut st, &plan, &e, 250_000).is_ok());
    let mut st = LowLevelState::new();
    assert_eq!(
        control(&cfg, &mut st, &Plan::zeroed(), &e, 0),
        Err(ControlFault::InvalidPlan)
    );
    assert_eq!(st, LowLevelState::new());
}

#[test]
fn a_plan_is_finite_only_when_every_node_input_and_step_is() {
    assert!(straight_plan(0, 10.0).is_finite());
    assert!(Plan::<f64>::zeroed().is_finite());
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        for k in 0..=HORIZON {
            for field in 0..6 {
                let mut p = straight_plan(0, 10.0);
                *node_field(&mut p.nodes[k], field) = bad;
                assert!(!p.is_finite(), "node {k} field {field}");
            }
        }
        for k in 0..HORIZON {
            for j in 0..2 {
                let mut p = straight_plan(0, 10.0);
                p.inputs[k][j] = bad;
                assert!(!p.is_finite(), "input {k}.{j}");
            }
        }
        let mut p = straight_plan(0, 10.0);
        p.dt_s = bad;
        assert!(!p.is_finite());
    }
    // Finite values whose sum would overflow are finite.
    let mut p = straight_plan(0, 10.0);
    p.dt_s = f64::MAX;
    for n in p.nodes.iter_mut() {
        (n.s_m, n.x_m, n.y_m, n.v_mps, n.psi_rad, n.delta_rad) =
            (f64::MAX, f64::MAX, f64::MAX, f64::MAX, f64::MAX, -f64::MAX);
    }
    p.inputs = [[f64::MAX, f64::MAX]; HORIZON];
    assert!(p.is_finite());
}

#[test]
fn a_state_estimate_is_finite_only_when_every_field_is() {
    let e = StateEstimate::<f64> {
        x_m: f64::MAX,
        y_m: f64::MAX,
        psi_rad: -f64::MAX,
        vx_mps: f64::MAX,
        vy_mps: f64::MAX,
        yaw_rate_radps: f64::MAX,
        delta_rad: f64::MAX,
        ..StateEstimate::zeroed()
    };
    assert!(e.is_finite(), "finite values whose sum overflows");
    assert!(StateEstimate::<f32>::zeroed().is_finite());
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        for field in 0..7 {
            let mut e = est(10.0, 0.0);
            *[
                &mut e.x_m,
                &mut e.y_m,
                &mut e.psi_rad,
                &mut e.vx_mps,
                &mut e.vy_mps,
                &mut e.yaw_rate_radps,
                &mut e.delta_rad,
            ][field] = bad;
            assert!(!e.is_finite(), "field {field}");
            let mut st = LowLevelState::new();
            assert_eq!(
                control(&cfg_no_ff(), &mut st, &straight_plan(0, 10.0), &e, 0),
                Err(ControlFault::NonFiniteEstimate),
                "field {field}"
            );
        }
    }
}

#[test]
fn clock_behind_plan_is_handled() {
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(10 * US, 10.0);
    plan.nodes[0].v_mps = 9.0;
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 9 * US).unwrap();
    assert!((a.plan_age_s + 1.0).abs() < 1e-9);
    assert_eq!(a.mode, Mode::Following);
    assert_eq!(a.v_ref_mps, 9.0);
    // And a control clock that goes backwards between calls.
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 8 * US).unwrap();
    assert!(a.delta_rad.is_finite());
    // Extreme stamps.
    let a = control(
        &cfg,
        &mut st,
        &straight_plan(u64::MAX, 1.0),
        &est(1.0, 0.0),
        0,
    )
    .unwrap();
    assert!(a.plan_age_s < 0.0);
    let a = control(
        &cfg,
        &mut st,
        &straight_plan(0, 1.0),
        &est(1.0, 0.0),
        u64::MAX,
    )
    .unwrap();
    assert_eq!(a.mode, Mode::Stopping);
    assert_eq!(a.v_ref_mps, 0.0);
}

#[test]
fn f32_runs_and_agrees_with_f64() {
    let c32 = LowLevelConfig::<f32>::default();
    let c64 = LowLevelConfig::<f64>::default();
    let p64 = straight_plan(0, 10.0);
    let mut p32 = Plan::<f32>::zeroed();
    p32.dt_s = 0.2;
    for (a, b) in p32.nodes.iter_mut().zip(p64.nodes.iter()) {
        a.v_mps = b.v_mps as f32;
        a.x_m = b.x_m as f32;
        a.psi_rad = 0.01;
    }
    let mut p64b = p64;
    for n in p64b.nodes.iter_mut() {
        n.psi_rad = 0.01f32 as f64;
    }
    let (mut s32, mut s64) = (LowLevelState::new(), LowLevelState::new());
    let e32 = StateEstimate {
        vx_mps: 9.5f32,
        ..StateEstimate::zeroed()
    };
    for k in 0..50u64 {
        let a = control(&c32, &mut s32, &p32, &e32, k * 10_000).unwrap();
        let b = control(&c64, &mut s64, &p64b, &est(9.5, 0.0), k * 10_000).unwrap();
        assert!((a.torque_total_nm as f64 - b.torque_total_nm).abs() < 1e-2);
        assert!((a.delta_rad as f64 - b.delta_rad).abs() < 1e-6);
    }
}

// ---------------------------------------------------------------------------
// Closed-loop smoke test.

/// Reference: constant speed `v` on a circle of radius `r` (left turn; straight
/// line for `r = ∞`), starting at the origin heading +X. Rear-axle kinematics.
struct Reference {
    v: f64,
    r: f64,
    wheelbase: f64,
}

impl Reference {
    fn at(&self, t: f64) -> (f64, f64, f64) {
        let s = self.v * t;
        if self.r.is_infinite() {
            return (s, 0.0, 0.0);
        }
        let psi = s / self.r;
        (self.r * psi.sin(), self.r * (1.0 - psi.cos()), psi)
    }
    fn delta(&self) -> f64 {
        (self.wheelbase / self.r).atan()
    }
    fn plan(&self, stamp_us: u64) -> Plan<f64> {
        let mut p = Plan::zeroed();
        p.stamp_us = stamp_us;
        p.dt_s = DT_U;
        let t0 = stamp_us as f64 * 1e-6;
        for (k, n) in p.nodes.iter_mut().enumerate() {
            let (x, y, psi) = self.at(t0 + DT_U * k as f64);
            n.x_m = x;
            n.y_m = y;
            n.psi_rad = psi;
            n.v_mps = self.v;
            n.s_m = self.v * (t0 + DT_U * k as f64);
            n.delta_rad = self.delta();
        }
        p
    }
}

/// A car unlike the planner's model: steering 15 % less effective (understeer),
/// a 50 ms steering lag, drag and rolling resistance, 1500 kg on 0.3 m wheels.
struct Car {
    x: f64,
    y: f64,
    psi: f64,
    v: f64,
    delta: f64,
    wheelbase: f64,
}

impl Car {
    fn yaw_rate(&self) -> f64 {
        self.v * (0.85 * self.delta).tan() / self.wheelbase
    }
    fn step(&mut self, a: &Actuation<f64>, dt: f64) {
        let torque: f64 = a.wheel_torque_nm.iter().sum();
        let resist = 0.5 * 1.225 * 0.31 * 2.2 * self.v * self.v + 0.015 * 1500.0 * 9.81;
        let accel = (torque / 0.3 - resist) / 1500.0;
        self.delta += (a.delta_rad - self.delta) * dt / 0.05;
        let r = self.yaw_rate();
        self.x += self.v * self.psi.cos() * dt;
        self.y += self.v * self.psi.sin() * dt;
        self.psi += r * dt;
        self.v = (self.v + accel * dt).max(0.0);
    }
    fn estimate(&self, now_us: u64) -> StateEstimate<f64> {
        StateEstimate {
            stamp_us: now_us,
            x_m: self.x,
            y_m: self.y,
            psi_rad: self.psi,
            vx_mps: self.v,
            vy_mps: 0.0,
            yaw_rate_radps: self.yaw_rate(),
            delta_rad: self.delta,
            ..StateEstimate::zeroed()
        }
    }
}

fn to_f32(p: &Plan<f64>) -> Plan<f32> {
    let mut q = Plan::<f32>::zeroed();
    q.stamp_us = p.stamp_us;
    q.dt_s = p.dt_s as f32;
    for (a, b) in q.nodes.iter_mut().zip(p.nodes.iter()) {
        a.s_m = b.s_m as f32;
        a.x_m = b.x_m as f32;
        a.y_m = b.y_m as f32;
        a.v_mps = b.v_mps as f32;
        a.psi_rad = b.psi_rad as f32;
        a.delta_rad = b.delta_rad as f32;
    }
    for (a, b) in q.inputs.iter_mut().zip(p.inputs.iter()) {
        *a = [b[0] as f32, b[1] as f32];
    }
    q
}

fn est_f32(e: &StateEstimate<f64>) -> StateEstimate<f32> {
    StateEstimate {
        stamp_us: e.stamp_us,
        x_m: e.x_m as f32,
        y_m: e.y_m as f32,
        psi_rad: e.psi_rad as f32,
        vx_mps: e.vx_mps as f32,
        vy_mps: e.vy_mps as f32,
        yaw_rate_radps: e.yaw_rate_radps as f32,
        delta_rad: e.delta_rad as f32,
        ..StateEstimate::zeroed()
    }
}

/// Runs 20 s from an initial yaw `psi0` (rad) off the plan, the controller in
/// `f32` if `single`, else `f64`; returns (max |yaw error| after 2 s, max |speed error| after 2 s,
/// max distance to the reference path).
fn closed_loop(radius: f64, psi0: f64, single: bool) -> (f64, f64, f64) {
    let reference = Reference {
        v: 10.0,
        r: radius,
        wheelbase: 2.65,
    };
    let cfg = LowLevelConfig::<f64>::default();
    cfg.validate().unwrap();
    let mut st = LowLevelState::new();
    let cfg32 = LowLevelConfig::<f32>::default();
    let mut st32 = LowLevelState::<f32>::new();
    let mut car = Car {
        x: 0.0,
        y: 0.0,
        psi: psi0,
        v: 10.0,
        delta: reference.delta(),
        wheelbase: 2.65,
    };
    let mut plan = reference.plan(0);
    let (mut max_yaw, mut max_v, mut max_dist) = (0.0f64, 0.0f64, 0.0f64);
    for k in 0..2000u64 {
        let now = k * 10_000;
        if k % 10 == 0 {
            plan = reference.plan(now);
        }
        let a = if single {
            let a = control(
                &cfg32,
                &mut st32,
                &to_f32(&plan),
                &est_f32(&car.estimate(now)),
                now,
            )
            .unwrap();
            Actuation {
                wheel_torque_nm: a.wheel_torque_nm.map(f64::from),
                delta_rad: f64::from(a.delta_rad),
                ..Actuation::safe(0.0, 0.0)
            }
        } else {
            let a = control(&cfg, &mut st, &plan, &car.estimate(now), now).unwrap();
            assert_eq!(a.mode, Mode::Following);
            a
        };
        let t = now as f64 * 1e-6;
        let (_, _, psi_r) = reference.at(t);
        if k >= 200 {
            max_yaw = max_yaw.max(wrap_pi(car.psi - psi_r).abs());
            max_v = max_v.max((car.v - 10.0).abs());
        }
        let dist = if radius.is_infinite() {
            car.y.abs()
        } else {
            ((car.x.powi(2) + (car.y - radius).powi(2)).sqrt() - radius).abs()
        };
        max_dist = max_dist.max(dist);
        for _ in 0..10 {
            car.step(&a, 0.001);
        }
    }
    (max_yaw, max_v, max_dist)
}

#[test]
fn closed_loop_straight_line() {
    // Starts yawed 0.05 rad to the left: the yaw loop brings it back.
    for single in [false, true] {
        let (yaw, v, dist) = closed_loop(f64::INFINITY, 0.05, single);
        println!("straight (f32: {single}): yaw {yaw} rad, speed {v} m/s, distance {dist} m");
        assert!(yaw < 0.01, "yaw error {yaw}");
        assert!(v < 0.05, "speed error {v}");
        assert!(dist < 0.5, "distance {dist}");
    }
}

#[test]
fn closed_loop_constant_radius_arc() {
    for single in [false, true] {
        let (yaw, v, dist) = closed_loop(30.0, 0.0, single);
        println!("arc (f32: {single}): yaw {yaw} rad, speed {v} m/s, distance {dist} m");
        assert!(yaw < 0.02, "yaw error {yaw}");
        assert!(v < 0.1, "speed error {v}");
        assert!(dist < 1.0, "distance {dist}");
    }
}

/// A car standing (under `lateral_min_speed_mps`) with the yaw loop's output wound
/// to −0.05 rad: paused, that output is released towards 0, so the steering becomes
/// the plan's. Held, it cancelled the plan's turning of the wheels at every new plan
/// (a car standing at its steering lock never turned them back).
#[test]
fn a_paused_yaw_loop_releases_its_output_to_the_plans_steering() {
    let cfg = LowLevelConfig::<f64>::default();
    let mut st = LowLevelState::new();
    st.yaw_pid.last_output = -0.05;
    st.yaw_pid.integral = -0.05;
    let mut plan = straight_plan(0, 0.0);
    for n in plan.nodes.iter_mut() {
        n.delta_rad = 0.3;
    }
    let mut a = None;
    // 2 s: about 7 time constants of the release.
    for k in 0..200u64 {
        a = Some(control(&cfg, &mut st, &plan, &est(0.0, 0.0), k * 10_000).unwrap());
    }
    let a = a.unwrap();
    assert!(a.delta_cl_rad.abs() < 1e-3, "δ_cl = {}", a.delta_cl_rad);
    assert!((a.delta_rad - 0.3).abs() < 1e-3, "δ = {}", a.delta_rad);
    assert!(st.yaw_pid.integral.abs() < 1e-3);
}

// ---------------------------------------------------------------------------
// Each rule at its edge (the mutation pass, docs/testing.md, "Tests that notice a
// wrong line").

#[test]
fn each_setting_out_of_its_range_is_refused_with_its_reason() {
    use LowLevelConfigError as E;
    type Change = fn(&mut LowLevelConfig<f64>);
    let cases: &[(&str, Change, Result<(), E>)] = &[
        (
            "speed PID",
            |c| c.speed_pid.kp = -1.0,
            Err(E::SpeedPid(c_err())),
        ),
        (
            "wheel 0",
            |c| c.wheel_radius_m = 0.0,
            Err(E::InvalidVehicle),
        ),
        (
            "wheel ∞",
            |c| c.wheel_radius_m = f64::INFINITY,
            Err(E::InvalidVehicle),
        ),
        ("mass < 0", |c| c.mass_kg = -1500.0, Err(E::InvalidVehicle)),
        (
            "traction 0",
            |c| c.max_traction_torque_nm = 0.0,
            Err(E::InvalidTorqueLimit),
        ),
        (
            "braking 0",
            |c| c.max_braking_torque_nm = 0.0,
            Err(E::InvalidTorqueLimit),
        ),
        (
            "braking NaN",
            |c| c.max_braking_torque_nm = f64::NAN,
            Err(E::InvalidTorqueLimit),
        ),
        (
            "safe brake < 0",
            |c| c.safe_brake_torque_nm = -1.0,
            Err(E::InvalidTorqueLimit),
        ),
        (
            "safe brake ∞",
            |c| c.safe_brake_torque_nm = f64::INFINITY,
            Err(E::InvalidTorqueLimit),
        ),
        ("safe brake 0", |c| c.safe_brake_torque_nm = 0.0, Ok(())),
        (
            "front share < 0",
            |c| c.brake_front_share = -0.1,
            Err(E::InvalidTorqueLimit),
        ),
        (
            "front share > 1",
            |c| c.brake_front_share = 1.1,
            Err(E::InvalidTorqueLimit),
        ),
        ("front share 0", |c| c.brake_front_share = 0.0, Ok(())),
        ("front share 1", |c| c.brake_front_share = 1.0, Ok(())),
        (
            "steer 0",
            |c| c.steer_limit_rad = 0.0,
            Err(E::InvalidSteeringLimit),
        ),
        (
            "steer ∞",
            |c| c.steer_limit_rad = f64::INFINITY,
            Err(E::InvalidSteeringLimit),
        ),
        (
            "rate 0",
            |c| c.steer_rate_limit_radps = 0.0,
            Err(E::InvalidSteeringLimit),
        ),
        (
            "rate NaN",
            |c| c.steer_rate_limit_radps = f64::NAN,
            Err(E::InvalidSteeringLimit),
        ),
        ("rate 2", |c| c.steer_rate_limit_radps = 2.0, Ok(())),
        (
            "stop ∞",
            |c| c.stop_decel_mps2 = f64::INFINITY,
            Err(E::InvalidStopDecel),
        ),
        ("period 0", |c| c.period_s = 0.0, Err(E::InvalidTiming)),
        (
            "lateral speed < 0",
            |c| c.lateral_min_speed_mps = -0.5,
            Err(E::InvalidTiming),
        ),
        (
            "lateral speed ∞",
            |c| c.lateral_min_speed_mps = f64::INFINITY,
            Err(E::InvalidTiming),
        ),
        ("lateral speed 0", |c| c.lateral_min_speed_mps = 0.0, Ok(())),
    ];
    for (what, change, expected) in cases {
        let mut c = LowLevelConfig::<f64>::default();
        change(&mut c);
        let got = c.validate();
        match (got, expected) {
            (Err(E::SpeedPid(_)), Err(E::SpeedPid(_))) => {}
            _ => assert_eq!(got, *expected, "{what}"),
        }
    }
}

/// A PID configuration error to fill [`LowLevelConfigError::SpeedPid`] (the
/// comparison above matches the variant only).
fn c_err() -> firmware::pid::PidConfigError {
    let mut c = LowLevelConfig::<f64>::default_speed_pid();
    c.kp = -1.0;
    c.validate().unwrap_err()
}

#[test]
fn the_default_loops_have_their_documented_gains_and_windows() {
    let s = LowLevelConfig::<f64>::default_speed_pid();
    assert_eq!((s.kp, s.ki, s.kd), (900.0, 450.0, 45.0));
    assert_eq!(s.derivative_filter_s, 0.05);
    assert_eq!((s.integral_min, s.integral_max), (-3000.0, 3000.0));
    let y = LowLevelConfig::<f64>::default_yaw_pid();
    assert_eq!((y.kp, y.ki, y.kd), (1.0, 0.5, 0.02));
    assert_eq!(y.derivative_filter_s, 0.05);
    assert_eq!((y.output_min, y.output_max), (-0.3, 0.3));
    assert_eq!((y.integral_min, y.integral_max), (-0.15, 0.15));
}

#[test]
fn the_safe_actuation_reports_its_total_and_holds_a_steering_within_the_limit() {
    let a = Actuation::safe(-0.1f64, 1000.0);
    assert_eq!(a.torque_total_nm, -1000.0);
    assert_eq!(a.wheel_torque_nm.iter().sum::<f64>(), -1000.0);
    let cfg = LowLevelConfig::<f64>::default();
    let mut st = LowLevelState::new();
    st.last_delta_rad = Some(-0.2);
    assert_eq!(safe_actuation(&cfg, &st).delta_rad, -0.2);
    st.last_delta_rad = Some(-0.9);
    assert_eq!(safe_actuation(&cfg, &st).delta_rad, -0.6);
    st.last_delta_rad = Some(0.9);
    assert_eq!(safe_actuation(&cfg, &st).delta_rad, 0.6);
    // Reset: a fresh state.
    st.plans_seen = 3;
    st.reset();
    assert_eq!(st, LowLevelState::new());
}

#[test]
fn braking_is_shared_between_the_axles_as_configured() {
    let mut cfg = cfg_no_ff();
    cfg.brake_front_share = 0.7;
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &straight_plan(0, 10.0), &est(11.0, 0.0), 0).unwrap();
    let t = a.torque_total_nm;
    assert!(t < 0.0);
    let [fl, fr, rl, rr] = a.wheel_torque_nm;
    assert!((fl - 0.35 * t).abs() < 1e-9 && fl == fr, "{fl} {fr} of {t}");
    assert!((rl - 0.15 * t).abs() < 1e-9 && rl == rr, "{rl} {rr} of {t}");
}

/// A brake force distribution: each axle's braking torque shared between left
/// and right by `brake_left_share`, the four adding up to the total; the
/// driving torque stays equal on the two front wheels.
#[test]
fn braking_is_shared_between_left_and_right_as_the_car_model_says() {
    let mut cfg = cfg_no_ff();
    cfg.brake_front_share = 0.7;
    let car = CarModel {
        brake_left_share: 0.3,
        ..CarModel::configured(&cfg)
    };
    let mut st = LowLevelState::new();
    let a = control_with_model(
        &cfg,
        &mut st,
        &straight_plan(0, 10.0),
        &est(11.0, 0.0),
        0,
        &car,
    )
    .unwrap();
    let t = a.torque_total_nm;
    assert!(t < 0.0);
    let [fl, fr, rl, rr] = a.wheel_torque_nm;
    assert!((fl - 0.7 * 0.3 * t).abs() < 1e-9, "{fl} of {t}");
    assert!((fr - 0.7 * 0.7 * t).abs() < 1e-9, "{fr} of {t}");
    assert!((rl - 0.3 * 0.3 * t).abs() < 1e-9, "{rl} of {t}");
    assert!((rr - 0.3 * 0.7 * t).abs() < 1e-9, "{rr} of {t}");
    assert!((fl + fr + rl + rr - t).abs() < 1e-9);
    // Driving: the open differential's equal halves whatever the share.
    let mut st = LowLevelState::new();
    let a = control_with_model(
        &cfg,
        &mut st,
        &straight_plan(0, 10.0),
        &est(9.0, 0.0),
        0,
        &car,
    )
    .unwrap();
    let [fl, fr, rl, rr] = a.wheel_torque_nm;
    assert!(
        a.torque_total_nm > 0.0 && fl == fr && rl == 0.0 && rr == 0.0,
        "{fl} {fr}"
    );
}

/// Brakes that give 0.7 of the torque commanded: the braking feed-forward and
/// the anti-lock limit are commanded as 1/0.7 of what the car needs; driving is
/// not touched.
#[test]
fn braking_is_commanded_through_the_brakes_gain() {
    let cfg = LowLevelConfig::<f64>::default();
    let car = CarModel {
        mass_kg: 1500.0,
        braking_grip_mps2: 4.0,
        inverse_brake_gain: 1.0 / 0.7,
        ..CarModel::configured(&cfg)
    };
    let run = |accel: f64, car: &CarModel<f64>| {
        let mut plan = straight_plan(0, 10.0);
        for u in plan.inputs.iter_mut() {
            u[0] = accel;
        }
        let mut st = LowLevelState::new();
        control_with_model(&cfg, &mut st, &plan, &est(10.0, 0.0), 0, car).unwrap()
    };
    let a = run(-2.0, &car);
    assert!(
        (a.torque_ff_nm + 1500.0 * 2.0 * 0.3 / 0.7).abs() < 1e-9,
        "{}",
        a.torque_ff_nm
    );
    // At the limit: m·a_grip·r/b.
    let a = run(-6.0, &car);
    assert!(
        (a.torque_ff_nm + 1500.0 * 4.0 * 0.3 / 0.7).abs() < 1e-9,
        "{}",
        a.torque_ff_nm
    );
    // Driving as commanded.
    let a = run(1.0, &car);
    assert!(
        (a.torque_ff_nm - 1500.0 * 0.3).abs() < 1e-9,
        "{}",
        a.torque_ff_nm
    );
    // A gain that is not usable (0, NaN, negative, ∞): the configured car (its
    // mass, 1500 kg as here; no resistance), brakes as commanded.
    for bad in [0.0, f64::NAN, -2.0, f64::INFINITY] {
        let b = CarModel {
            inverse_brake_gain: bad,
            ..car
        };
        let a = run(-2.0, &b);
        assert!(
            (a.torque_ff_nm + 1500.0 * 2.0 * 0.3).abs() < 1e-9,
            "{bad}: {}",
            a.torque_ff_nm
        );
    }
}

#[test]
fn the_feedforward_holds_the_cars_model_and_the_torque_its_grip() {
    let cfg = LowLevelConfig::<f64>::default();
    let mut plan = straight_plan(0, 10.0);
    for u in plan.inputs.iter_mut() {
        u[0] = 1.0;
    }
    let car = CarModel {
        mass_kg: 1600.0,
        resistance_n: 200.0,
        drag_n_per_mps2: 0.5,
        traction_grip_mps2: f64::INFINITY,
        braking_grip_mps2: f64::INFINITY,
        inverse_brake_gain: 1.0,
        brake_left_share: 0.5,
        hold_steering: false,
    };
    // On the planned speed: (m·a + F₀ + c₂·V²)·r.
    let mut st = LowLevelState::new();
    let a = control_with_model(&cfg, &mut st, &plan, &est(10.0, 0.0), 0, &car).unwrap();
    let expected = (1600.0 * 1.0 + 200.0 + 0.5 * 100.0) * 0.3;
    assert!(
        (a.torque_ff_nm - expected).abs() < 1e-9,
        "{}",
        a.torque_ff_nm
    );
    assert!((a.torque_total_nm - expected).abs() < 1e-9);
    // A car model that is not usable: the configured car, no resistance.
    for bad in [
        CarModel {
            mass_kg: 0.0,
            ..car
        },
        CarModel {
            mass_kg: -1600.0,
            ..car
        },
        CarModel {
            mass_kg: f64::NAN,
            ..car
        },
        CarModel {
            resistance_n: f64::INFINITY,
            ..car
        },
        CarModel {
            drag_n_per_mps2: f64::NAN,
            ..car
        },
    ] {
        let mut st = LowLevelState::new();
        let a = control_with_model(&cfg, &mut st, &plan, &est(10.0, 0.0), 0, &bad).unwrap();
        assert!(
            (a.torque_ff_nm - 1500.0 * 0.3).abs() < 1e-9,
            "{bad:?}: {}",
            a.torque_ff_nm
        );
    }
    // Traction within the grip: (m·a_grip + F₀ + c₂·V²)·r at most, a negative
    // resistance (downhill) not counted.
    let grip = CarModel {
        traction_grip_mps2: 2.0,
        ..car
    };
    let mut st = LowLevelState::new();
    let a = control_with_model(&cfg, &mut st, &plan, &est(5.0, 0.0), 0, &grip).unwrap();
    let t_grip = (1600.0 * 2.0 + 200.0 + 0.5 * 25.0) * 0.3;
    assert!(
        (a.torque_total_nm - t_grip).abs() < 1e-9,
        "{}",
        a.torque_total_nm
    );
    assert_eq!(a.wheel_torque_nm[0], a.torque_total_nm / 2.0);
    let downhill = CarModel {
        resistance_n: -300.0,
        drag_n_per_mps2: 0.0,
        ..grip
    };
    let mut st = LowLevelState::new();
    let a = control_with_model(&cfg, &mut st, &plan, &est(5.0, 0.0), 0, &downhill).unwrap();
    assert!((a.torque_total_nm - 1600.0 * 2.0 * 0.3).abs() < 1e-9);
    // Braking within the grip: m·a_grip·r at most (the feed-forward too).
    let abs = CarModel {
        braking_grip_mps2: 3.0,
        ..car
    };
    let mut st = LowLevelState::new();
    let a = control_with_model(&cfg, &mut st, &plan, &est(20.0, 0.0), 0, &abs).unwrap();
    assert!(
        (a.torque_total_nm + 1600.0 * 3.0 * 0.3).abs() < 1e-9,
        "{}",
        a.torque_total_nm
    );
    let mut brake_plan = plan;
    for u in brake_plan.inputs.iter_mut() {
        u[0] = -5.0;
    }
    let mut st = LowLevelState::new();
    let a = control_with_model(&cfg, &mut st, &brake_plan, &est(10.0, 0.0), 0, &abs).unwrap();
    assert!(
        (a.torque_ff_nm + 1600.0 * 3.0 * 0.3).abs() < 1e-9,
        "{}",
        a.torque_ff_nm
    );
}

#[test]
fn the_pid_time_step_is_the_measured_one_within_ten_periods() {
    // The speed loop alone (no feed-forward), 1 m/s too slow; the same PID run
    // by hand with the steps the controller should use: the first call and any
    // step over 10 periods (or not forward) take the nominal period.
    let cfg = cfg_no_ff();
    let plan = straight_plan(0, 10.0);
    let mut st = LowLevelState::new();
    let mut ps = PidState::new();
    for (now, dt) in [
        (0, 0.01),
        (20_000, 0.02),
        (120_000, 0.1),
        (320_000, 0.01),
        (320_000, 0.01),
        (300_000, 0.01),
    ] {
        let a = control(&cfg, &mut st, &plan, &est(9.0, 0.0), now).unwrap();
        let u = pid::update(&cfg.speed_pid, &mut ps, 10.0, 9.0, dt).unwrap();
        assert!(
            (a.torque_total_nm - u).abs() < 1e-9,
            "at {now}: {} vs {u}",
            a.torque_total_nm
        );
    }
}

#[test]
fn modes_change_at_the_plans_ends_exactly() {
    // A plan of 16 steps of 0.25 s (exact in binary): T_H = 4 s.
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(0, 3.0);
    plan.dt_s = 0.25;
    for (now, mode) in [
        (3_750_000, Mode::Following),
        (3_750_001, Mode::Extrapolating),
        (4_000_000, Mode::Extrapolating),
        (4_000_001, Mode::Stopping),
    ] {
        let mut st = LowLevelState::new();
        let a = control(&cfg, &mut st, &plan, &est(3.0, 0.0), now).unwrap();
        assert_eq!(a.mode, mode, "at {now} µs");
    }
    // At the plan's stamp the age is +0, not −0.
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(3.0, 0.0), 0).unwrap();
    assert!(a.plan_age_s == 0.0 && a.plan_age_s.is_sign_positive());
}

#[test]
fn the_controlled_stop_ends_with_no_acceleration_asked() {
    // 3 m/s at the end of a 4 s plan, stopping at 3 m/s²: at rest 1 s later
    // exactly; from then on the feed-forward asks nothing, and the yaw
    // reference stays where the stop ended (ψ_N + ψ̇_N·V_N/(2·a)).
    let cfg = LowLevelConfig::<f64>::default();
    let mut plan = straight_plan(0, 3.0);
    plan.dt_s = 0.25;
    for (k, n) in plan.nodes.iter_mut().enumerate() {
        n.psi_rad = 0.025 * k as f64;
    }
    let psi_n = 0.025 * HORIZON as f64;
    let yaw_rate = 0.025 / 0.25;
    for now in [5_000_000, 6_000_000] {
        let mut st = LowLevelState::new();
        let a = control(&cfg, &mut st, &plan, &est(0.0, psi_n), now).unwrap();
        assert_eq!(a.v_ref_mps, 0.0);
        assert_eq!(a.torque_ff_nm, 0.0, "at {now} µs");
        let psi_end = psi_n + yaw_rate * 3.0 / (2.0 * 3.0);
        assert!((a.psi_ref_rad - psi_end).abs() < 1e-12, "{}", a.psi_ref_rad);
    }
    // Half-way through the stop (0.5 s): V^r = 1.5, −3 m/s² asked, and the yaw
    // reference one step (0.25 s) ahead, 0.75 s into the stop, has turned for
    // ∫V^r/V_N = 0.75 − 3·0.75²/(2·3) s.
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(1.5, psi_n), 4_500_000).unwrap();
    assert_eq!(a.v_ref_mps, 1.5);
    assert!((a.torque_ff_nm + 1500.0 * 3.0 * 0.3).abs() < 1e-9);
    let t_eff = 0.75 - 3.0 * 0.75 * 0.75 / (2.0 * 3.0);
    assert!((a.psi_ref_rad - (psi_n + yaw_rate * t_eff)).abs() < 1e-12);
}

#[test]
fn the_yaw_reference_is_interpolated_one_step_ahead() {
    // ψ^r rising 0.1 rad per node: at t = 0.05 s the reference one step (0.2 s)
    // ahead is at node 1.25: 0.125 rad. The car on it, yawing with it
    // (0.5 rad/s): no error.
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(0, 10.0);
    for (k, n) in plan.nodes.iter_mut().enumerate() {
        n.psi_rad = 0.1 * k as f64;
    }
    let mut st = LowLevelState::new();
    let mut e = est(10.0, 0.025);
    e.yaw_rate_radps = 0.5;
    e.stamp_us = 50_000;
    let a = control(&cfg, &mut st, &plan, &e, 50_000).unwrap();
    assert!((a.psi_ref_rad - 0.125).abs() < 1e-12, "{}", a.psi_ref_rad);
    assert!(a.yaw_error_rad.abs() < 1e-12, "{}", a.yaw_error_rad);
}

#[test]
fn a_late_estimates_heading_is_projected_over_its_age() {
    // ψ^r rising 0.1 rad per node (0.5 rad/s). At t = 0.15 s the car's estimate
    // is 100 ms old (stamped 0.05 s, on the plan then: 0.025 rad, yawing at
    // 0.5 rad/s): projected over its age and one plan step (0.3 s), it is on the
    // reference one step ahead (node 1.75, 0.175 rad): no error. Read as if
    // measured now, it would be 0.05 rad behind and steer the car off its plan.
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(0, 10.0);
    for (k, n) in plan.nodes.iter_mut().enumerate() {
        n.psi_rad = 0.1 * k as f64;
    }
    let mut e = est(10.0, 0.025);
    e.yaw_rate_radps = 0.5;
    e.stamp_us = 50_000;
    let a = control(&cfg, &mut LowLevelState::new(), &plan, &e, 150_000).unwrap();
    assert!((a.psi_ref_rad - 0.175).abs() < 1e-12, "{}", a.psi_ref_rad);
    assert!(a.yaw_error_rad.abs() < 1e-12, "{}", a.yaw_error_rad);
    // An estimate older than MAX_PROJECTED_AGE_S is projected over that much only:
    // stamped 0.5 s before t = 0.6 s, on the plan then (0.25 rad), it lands
    // 0.5 rad/s × (0.3 + 0.2 s) later, against the reference at node 4 (0.4 rad).
    let mut e = est(10.0, 0.25);
    e.yaw_rate_radps = 0.5;
    e.stamp_us = 100_000;
    let a = control(&cfg, &mut LowLevelState::new(), &plan, &e, 600_000).unwrap();
    let projected = 0.25 + 0.5 * (f64::from(low_level::MAX_PROJECTED_AGE_S) + 0.2);
    assert!(
        (a.yaw_error_rad - (projected - 0.4)).abs() < 1e-6,
        "{}",
        a.yaw_error_rad
    );
    // A stamp after `now` (clocks out of step) is an age of 0.
    let mut e = est(10.0, 0.025);
    e.yaw_rate_radps = 0.5;
    e.stamp_us = 90_000;
    let a = control(&cfg, &mut LowLevelState::new(), &plan, &e, 50_000).unwrap();
    assert!(a.yaw_error_rad.abs() < 1e-12, "{}", a.yaw_error_rad);
}

#[test]
fn the_steering_rate_limit_holds_both_ways_from_a_command_within_the_limit() {
    let mut cfg = cfg_no_ff();
    cfg.steer_rate_limit_radps = 1.0;
    let mut plan = straight_plan(0, 10.0);
    for n in plan.nodes.iter_mut() {
        n.delta_rad = -0.4;
    }
    let mut st = LowLevelState::new();
    st.last_delta_rad = Some(0.0);
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 0).unwrap();
    assert!((a.delta_rad + 0.01).abs() < 1e-12, "{}", a.delta_rad);
    // A last command beyond the mechanical limit counts as the limit.
    let mut st = LowLevelState::new();
    st.last_delta_rad = Some(0.9);
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 0).unwrap();
    assert!((a.delta_rad - 0.59).abs() < 1e-12, "{}", a.delta_rad);
    assert!((a.delta_cl_rad - (0.59 + 0.4)).abs() < 1e-12);
}

#[test]
fn a_wrapped_yaw_estimate_gives_no_derivative_kick() {
    // The car on a plan heading 3.1 rad; its estimate wraps from 3.1 to
    // 3.1 − 2π between two calls (the same heading): the yaw loop's output
    // stays where it was (no error), with no derivative spike.
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(0, 10.0);
    for n in plan.nodes.iter_mut() {
        n.psi_rad = 3.1;
    }
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 3.1), 0).unwrap();
    assert!(a.delta_cl_rad.abs() < 1e-12);
    let wrapped = 3.1 - 2.0 * std::f64::consts::PI;
    let a = control(&cfg, &mut st, &plan, &est(10.0, wrapped), 10_000).unwrap();
    assert!(a.yaw_error_rad.abs() < 1e-12);
    assert!(a.delta_cl_rad.abs() < 1e-9, "δ_cl = {}", a.delta_cl_rad);
    // A genuine yaw step (0.05 rad) keeps its derivative: the D term acts.
    let mut st = LowLevelState::new();
    control(&cfg, &mut st, &plan, &est(10.0, 3.1), 0).unwrap();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 3.05), 10_000).unwrap();
    let p_and_i = 0.05 + 0.5 * 0.05 * 0.01;
    assert!(a.delta_cl_rad > p_and_i + 1e-3, "δ_cl = {}", a.delta_cl_rad);
}

#[test]
fn a_paused_yaw_loop_releases_with_its_time_constant() {
    // Below the lateral speed: δ_cl and the integrator decay by 1/(1 + Δt/τ)
    // per call, τ = 0.3 s (the implicit Euler step).
    let cfg = LowLevelConfig::<f64>::default();
    let mut st = LowLevelState::new();
    st.yaw_pid.last_output = -0.05;
    st.yaw_pid.integral = -0.04;
    let plan = straight_plan(0, 0.0);
    let a = control(&cfg, &mut st, &plan, &est(0.4, 0.0), 0).unwrap();
    let keep = 1.0 / (1.0 + 0.01 / 0.3);
    assert!(
        (a.delta_cl_rad + 0.05 * keep).abs() < 1e-9,
        "{}",
        a.delta_cl_rad
    );
    assert!((st.yaw_pid.integral + 0.04 * keep).abs() < 1e-9);
    // At the lateral speed (0.5 m/s) the loop runs.
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(0.5, -0.1), 0).unwrap();
    assert!(a.delta_cl_rad > 0.09, "{}", a.delta_cl_rad);
}

#[test]
fn a_plan_of_large_finite_numbers_is_accepted() {
    // Finite is all the check asks: a node and an input beyond the two the
    // controller reads at t = 0 hold 1e200 in every number (their sum is
    // finite, their products would not be).
    let cfg = cfg_no_ff();
    let mut plan = straight_plan(0, 10.0);
    let n = &mut plan.nodes[10];
    n.s_m = 1e200;
    n.x_m = 1e200;
    n.y_m = 1e200;
    n.v_mps = 1e200;
    n.psi_rad = 1e200;
    n.delta_rad = 1e200;
    plan.inputs[10] = [1e200, 1e200];
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 0).unwrap();
    assert_eq!(a.v_ref_mps, 10.0);
}

#[test]
fn the_measured_speed_is_the_velocitys_norm_with_the_sign_of_its_forward_part() {
    let cfg = cfg_no_ff();
    let plan = straight_plan(0, 10.0);
    for (vx, vy, v) in [
        (3.0, 4.0, 5.0),
        (-3.0, 4.0, -5.0),
        (0.0, 2.0, 2.0),
        (-0.0, -2.0, 2.0),
    ] {
        let mut st = LowLevelState::new();
        let e = StateEstimate {
            vy_mps: vy,
            ..est(vx, 0.0)
        };
        let a = control(&cfg, &mut st, &plan, &e, 0).unwrap();
        assert_eq!(a.v_mps, v, "({vx}, {vy})");
    }
}

#[test]
fn the_speed_loop_brakes_within_what_the_feedforward_leaves() -> Result<(), ControlFault> {
    // Accelerating plan (2 m/s²: T_ff = 1500·2·0.3 = 900 N·m) with the car
    // 15 m/s too fast: the PID asks for more than the brakes give; the total is
    // the braking limit, T_ff included (the PID's window is −4500 − 900).
    let cfg = LowLevelConfig::<f64>::default();
    let mut plan = straight_plan(0, 10.0);
    for u in plan.inputs.iter_mut() {
        *u = [2.0, 0.0];
    }
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(25.0, 0.0), 0)?;
    assert!((a.torque_ff_nm - 900.0).abs() < 1e-9, "{}", a.torque_ff_nm);
    assert_eq!(a.torque_total_nm, -cfg.max_braking_torque_nm);
    assert!((sum(&a) + cfg.max_braking_torque_nm).abs() < 1e-9);
    Ok(())
}

#[test]
fn the_yaw_loop_steers_within_what_the_open_loop_steering_leaves() -> Result<(), ControlFault> {
    // The plan steers 0.5 rad; the car is yawed 1 rad left of it: the yaw loop
    // asks for its limit, −0.3 rad (within the window −0.6 − 0.5), and the
    // steering is 0.5 − 0.3 = 0.2 rad.
    let cfg = LowLevelConfig::<f64>::default();
    let mut plan = straight_plan(0, 10.0);
    for n in plan.nodes.iter_mut() {
        n.delta_rad = 0.5;
    }
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 1.0), 0)?;
    assert_eq!(a.delta_ol_rad, 0.5);
    assert!(
        (a.delta_cl_rad + 0.3).abs() < 1e-12,
        "δ_cl = {}",
        a.delta_cl_rad
    );
    assert!((a.delta_rad - 0.2).abs() < 1e-12, "δ = {}", a.delta_rad);
    Ok(())
}

#[test]
fn a_plan_of_finite_numbers_is_accepted_whatever_their_signs() -> Result<(), ControlFault> {
    // Every number finite, two of them ±1e308 in one node (or input) beyond
    // the ones read at t = 0: finite is all the check asks, whichever two.
    let cfg = cfg_no_ff();
    for field in 1..6 {
        let mut plan = straight_plan(0, 10.0);
        plan.nodes[10].s_m = 1e308;
        *node_field(&mut plan.nodes[10], field) = -1e308;
        let mut st = LowLevelState::new();
        let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 0)?;
        assert_eq!(a.v_ref_mps, 10.0, "field {field}");
    }
    let mut plan = straight_plan(0, 10.0);
    plan.inputs[10] = [1e308, -1e308];
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &plan, &est(10.0, 0.0), 0)?;
    assert_eq!(a.v_ref_mps, 10.0);
    Ok(())
}

#[test]
fn wrap_pi_leaves_an_angle_within_pi_unchanged_to_the_bit() {
    // (−π, π] is its own wrap: no rounding from adding and removing 2π.
    let pi = std::f64::consts::PI;
    for x in [0.0, 1e-10, 1e-3, 0.1, -0.1, 0.3, 0.7, 1.1, -3.0, 3.0, pi] {
        assert_eq!(wrap_pi(x), x, "{x}");
    }
}

#[test]
fn a_finite_car_model_is_used_however_large_its_numbers() -> Result<(), ControlFault> {
    // Finite mass and resistance, far beyond any car: the feed-forward is the
    // model's, at the torque limits (the configured car's would be 0 here, on
    // a plan of constant speed followed at that speed).
    let cfg = LowLevelConfig::<f64>::default();
    let plan = straight_plan(0, 10.0);
    for (mass_kg, resistance_n, ff) in [
        (1e200, 1e200, cfg.max_traction_torque_nm),
        (1e308, -1e308, -cfg.max_braking_torque_nm),
    ] {
        let car = CarModel {
            mass_kg,
            resistance_n,
            ..CarModel::configured(&cfg)
        };
        let mut st = LowLevelState::new();
        let a = control_with_model(&cfg, &mut st, &plan, &est(10.0, 0.0), 0, &car)?;
        assert_eq!(a.torque_ff_nm, ff, "({mass_kg}, {resistance_n})");
    }
    Ok(())
}

#[test]
fn a_yaw_jump_of_exactly_pi_keeps_the_derivative() -> Result<(), ControlFault> {
    // Only a jump by more than π is taken for a wrapped estimate. The loop last
    // saw a yaw of 0; the car now reads π, the plan's heading: no error, and
    // the jump's derivative (0.02·(π/0.01)/6 ≈ 1 rad) steers to the loop's
    // limit, −0.3 rad.
    let cfg = cfg_no_ff();
    let pi = std::f64::consts::PI;
    let mut plan = straight_plan(0, 10.0);
    for n in plan.nodes.iter_mut() {
        n.psi_rad = pi;
    }
    let mut st = LowLevelState::new();
    st.yaw_pid.initialised = true;
    st.yaw_pid.prev_measurement = 0.0;
    let a = control(&cfg, &mut st, &plan, &est(10.0, pi), 0)?;
    assert_eq!(a.yaw_error_rad, 0.0);
    assert!(
        (a.delta_cl_rad + 0.3).abs() < 1e-12,
        "δ_cl = {}",
        a.delta_cl_rad
    );
    Ok(())
}

/// A held steering turns no further from straight ahead than the last command,
/// on either side, and may turn back; without the hold the same plan steers
/// further.
#[test]
fn a_held_steering_turns_no_further_but_may_turn_back() {
    let cfg = LowLevelConfig::<f64>::default();
    let held = CarModel {
        hold_steering: true,
        ..CarModel::configured(&cfg)
    };
    let free = CarModel::configured(&cfg);
    let steer = |delta_plan: f64, last: f64, car: &CarModel<f64>| {
        let mut plan = straight_plan(0, 10.0);
        for n in plan.nodes.iter_mut() {
            n.delta_rad = delta_plan;
        }
        let mut st = LowLevelState::new();
        st.last_delta_rad = Some(last);
        control_with_model(&cfg, &mut st, &plan, &est(10.0, 0.0), 0, car)
            .unwrap()
            .delta_rad
    };
    for side in [1.0, -1.0] {
        let further = steer(0.3 * side, 0.2 * side, &held);
        assert_eq!(further, 0.2 * side, "held at the last command");
        assert!(
            steer(0.3 * side, 0.2 * side, &free).abs() > 0.2,
            "free: further"
        );
        let back = steer(0.05 * side, 0.2 * side, &held);
        assert!(back.abs() < 0.2 && back * side > 0.0, "back: {back}");
    }
    // Straight ahead, held: either way is further, so it stays straight.
    assert_eq!(steer(0.3, 0.0, &held), 0.0);
}

proptest::proptest! {
    /// Whatever the plan asks and the car does, a held steering's command is no
    /// further from straight ahead than the last one, and any command stays
    /// within the lock and the rate limit of one period.
    #[test]
    fn the_steering_command_keeps_its_hold_lock_and_rate(
        last in -0.6f64..0.6,
        delta_plan in -0.6f64..0.6,
        rate in -2.0f64..2.0,
        v in 0.0f64..30.0,
        yaw_rate in -1.0f64..1.0,
        psi in -3.0f64..3.0,
        held: bool,
    ) {
        let cfg = LowLevelConfig::<f64>::default();
        let car = CarModel {
            hold_steering: held,
            ..CarModel::configured(&cfg)
        };
        let mut plan = straight_plan(0, v);
        for n in plan.nodes.iter_mut() {
            n.delta_rad = delta_plan;
        }
        for u in plan.inputs.iter_mut() {
            u[1] = rate;
        }
        let mut st = LowLevelState::new();
        st.last_delta_rad = Some(last);
        let e = StateEstimate {
            yaw_rate_radps: yaw_rate,
            ..est(v, psi)
        };
        let d = control_with_model(&cfg, &mut st, &plan, &e, 0, &car)
            .unwrap()
            .delta_rad;
        let step = cfg.steer_rate_limit_radps * cfg.period_s;
        proptest::prop_assert!(d.abs() <= cfg.steer_limit_rad);
        proptest::prop_assert!((d - last).abs() <= step + 1e-12, "{d} from {last}");
        if held {
            proptest::prop_assert!(d.abs() <= last.abs(), "{d} held at {last}");
        }
    }
}

#[test]
fn a_plan_that_stands_holds_the_brakes_on_a_standing_car() {
    let cfg = LowLevelConfig::<f64>::default();
    let still = f64::from(firmware::low_level::STANDSTILL_MPS);
    let plan = straight_plan(0, 0.0);
    // Standing, and the estimate's noise round 0 of either sign: the hold's
    // torque, whatever the speed loop would have asked.
    for v in [0.0, 0.3, -0.3, 0.99 * still] {
        let mut st = LowLevelState::new();
        let a = control(&cfg, &mut st, &plan, &est(v, 0.0), 0).unwrap();
        assert!(
            (a.torque_total_nm + cfg.safe_brake_torque_nm).abs() < 1e-9,
            "{v} m/s: {}",
            a.torque_total_nm
        );
        assert!(a.wheel_torque_nm.iter().all(|&t| t < 0.0), "{v} m/s");
        assert_eq!(st.speed_pid.integral, 0.0, "the speed loop starts afresh");
    }
    // Moving (or measured moving), or a plan that moves off: the speed loop.
    for (v_plan, v) in [
        (0.0, 1.05 * still),
        (0.0, -1.05 * still),
        (1.0, 0.0),
        (5.0, 5.0),
    ] {
        let mut st = LowLevelState::new();
        let a = control(&cfg, &mut st, &straight_plan(0, v_plan), &est(v, 0.0), 0).unwrap();
        assert!(
            (a.torque_total_nm + cfg.safe_brake_torque_nm).abs() > 1.0,
            "plan {v_plan} m/s, car {v} m/s: {}",
            a.torque_total_nm
        );
    }
    // A plan that stands now and moves within a plan step releases the brakes.
    let mut moving_off = straight_plan(0, 0.0);
    for n in moving_off.nodes.iter_mut().skip(1) {
        n.v_mps = 2.0;
    }
    let mut st = LowLevelState::new();
    let a = control(&cfg, &mut st, &moving_off, &est(0.0, 0.0), 0).unwrap();
    assert!(a.torque_total_nm >= 0.0, "{}", a.torque_total_nm);
}
