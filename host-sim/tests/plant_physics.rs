//! The plant at the limit: physics checks that a wrong force or a wrong moment
//! would fail (friction limit on a steady circle, momentum and energy balances,
//! rest, wheel lift).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::closed_loop::validity::{sweep_radius, StopCause, ValidityConfig};
use host_sim::model::plant::{Inputs, Plant, State, FL, FR, RL, RR};
use host_sim::model::tire::{self, TireParams};
use host_sim::model::vehicle::{VehicleParams, G};
use indicatif::ProgressBar;

/// The light car of issue 8: 1,090 kg, 2.58 m wheelbase, centre of gravity 0.57 m
/// high, a tyre of peak lateral friction 1.05 whatever the load and without the
/// book tyre's ply-steer offset (so that 1.05 is the whole lateral grip).
fn light_car() -> VehicleParams {
    let d = VehicleParams::default();
    VehicleParams {
        mass_kg: 1090.0,
        ix_kg_m2: 380.0,
        iy_kg_m2: 1500.0,
        iz_kg_m2: 1700.0,
        lf_m: 1.03,
        lr_m: 1.55,
        lw_m: 0.72,
        h_m: 0.57,
        ks_n_per_m: 25000.0,
        ds_n_s_per_m: 2200.0,
        tyre: TireParams {
            fnomin: 2700.0,
            pdy1: -1.05,
            pdy2: 0.0,
            pvy1: 0.0,
            pvy2: 0.0,
            ..d.tyre
        },
        ..d
    }
}

/// Largest lateral force the tyre can make at load `fz_n` (N) and friction `mu`, N:
/// the peak of its pure-slip curve over slip angles of both signs, sampled finely.
fn peak_lateral_force_n(tyre: &TireParams, fz_n: f64, mu: f64) -> f64 {
    (-2000..=2000)
        .map(|k| {
            let alpha = k as f64 * 0.5e-3; // ±1 rad
            tire::pure_slip_forces(0.0, alpha, fz_n, mu, tyre).1.abs()
        })
        .fold(0.0, f64::max)
}

/// The lateral acceleration the tyres' peak friction allows, m/s²: four tyres at a
/// quarter of the weight each. The peak force is concave in the load for these tyres,
/// so any load transfer can only lower the sum (Jensen): an upper bound.
fn friction_limit_mps2(p: &VehicleParams, mu: f64) -> f64 {
    let quarter = p.mass_kg * G / 4.0;
    4.0 * peak_lateral_force_n(&p.tyre, quarter, mu) / p.mass_kg
}

#[test]
fn a_steady_circle_never_holds_more_than_the_tyres_friction() {
    let cars = [
        ("default", VehicleParams::default()),
        ("light", light_car()),
    ];
    for ((name, p), mu) in cars.iter().flat_map(|c| [(c, 1.0), (c, 0.5)]) {
        let limit = friction_limit_mps2(p, mu);
        let cfg = ValidityConfig {
            mu,
            ..ValidityConfig::default()
        };
        let s = sweep_radius(p, 10.0, &cfg, &ProgressBar::hidden()).unwrap();
        let top = s.points.last().expect("steady points");
        println!(
            "{name} mu {mu}: limit {limit:.3} m/s2, highest steady {:.3} m/s2, {}",
            top.ay_mps2, s.stop_reason
        );
        for q in &s.points {
            assert!(
                q.ay_mps2 <= 1.01 * limit,
                "{name} mu {mu}: steady a_y {:.3} m/s2 at {:.2} m/s over the friction limit {limit:.3}",
                q.ay_mps2,
                q.speed_mps
            );
        }
        // Not vacuous: the sweep went most of the way to the limit.
        assert!(
            top.ay_mps2 > 0.75 * limit,
            "{name} mu {mu}: {}",
            top.ay_mps2
        );
        assert!(
            s.stop_reason.contains("could not hold"),
            "{}",
            s.stop_reason
        );
        assert_ne!(s.stop_cause, StopCause::AboveLimit);
    }
}

/// Longitudinal momentum of the car with its wheels' spin, `M·V_x + Σ I_r·ω_i/r`,
/// N·s: with no drag, no torque and the wheels straight, only the `M·ψ̇·V_y` term can
/// change it, and with `V_y = ψ̇ = 0` it is a linear invariant RK4 keeps exactly.
fn momentum(p: &VehicleParams, s: &State) -> f64 {
    p.mass_kg * s.vx_mps + s.omega_radps.iter().sum::<f64>() * p.wheel_inertia_kg_m2 / p.r_eff_m
}

#[test]
fn a_pitching_car_coasting_keeps_its_momentum() {
    let p = VehicleParams {
        cx: 0.0,
        ..VehicleParams::default()
    };
    let mut s0 = State::at_speed(20.0, &p);
    s0.pitch_rad = 0.03;
    s0.pitch_rate_radps = -0.2;
    let mut plant = Plant::new(p, s0).unwrap();
    let p0 = momentum(&p, &s0);
    let mut max_pitch = 0.0_f64;
    for _ in 0..3000 {
        plant.step(&Inputs::default(), 1.0).unwrap();
        let s = plant.state();
        max_pitch = max_pitch.max(s.pitch_rad.abs());
        assert!(s.vy_mps == 0.0 && s.yaw_rate_radps == 0.0, "{s:?}");
        let dp = momentum(&p, s) - p0;
        assert!(dp.abs() < 1e-9 * p0, "momentum changed by {dp} N·s");
    }
    assert!(max_pitch > 0.02, "the body did pitch");
}

