//! Tests of the PID controller (`firmware::pid`).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::pid::{
    preset_output, step, update, update_within, AntiWindup, PidConfig, PidConfigError, PidError,
    PidState,
};

const DT: f64 = 0.01;

/// First-order plant `τ·ẏ = −y + b·u`, integrated exactly over one step.
struct FirstOrder {
    y: f64,
    tau: f64,
    b: f64,
    /// Constant disturbance added to the input.
    dist: f64,
}

impl FirstOrder {
    fn step(&mut self, u: f64, dt: f64) {
        let a = (-dt / self.tau).exp();
        self.y = a * self.y + (1.0 - a) * self.b * (u + self.dist);
    }
}

fn pi_cfg() -> PidConfig<f64> {
    let mut c = PidConfig::new(2.0, 4.0, 0.0, DT);
    c.output_min = -10.0;
    c.output_max = 10.0;
    c
}

#[test]
fn step_response_converges_with_zero_steady_state_error() {
    let cfg = pi_cfg();
    cfg.validate().unwrap();
    let mut st = PidState::new();
    // Gain b = 0.5 and a disturbance: a P controller alone would leave an offset.
    let mut plant = FirstOrder {
        y: 0.0,
        tau: 0.5,
        b: 0.5,
        dist: -1.0,
    };
    let r = 1.0;
    for _ in 0..2000 {
        let u = step(&cfg, &mut st, r, plant.y).unwrap();
        plant.step(u, DT);
    }
    assert!((plant.y - r).abs() < 1e-6, "y = {}", plant.y);
    // The integrator carries the steady-state input u = r/b − dist = 3.
    assert!((st.integral - 3.0).abs() < 1e-4, "I = {}", st.integral);

    // Same loop without integrator: an offset remains.
    let mut p_only = cfg;
    p_only.ki = 0.0;
    let mut st = PidState::new();
    plant.y = 0.0;
    for _ in 0..2000 {
        let u = step(&p_only, &mut st, r, plant.y).unwrap();
        plant.step(u, DT);
    }
    assert!((plant.y - r).abs() > 0.1, "P only: y = {}", plant.y);
}

#[test]
fn sign_convention_is_the_papers() {
    // e = y − r > 0 (measurement above setpoint) → negative output.
    let cfg = PidConfig::new(3.0, 0.0, 0.0, DT);
    let mut st = PidState::new();
    let u = update(&cfg, &mut st, 1.0, 1.5, DT).unwrap();
    assert_eq!(u, -1.5);
    let mut st = PidState::new();
    let u = update(&cfg, &mut st, 1.0, 0.5, DT).unwrap();
    assert_eq!(u, 1.5);
}

/// Runs `n` steps of a saturating loop against a plant that cannot follow (the
/// error keeps its sign), then flips the setpoint and counts the steps until the
/// output leaves the upper limit.
fn steps_to_leave_saturation(anti_windup: AntiWindup<f64>) -> usize {
    let mut cfg = pi_cfg();
    cfg.anti_windup = anti_windup;
    cfg.validate().unwrap();
    let mut st = PidState::new();
    // Setpoint far above what the plant reaches with |u| ≤ 10 (y → 5).
    let mut plant = FirstOrder {
        y: 0.0,
        tau: 0.5,
        b: 0.5,
        dist: 0.0,
    };
    for _ in 0..1000 {
        let u = step(&cfg, &mut st, 20.0, plant.y).unwrap();
        plant.step(u, DT);
    }
    assert_eq!(st.output(), 10.0, "saturated high");
    // Error changes sign: setpoint now below the measurement.
    for k in 0..100_000 {
        let u = step(&cfg, &mut st, 0.0, plant.y).unwrap();
        plant.step(u, DT);
        if u < 10.0 {
            return k;
        }
    }
    usize::MAX
}