/// Kinetic energy of the car, its body's roll and pitch and its wheels, J.
fn kinetic(p: &VehicleParams, s: &State) -> f64 {
    0.5 * p.mass_kg * (s.vx_mps.powi(2) + s.vy_mps.powi(2))
        + 0.5 * p.iz_kg_m2 * s.yaw_rate_radps.powi(2)
        + 0.5 * p.ix_kg_m2 * s.roll_rate_radps.powi(2)
        + 0.5 * p.iy_kg_m2 * s.pitch_rate_radps.powi(2)
        + 0.5 * p.wheel_inertia_kg_m2 * s.omega_radps.iter().map(|w| w * w).sum::<f64>()
}

/// Potential energy of the suspension, J: each corner's spring pushes with
/// `max(0, F_z0,i − k_s·ζ)`, so its energy is `−∫₀^ζ max(0, F_z0,i − k_s·z) dz`;
/// plus that of the plant's (analytically zero) static pitch moment correction.
fn potential(p: &VehicleParams, s: &State) -> f64 {
    let fz0 = p.static_loads_n();
    let pitch_static = p.lr_m * (fz0[RL] + fz0[RR]) - p.lf_m * (fz0[FL] + fz0[FR]);
    let x = [p.lf_m, p.lf_m, -p.lr_m, -p.lr_m];
    let side = [1.0, -1.0, 1.0, -1.0];
    (0..4)
        .map(|i| {
            let zeta = side[i] * p.lw_m * s.roll_rad.sin() - x[i] * s.pitch_rad.sin();
            let z_free = fz0[i] / p.ks_n_per_m;
            let z = zeta.min(z_free);
            -(fz0[i] * z - 0.5 * p.ks_n_per_m * z * z)
        })
        .sum::<f64>()
        + pitch_static * s.pitch_rad.sin()
}

fn energy(p: &VehicleParams, s: &State) -> f64 {
    kinetic(p, s) + potential(p, s)
}

#[test]
fn a_free_roll_oscillation_loses_energy_and_never_gains_it() {
    for (name, p) in [
        ("default", VehicleParams::default()),
        ("light", light_car()),
    ] {
        // Small (springs only) and large (the inner wheels lift off the road).
        for roll in [0.05, 0.25] {
            let mut s0 = State::at_rest();
            s0.roll_rad = roll;
            s0.pitch_rad = 0.2 * roll;
            let mut plant = Plant::new(p, s0).unwrap();
            let e0 = energy(&p, &s0);
            assert!(e0 > 0.0);
            let mut e_prev = e0;
            for k in 0..5000 {
                plant.step(&Inputs::default(), 1.0).unwrap();
                let s = plant.state();
                let e = energy(&p, s);
                assert!(
                    e <= e_prev + 1e-9 * e0,
                    "{name} roll {roll}: energy rose from {e_prev} to {e} J at step {k}"
                );
                e_prev = e;
                // No tyre force at rest: the body's motion never moves the car.
                assert!(s.x_m == 0.0 && s.y_m == 0.0 && s.psi_rad == 0.0, "{s:?}");
                assert!(plant.outputs().fz_n.iter().all(|f| *f >= 0.0));
            }
            assert!(
                e_prev < 0.01 * e0,
                "{name} roll {roll}: {e_prev} of {e0} J left"
            );
            let lift = plant.wheel_lift();
            if roll > 0.1 {
                assert!(lift.count >= 1, "{name}: {lift:?}");
                assert_eq!(lift.first_lift_s, Some(0.0), "{name}: {lift:?}");
                assert!(
                    lift.lifted_s > 0.0 && lift.lifted_s < 1.0,
                    "{name}: {lift:?}"
                );
            } else {
                assert_eq!(lift.count, 0, "{name}: {lift:?}");
                assert_eq!(lift.first_lift_s, None);
            }
        }
    }
}