#[test]
fn anti_windup_leaves_saturation_promptly() {
    let cond = steps_to_leave_saturation(AntiWindup::Conditional);
    let back = steps_to_leave_saturation(AntiWindup::BackCalculation {
        tracking_time_s: 0.25,
    });
    let none = steps_to_leave_saturation(AntiWindup::None);
    assert!(cond <= 1, "conditional: {cond} steps");
    assert!(back <= 5, "back-calculation: {back} steps");
    // Without anti-windup the integrator wound up to ~ 4·15·10 s and needs
    // seconds to unwind.
    assert!(none > 100, "no anti-windup: {none} steps");
}

#[test]
fn conditional_integration_still_integrates_back_out_of_saturation() {
    // Saturated high with a positive error step: the integrator must be allowed
    // to decrease (the step moves the output back into range).
    let mut cfg = pi_cfg();
    cfg.kp = 0.0;
    let mut st = PidState {
        integral: 12.0,
        ..PidState::new()
    };
    let u = update(&cfg, &mut st, 0.0, 1.0, DT).unwrap();
    assert_eq!(u, 10.0);
    assert!((st.integral - (12.0 - 4.0 * DT)).abs() < 1e-12);
    // And not allowed to grow further.
    let mut st = PidState {
        integral: 12.0,
        ..PidState::new()
    };
    update(&cfg, &mut st, 1.0, 0.0, DT).unwrap();
    assert_eq!(st.integral, 12.0);
}

#[test]
fn integrator_limits_hold() {
    let mut cfg = pi_cfg();
    cfg.anti_windup = AntiWindup::None;
    cfg.integral_min = -2.0;
    cfg.integral_max = 2.0;
    let mut st = PidState::new();
    for _ in 0..1000 {
        update(&cfg, &mut st, 5.0, 0.0, DT).unwrap();
    }
    assert_eq!(st.integral, 2.0);
}

#[test]
fn derivative_on_measurement_has_no_setpoint_kick() {
    let cfg = PidConfig::new(0.0, 0.0, 1.0, DT);
    let mut st = PidState::new();
    for _ in 0..10 {
        assert_eq!(update(&cfg, &mut st, 0.0, 2.0, DT).unwrap(), 0.0);
    }
    // Setpoint step: measurement unchanged → no derivative output.
    assert_eq!(update(&cfg, &mut st, 5.0, 2.0, DT).unwrap(), 0.0);
    // Measurement ramp of 3 /s → D = −K_D·3.
    let u = update(&cfg, &mut st, 5.0, 2.0 + 3.0 * DT, DT).unwrap();
    assert!((u + 3.0).abs() < 1e-9, "u = {u}");
}

#[test]
fn first_update_has_no_derivative_kick() {
    let cfg = PidConfig::new(0.0, 0.0, 10.0, DT);
    let mut st = PidState::new();
    assert_eq!(update(&cfg, &mut st, 0.0, 100.0, DT).unwrap(), 0.0);
    st.forget_derivative();
    assert_eq!(update(&cfg, &mut st, 0.0, -50.0, DT).unwrap(), 0.0);
}

#[test]
fn derivative_filter_is_first_order() {
    let tf = 0.1;
    let mut cfg = PidConfig::new(0.0, 0.0, 1.0, DT);
    cfg.derivative_filter_s = tf;
    let mut st = PidState::new();
    update(&cfg, &mut st, 0.0, 0.0, DT).unwrap();
    // Measurement ramp of slope 1: the raw derivative steps to 1, the filtered one
    // follows 1 − (T_f/(T_f+Δt))^k.
    let alpha = DT / (tf + DT);
    for k in 1..=50 {
        let u = update(&cfg, &mut st, 0.0, k as f64 * DT, DT).unwrap();
        let expected = -(1.0 - (1.0 - alpha).powi(k));
        assert!((u - expected).abs() < 1e-9, "k = {k}: {u} vs {expected}");
    }
    // After one time constant, about 63 % (backward Euler: 1 − (1/1.1)^10 ≈ 0.614).
    let mut st2 = PidState::new();
    update(&cfg, &mut st2, 0.0, 0.0, DT).unwrap();
    let mut u = 0.0;
    for k in 1..=10 {
        u = update(&cfg, &mut st2, 0.0, k as f64 * DT, DT).unwrap();
    }
    assert!(-u > 0.58 && -u < 0.66, "u = {u}");
}