#[test]
fn coasting_with_a_rolling_and_pitching_body_never_gains_energy() {
    // A tyre without the Magic Formula's offsets (conicity, ply steer): its forces
    // always oppose the slip, so the only energy source is gone.
    let d = VehicleParams::default();
    let p = VehicleParams {
        tyre: TireParams {
            phx1: 0.0,
            phx2: 0.0,
            pvx1: 0.0,
            pvx2: 0.0,
            phy1: 0.0,
            phy2: 0.0,
            pvy1: 0.0,
            pvy2: 0.0,
            rvy1: 0.0,
            rvy2: 0.0,
            ..d.tyre
        },
        ..d
    };
    let mut s0 = State::at_speed(20.0, &p);
    s0.roll_rad = 0.04;
    s0.pitch_rad = 0.02;
    let mut plant = Plant::new(p, s0).unwrap();
    let e0 = energy(&p, &s0);
    let mut e_prev = e0;
    for k in 0..4000 {
        plant.step(&Inputs::default(), 1.0).unwrap();
        let e = energy(&p, plant.state());
        assert!(
            e <= e_prev + 1e-9 * e0,
            "energy rose from {e_prev} to {e} J at step {k}"
        );
        e_prev = e;
        // Straight ahead: no lateral force from the roll.
        assert!(
            plant.outputs().ay_mps2.abs() < 1e-3,
            "{:?}",
            plant.outputs()
        );
    }
    // The drag took some.
    assert!(e_prev < e0);
}

#[test]
fn cars_at_rest_on_flat_ground_stay_exactly_at_rest() {
    for p in [VehicleParams::default(), light_car()] {
        for mu in [1.0, 0.5] {
            let mut plant = Plant::new(p, State::at_rest()).unwrap();
            for _ in 0..5000 {
                plant.step(&Inputs::default(), mu).unwrap();
            }
            assert_eq!(*plant.state(), State::at_rest());
            let o = plant.outputs();
            assert_eq!((o.ax_mps2, o.ay_mps2), (0.0, 0.0));
            assert_eq!(o.fz_n, p.static_loads_n());
            assert_eq!(o.wheel_lifted, [false; 4]);
            assert_eq!(plant.wheel_lift().count, 0);
        }
    }
}

#[test]
#[allow(clippy::needless_range_loop)] // four wheels, several arrays indexed alike
fn a_turn_too_hard_for_the_light_car_lifts_its_inner_wheels_and_says_so() {
    // A step steer at speed: the roll overshoot unloads the inner (left) wheels.
    let p = light_car();
    let mut plant = Plant::new(p, State::at_speed(18.0, &p)).unwrap();
    let steer = Inputs {
        torque_nm: [0.0; 4],
        delta_rad: -0.25,
    };
    let mut seen = [false; 4];
    let mut first = None;
    for k in 0..1500 {
        plant.step(&steer, 1.0).unwrap();
        let o = plant.outputs();
        assert!(o.fz_n.iter().all(|f| *f >= 0.0), "{:?}", o.fz_n);
        for i in 0..4 {
            if o.wheel_lifted[i] {
                assert_eq!(o.fz_n[i], 0.0);
                assert_eq!((o.fxp_n[i], o.fyp_n[i]), (0.0, 0.0));
                seen[i] = true;
                first.get_or_insert(k);
            }
        }
    }
    // Turning right, the body rolls left side down: the inner (right) wheels lift,
    // never the outer ones.
    assert!(seen[FR] || seen[RR], "{seen:?}");
    assert!(!seen[FL] && !seen[RL], "{seen:?}");
    let lift = plant.wheel_lift();
    assert!(lift.count >= 1 && lift.lifted_s > 0.0, "{lift:?}");
    let t_first = lift.first_lift_s.unwrap();
    assert!(t_first <= (first.unwrap() + 1) as f64 * plant.dt_s() + 1e-12);
}

/// A 3 s manoeuvre through every term of the plant (drive, brake, steer, roll, pitch,
/// combined slip, μ = 0.8): the state at its end.
fn reference_manoeuvre() -> State {
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_speed(12.0, &p)).unwrap();
    for k in 0..3000 {
        let t = k as f64 * 1e-3;
        let inputs = Inputs {
            torque_nm: [300.0 * (t * 2.0).sin(), 250.0, -100.0 * t, 40.0],
            delta_rad: 0.1 * (t * 3.0).sin(),
        };
        plant.step(&inputs, 0.8).unwrap();
    }
    *plant.state()
}

/// The plant's speed-ups are exact rewrites (shared trigonometry, terms computed once
/// per step or per evaluation, skipped multiplications by an exact zero): they may
/// only reassociate floating-point operations. The end state of the reference
/// manoeuvre, recorded before them, must stay equal to a relative 1e-9 (the
/// manoeuvre's sensitivity turns reassociation's 1e-16 into at most about 1e-12).
#[test]
fn the_reference_manoeuvre_ends_where_it_did_before_the_speed_ups() {
    let s = reference_manoeuvre();
    let got = s.to_array();
    let want: [f64; 14] = REFERENCE;
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= 1e-9 * w.abs().max(1e-3),
            "state[{i}] = {g:e}, recorded {w:e}: {got:?}"
        );
    }
}
/// The end state of [`reference_manoeuvre`] (the order of the plant's state array),
/// recorded with the plant of the commit that introduced this test.
const REFERENCE: [f64; 14] = [
    37.39289128544387,
    6.321510323339639,
    0.43183672293787,
    12.291657045861031,
    -0.7411573280964131,
    0.6165255330607569,
    0.05636760503971652,
    -0.019742707662494814,
    0.0014949694152180905,
    -0.005885907039664485,
    39.22041163746656,
    42.89142691685032,
    34.28719104119795,
    42.78993574468062,
];