#[test]
fn non_finite_inputs_leave_state_unchanged() {
    let mut cfg = pi_cfg();
    cfg.kd = 0.5;
    cfg.derivative_filter_s = 0.05;
    let mut st = PidState::new();
    for k in 0..20 {
        update(&cfg, &mut st, 1.0, 0.1 * k as f64, DT).unwrap();
    }
    let before = st;
    for (r, y, dt) in [
        (f64::NAN, 0.0, DT),
        (0.0, f64::NAN, DT),
        (f64::INFINITY, 0.0, DT),
        (0.0, f64::NEG_INFINITY, DT),
    ] {
        assert_eq!(
            update(&cfg, &mut st, r, y, dt),
            Err(PidError::NonFiniteInput)
        );
        assert_eq!(st, before);
    }
    for dt in [0.0, -0.01, f64::NAN, f64::INFINITY] {
        assert_eq!(
            update(&cfg, &mut st, 1.0, 0.0, dt),
            Err(PidError::InvalidTimeStep)
        );
        assert_eq!(st, before);
    }
    assert_eq!(
        update_within(&cfg, &mut st, 1.0, 0.0, DT, 1.0, -1.0),
        Err(PidError::InvalidLimits)
    );
    assert_eq!(st, before);
    assert_eq!(st.output(), before.last_output);
}

#[test]
fn reset_and_bumpless_preset() {
    let mut cfg = pi_cfg();
    cfg.kd = 0.1;
    let mut st = PidState::new();
    for _ in 0..50 {
        update(&cfg, &mut st, 1.0, 0.0, DT).unwrap();
    }
    assert_ne!(st, PidState::new());
    st.reset();
    assert_eq!(st, PidState::new());

    // Hand over from a manual command of 4.2 with the error at 0.5.
    let u0 = preset_output(&cfg, &mut st, 1.0, 0.5, 4.2).unwrap();
    assert!((u0 - 4.2).abs() < 1e-12);
    // The first update at the same error and measurement continues from 4.2 (plus
    // one integration step), without a bump.
    let u1 = update(&cfg, &mut st, 1.0, 0.5, DT).unwrap();
    assert!((u1 - (4.2 + 4.0 * 0.5 * DT)).abs() < 1e-9, "u1 = {u1}");
}

#[test]
fn update_within_narrows_the_output_and_stops_windup() {
    let cfg = pi_cfg();
    let mut st = PidState::new();
    for _ in 0..500 {
        let u = update_within(&cfg, &mut st, 1.0, 0.0, DT, -1.0, 0.5).unwrap();
        assert!(u <= 0.5);
    }
    // P = 2 alone is beyond 0.5: conditional integration never let I grow.
    assert_eq!(st.integral, 0.0);
    // Disjoint ranges: the window's bound nearest the configuration's range.
    let u = update_within(&cfg, &mut st, 1.0, 0.0, DT, 20.0, 30.0).unwrap();
    assert_eq!(u, 20.0);
}

#[test]
fn config_validation() {
    let good = pi_cfg();
    assert_eq!(good.validate(), Ok(()));
    let mut c = good;
    c.kp = -1.0;
    assert_eq!(c.validate(), Err(PidConfigError::InvalidGain));
    c = good;
    c.ki = f64::NAN;
    assert_eq!(c.validate(), Err(PidConfigError::InvalidGain));
    c = good;
    c.kd = f64::INFINITY;
    assert_eq!(c.validate(), Err(PidConfigError::InvalidGain));
    c = good;
    c.derivative_filter_s = -0.1;
    assert_eq!(c.validate(), Err(PidConfigError::InvalidFilterTime));
    c = good;
    c.output_min = 1.0;
    c.output_max = -1.0;
    assert_eq!(c.validate(), Err(PidConfigError::InvalidOutputLimits));
    c = good;
    c.output_max = f64::NAN;
    assert_eq!(c.validate(), Err(PidConfigError::InvalidOutputLimits));
    c = good;
    c.integral_min = 3.0;
    c.integral_max = 2.0;
    assert_eq!(c.validate(), Err(PidConfigError::InvalidIntegralLimits));
    c = good;
    c.anti_windup = AntiWindup::BackCalculation {
        tracking_time_s: 0.0,
    };
    assert_eq!(c.validate(), Err(PidConfigError::InvalidTrackingTime));
    c = good;
    c.sample_time_s = 0.0;
    assert_eq!(c.validate(), Err(PidConfigError::InvalidSampleTime));
    // Infinite limits are allowed (no limit).
    assert_eq!(PidConfig::new(1.0f32, 0.0, 0.0, 0.01).validate(), Ok(()));
}

#[test]
fn f32_and_f64_agree() {
    let c64 = pi_cfg();
    let mut c32 = PidConfig::new(2.0f32, 4.0, 0.0, 0.01);
    c32.output_min = -10.0;
    c32.output_max = 10.0;
    let (mut s32, mut s64) = (PidState::new(), PidState::new());
    let (mut y32, mut y64) = (0.0f32, 0.0f64);
    for _ in 0..300 {
        let u32_ = step(&c32, &mut s32, 1.0, y32).unwrap();
        let u64_ = step(&c64, &mut s64, 1.0, y64).unwrap();
        y32 += 0.01 * (-y32 + 0.5 * u32_);
        y64 += 0.01 * (-y64 + 0.5 * u64_);
    }
    assert!((y32 as f64 - y64).abs() < 1e-4);
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    fn any_mode() -> impl Strategy<Value = AntiWindup<f64>> {
        prop_oneof![
            Just(AntiWindup::None),
            Just(AntiWindup::Conditional),
            (0.01f64..2.0).prop_map(|t| AntiWindup::BackCalculation { tracking_time_s: t }),
        ]
    }

    proptest! {
        // Fixed seed: the test is deterministic; nothing written to disk.
        #![proptest_config(ProptestConfig {
            rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed_2018),
            failure_persistence: None,
            cases: 256,
            ..ProptestConfig::default()
        })]
        /// Whatever the finite inputs: the output stays within its limits, the
        /// integrator within its own, and with conditional integration the
        /// integrator never moves further in the direction of a saturation.
        #[test]
        fn output_and_integrator_stay_bounded(
            kp in 0.0f64..50.0, ki in 0.0f64..50.0, kd in 0.0f64..5.0, tf in 0.0f64..0.5,
            mode in any_mode(),
            steps in prop::collection::vec((-100.0f64..100.0, -100.0f64..100.0, 1e-4f64..0.1), 1..200),
        ) {
            let mut cfg = PidConfig::new(kp, ki, kd, 0.01);
            cfg.derivative_filter_s = tf;
            cfg.output_min = -5.0;
            cfg.output_max = 7.0;
            cfg.integral_min = -3.0;
            cfg.integral_max = 4.0;
            cfg.anti_windup = mode;
            prop_assert!(cfg.validate().is_ok());
            let mut st = PidState::new();
            for (r, y, dt) in steps {
                let before = st.integral;
                let u = update(&cfg, &mut st, r, y, dt).unwrap();
                prop_assert!((-5.0..=7.0).contains(&u));
                prop_assert!((-3.0..=4.0).contains(&st.integral));
                if mode == AntiWindup::Conditional {
                    if u == 7.0 && y < r {
                        prop_assert!(st.integral <= before);
                    }
                    if u == -5.0 && y > r {
                        prop_assert!(st.integral >= before);
                    }
                }
            }
        }
    }
}

/// One update with back-calculation, counted by hand in binary fractions (exact
/// in f64): the integrator takes `di` plus the saturation excess over `T_t`.
#[test]
fn back_calculation_feeds_back_the_saturation_excess() {
    let mut cfg = PidConfig::new(2.0, 4.0, 0.0, 0.5);
    cfg.output_min = -1.0;
    cfg.output_max = 1.0;
    cfg.integral_min = -100.0;
    cfg.integral_max = 100.0;
    cfg.anti_windup = AntiWindup::BackCalculation {
        tracking_time_s: 0.25,
    };
    let mut st = PidState::new();
    // e = measurement − setpoint = −1: p = 2, di = −ki·e·dt = 2, u_unsat = 2
    // (the integral before the update is 0), u_sat = 1, excess −1 over
    // T_t = 0.25 for dt = 0.5: −2. The integral: 0 + 2 − 2 = 0.
    let u = update(&cfg, &mut st, 1.0, 0.0, 0.5).unwrap();
    assert_eq!(st.integral, 0.0);
    assert_eq!(u, 1.0);
    // Again from an integral of 0.5: u_unsat = 2.5, excess −1.5 · 2 = −3, so the
    // integral is 0.5 + 2 − 3 = −0.5, and u = clamp(2 − 0.5) = 1.
    st.integral = 0.5;
    let u = update(&cfg, &mut st, 1.0, 0.0, 0.5).unwrap();
    assert_eq!(st.integral, -0.5);
    assert_eq!(u, 1.0);
    // Inside the limits there is no excess: the plain integral step.
    st.integral = -1.5;
    let u = update(&cfg, &mut st, 1.0, 0.75, 0.5).unwrap();
    // e = −0.25: p = 0.5, di = 0.5, u_unsat = 0.5 − 1.5 = −1 (at the limit, no
    // excess): integral −1.0, u = 0.5 − 1.0 = −0.5.
    assert_eq!(st.integral, -1.0);
    assert_eq!(u, -0.5);
}

/// The preset accounts for the derivative term the controller holds: with a
/// filtered derivative of the measurement in the state, the integral is
/// `output − p − d`, and the output returned is the one asked for.
#[test]
fn preset_output_subtracts_the_proportional_and_derivative_terms() {
    let mut cfg = PidConfig::new(2.0, 4.0, 0.5, 0.25);
    cfg.output_min = -10.0;
    cfg.output_max = 10.0;
    cfg.integral_min = -10.0;
    cfg.integral_max = 10.0;
    let mut st = PidState::new();
    // Two updates give the state a derivative: measurement 0 then 1 over 0.25 s,
    // unfiltered: 4 per s.
    update(&cfg, &mut st, 0.0, 0.0, 0.25).unwrap();
    update(&cfg, &mut st, 0.0, 1.0, 0.25).unwrap();
    assert_eq!(st.derivative, 4.0);
    // p = −2·(1 − 3) = 4, d = −0.5·4 = −2: the integral for an output of 3 is
    // 3 − 4 + 2 = 1.
    let u = preset_output(&cfg, &mut st, 3.0, 1.0, 3.0).unwrap();
    assert_eq!(st.integral, 1.0);
    assert_eq!(u, 3.0);
    assert_eq!(st.output(), 3.0);
    // An output the integrator limits cannot reach: clamped there, and the output
    // returned is what the state gives.
    let u = preset_output(&cfg, &mut st, 3.0, 1.0, 20.0).unwrap();
    assert_eq!(st.integral, 10.0);
    assert_eq!(u, 10.0);
}

/// Conditional integration at exactly the limit: an output that lands on the
/// limit (not beyond it) still integrates; one step beyond does not.
#[test]
fn conditional_integration_stops_only_beyond_the_limit() {
    let mut cfg = PidConfig::new(2.0, 1.0, 0.0, 0.25);
    cfg.output_min = -1.0;
    cfg.output_max = 1.0;
    cfg.integral_min = -10.0;
    cfg.integral_max = 10.0;
    // Upper: e = −0.25 → p = 0.5, di = −ki·e·dt = 0.0625; from 0.4375 the
    // unsaturated output is 0.5 + 0.5 = 1.0, exactly the limit: integrates.
    let mut st = PidState::new();
    st.integral = 0.4375;
    let u = update(&cfg, &mut st, 1.0, 0.75, 0.25).unwrap();
    assert_eq!(st.integral, 0.5);
    assert_eq!(u, 1.0);
    // From 0.5 the same step would reach 1.0625: held.
    update(&cfg, &mut st, 1.0, 0.75, 0.25).unwrap();
    assert_eq!(st.integral, 0.5);
    // Lower, mirrored.
    let mut st = PidState::new();
    st.integral = -0.4375;
    let u = update(&cfg, &mut st, -1.0, -0.75, 0.25).unwrap();
    assert_eq!(st.integral, -0.5);
    assert_eq!(u, -1.0);
    update(&cfg, &mut st, -1.0, -0.75, 0.25).unwrap();
    assert_eq!(st.integral, -0.5);
}

/// Back-calculation with a derivative term: the unsaturated output includes it.
#[test]
fn back_calculation_counts_the_derivative_in_the_excess() {
    let mut cfg = PidConfig::new(0.0, 0.0, 0.5, 0.5);
    cfg.output_min = -1.0;
    cfg.output_max = 1.0;
    cfg.integral_min = -100.0;
    cfg.integral_max = 100.0;
    cfg.anti_windup = AntiWindup::BackCalculation {
        tracking_time_s: 0.5,
    };
    let mut st = PidState::new();
    update(&cfg, &mut st, 0.0, 0.0, 0.5).unwrap();
    // The measurement falls by 4 in 0.5 s: derivative −8, d = −kd·(−8) = 4;
    // u_unsat = 0 + 0 + 4 = 4, u_sat = 1, excess −3 · dt/T_t (1): integral −3.
    let u = update(&cfg, &mut st, 0.0, -4.0, 0.5).unwrap();
    assert_eq!(st.derivative, -8.0);
    assert_eq!(st.integral, -3.0);
    assert_eq!(u, 1.0);
}

/// A derivative that overflows while the clamped output stays finite is still a
/// refused output, and the state is left as it was.
#[test]
fn an_infinite_derivative_behind_a_finite_output_is_refused() {
    let mut cfg = PidConfig::new(0.0, 0.0, 1.0, 1.0);
    cfg.output_min = -1.0;
    cfg.output_max = 1.0;
    let mut st = PidState::new();
    update(&cfg, &mut st, 0.0, 0.0, 1.0).unwrap();
    let before = st;
    // (f64::MAX − 0) / 1e-300 overflows: d = −∞, the output clamps to −1.
    assert_eq!(
        update(&cfg, &mut st, 0.0, f64::MAX, 1e-300),
        Err(PidError::NonFiniteOutput)
    );
    assert_eq!(st, before);
}

/// Each of the preset's inputs is checked on its own.
#[test]
fn preset_refuses_each_non_finite_input() {
    let cfg = pi_cfg();
    let mut st = PidState::new();
    let before = st;
    for (s, m, o) in [
        (f64::NAN, 0.0, 1.0),
        (0.0, f64::INFINITY, 1.0),
        (0.0, 0.0, f64::NEG_INFINITY),
    ] {
        assert_eq!(
            preset_output(&cfg, &mut st, s, m, o),
            Err(PidError::NonFiniteInput),
            "{s} {m} {o}"
        );
        assert_eq!(st, before);
    }
}

/// A preset whose proportional term overflows: the integral clamps to its limit
/// (finite), the output does not (no output limits): refused, state unchanged.
#[test]
fn preset_refuses_an_infinite_output_behind_a_finite_integral() {
    let mut cfg = PidConfig::new(2.0, 1.0, 0.0, 0.01);
    cfg.integral_min = -10.0;
    cfg.integral_max = 10.0;
    assert_eq!(cfg.output_max, f64::INFINITY);
    let mut st = PidState::new();
    let before = st;
    // e = MAX − (−MAX) overflows: p = −∞, the integral clamps to 10, u = −∞.
    assert_eq!(
        preset_output(&cfg, &mut st, -f64::MAX, f64::MAX, 0.0),
        Err(PidError::NonFiniteOutput)
    );
    assert_eq!(st, before);
}
