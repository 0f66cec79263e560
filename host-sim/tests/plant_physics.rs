//! The plant at the limit: physics checks that a wrong force or a wrong moment
//! would fail (friction limit on a steady circle, momentum and energy balances,
//! rest, wheel lift, the road's grade, drag and rolling resistance against hand
//! calculations, the actuators' step responses against their closed form).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::closed_loop::validity::{sweep_radius, StopCause, ValidityConfig};
use host_sim::model::actuator::ActuatorParams;
use host_sim::model::plant::{Inputs, Plant, RoadUnder, State, FL, FR, RL, RR};
use host_sim::model::tire::{self, TireParams};
use host_sim::model::vehicle::{VehicleParams, G};
use indicatif::ProgressBar;

/// A light car: 1,090 kg, 2.58 m wheelbase, centre of gravity 0.57 m
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
        crr: 0.0,
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
    // always oppose the slip, so the only energy source is gone. Without rolling
    // resistance: the rolled body's left and right wheels would resist unequally and
    // turn the car (a lateral force the check below would count).
    let d = VehicleParams::default();
    let p = VehicleParams {
        crr: 0.0,
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
/// combined slip, μ = 0.8) on the level, without rolling resistance (the plant the
/// state was recorded with had none): the state at its end.
fn reference_manoeuvre() -> State {
    let p = VehicleParams {
        crr: 0.0,
        ..VehicleParams::default()
    };
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

/// A shipped vehicle file.
fn shipped(name: &str) -> VehicleParams {
    let p = format!("{}/vehicles/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    VehicleParams::from_toml_file(&p).unwrap_or_else(|e| panic!("{p}: {e}"))
}

/// The grade angle of a grade of `percent` %, rad.
fn grade_rad(percent: f64) -> f64 {
    (percent / 100.0).atan()
}

/// Mass plus the four wheels' spin inertia seen at the road, kg: what a force along
/// the road accelerates when the wheels roll without slipping more.
fn rolling_mass_kg(p: &VehicleParams) -> f64 {
    p.mass_kg + 4.0 * p.wheel_inertia_kg_m2 / p.r_eff_m.powi(2)
}

/// Coasts straight at `v0` m/s on a road of grade `percent` % for `settle_s`, then
/// returns the mean deceleration over the next 0.1 s (m/s², positive slowing) and
/// the speed at its middle (m/s), with the outputs there.
fn coasting_deceleration(
    p: &VehicleParams,
    v0: f64,
    percent: f64,
    settle_s: f64,
) -> (f64, f64, host_sim::model::plant::Outputs) {
    let mut plant = Plant::new(*p, State::at_speed(v0, p)).unwrap();
    let road = RoadUnder {
        mu: [1.0; 4],
        grade_rad: grade_rad(percent),
    };
    let steps = |plant: &mut Plant, n: usize| {
        for _ in 0..n {
            plant.step_on_road(&Inputs::default(), &road).unwrap();
        }
    };
    steps(&mut plant, (settle_s * 1e3) as usize);
    let v_a = plant.state().vx_mps;
    steps(&mut plant, 50);
    let (v_mid, out) = (plant.state().vx_mps, plant.outputs());
    steps(&mut plant, 50);
    let v_b = plant.state().vx_mps;
    ((v_a - v_b) / 0.1, v_mid, out)
}

/// By hand: a car coasting at `v` m/s on a grade of `percent` % slows by gravity's
/// component along the road, the rolling resistance of its weight's normal
/// component and the drag, over its mass and its wheels' inertia, m/s².
fn coasting_by_hand(p: &VehicleParams, v: f64, percent: f64) -> f64 {
    let g = grade_rad(percent);
    let weight = p.mass_kg * G;
    let drag = 0.5 * p.rho_air_kg_per_m3 * p.cx * p.frontal_area_m2 * v * v;
    (weight * g.sin() + p.crr * weight * g.cos() + drag) / rolling_mass_kg(p)
}

#[test]
fn a_car_coasting_up_or_down_a_6_percent_grade_slows_by_gravity_and_its_resistances() {
    for name in ["default", "light", "heavy"] {
        let p = shipped(name);
        for percent in [6.0, 0.0, -6.0] {
            let (decel, v, _) = coasting_deceleration(&p, 20.0, percent, 1.0);
            let want = coasting_by_hand(&p, v, percent);
            assert!(
                (decel - want).abs() < 0.005 * want.abs().max(1.0),
                "{name} at {percent} %: slows by {decel} m/s², by hand {want} m/s²"
            );
        }
        // Uphill slows by about g·sin γ more than the level (a third of what a
        // missing gravity term or rolling resistance would change).
        let up = coasting_deceleration(&p, 20.0, 6.0, 1.0).0;
        let level = coasting_deceleration(&p, 20.0, 0.0, 1.0).0;
        let gravity = G * grade_rad(6.0).sin() * p.mass_kg / rolling_mass_kg(&p);
        assert!(
            ((up - level) - gravity).abs() < 0.02,
            "{name}: {up} vs {level}"
        );
    }
}

#[test]
fn drag_and_rolling_resistance_are_the_vehicle_files_against_hand_calculations() {
    // The heavy car's numbers, typed from its file: C_x 0.33, S 2.85 m², ρ 1.225
    // kg/m³, C_rr 0.012, 2,250 kg.
    let p = shipped("heavy");
    let (_, _, o) = coasting_deceleration(&p, 25.0, 0.0, 0.5);
    let v = o.speed_mps;
    let drag = 0.5 * 1.225 * 0.33 * 2.85 * v * v;
    assert!(
        (o.aero_drag_n - drag).abs() < 1e-9 * drag,
        "{} vs {drag}",
        o.aero_drag_n
    );
    for i in 0..4 {
        let rr = 0.012 * o.fz_n[i];
        assert!(
            (o.rolling_resistance_n[i] - rr).abs() < 1e-9 * rr,
            "wheel {i}: {} N vs {rr} N",
            o.rolling_resistance_n[i]
        );
    }
    let total: f64 = o.rolling_resistance_n.iter().sum();
    let weight_rr = 0.012 * 2250.0 * G;
    assert!(
        (total - weight_rr).abs() < 0.005 * weight_rr,
        "{total} N vs {weight_rr} N"
    );
    // At steady rolling the tyres push back with it: their longitudinal forces sum
    // to the rolling resistance plus what spins the wheels down.
    let fx: f64 = o.fxp_n.iter().sum();
    let spin_down = 4.0 * p.wheel_inertia_kg_m2 / p.r_eff_m.powi(2) * o.ax_mps2;
    assert!(
        (fx + total + spin_down).abs() < 0.01 * total,
        "tyres {fx} N, rolling resistance {total} N, spin-down {spin_down} N"
    );
}

#[test]
fn a_car_at_rest_on_a_grade_without_torque_rolls_back() {
    let p = VehicleParams::default();
    for percent in [6.0, -6.0] {
        let mut plant = Plant::new(p, State::at_rest()).unwrap();
        let road = RoadUnder {
            mu: [1.0; 4],
            grade_rad: grade_rad(percent),
        };
        // Distance rolled along the road (trapezoids of the speed at each step).
        let mut along_m = 0.0;
        for _ in 0..3000 {
            let v0 = plant.state().vx_mps;
            plant.step_on_road(&Inputs::default(), &road).unwrap();
            along_m += 0.5 * (v0 + plant.state().vx_mps) * plant.dt_s();
        }
        let s = *plant.state();
        // Over the ground it moved the road's distance times cos γ.
        let g = grade_rad(percent);
        assert!(
            (s.x_m - along_m * g.cos()).abs() < 1e-5 * along_m.abs(),
            "{} m over the ground for {along_m} m along the road",
            s.x_m
        );
        // Down the slope: backwards on an uphill grade, forwards on a downhill one,
        // at the rate gravity less the rolling resistance gives (from 0.2 m/s, the
        // speed under which the resistance fades, on).
        let a = (G * g.sin().abs() - p.crr * G * g.cos()) * p.mass_kg / rolling_mass_kg(&p);
        let want = -percent.signum() * a * 3.0;
        assert!(
            (s.vx_mps - want).abs() < 0.05 * want.abs(),
            "{percent} %: {} m/s after 3 s, by hand {want} m/s",
            s.vx_mps
        );
        assert!(s.x_m * percent < 0.0, "{s:?}");
    }
}

#[test]
fn a_car_held_on_its_brakes_on_a_grade_loads_its_rear_axle_and_its_accelerometer_reads_g_sin() {
    let p = VehicleParams::default();
    let g = grade_rad(6.0);
    let mut plant = Plant::new(p, State::at_rest()).unwrap();
    let road = RoadUnder {
        mu: [1.0; 4],
        grade_rad: g,
    };
    let hold = Inputs {
        torque_nm: [-2000.0; 4],
        delta_rad: 0.0,
    };
    for _ in 0..4000 {
        plant.step_on_road(&hold, &road).unwrap();
    }
    let o = plant.outputs();
    // Held: (nearly) no acceleration, so the accelerometer reads gravity's
    // component along the road.
    assert!(o.ax_mps2.abs() < 1e-3, "{}", o.ax_mps2);
    assert!(
        (o.specific_force_x_mps2 - G * g.sin()).abs() < 1e-3,
        "{}",
        o.specific_force_x_mps2
    );
    // The loads carry the weight's normal component, and the tyres' pull up the
    // slope at ground level, `M·g·sin γ` at `h` under the centre of gravity, moves
    // load from the front axle to the rear one until the loads' moment balances it
    // (how it splits between the axles is the suspension's: the model has no heave).
    let fz = o.fz_n;
    let weight = p.mass_kg * G;
    let pull = weight * g.sin() * p.h_m;
    let l = p.lf_m + p.lr_m;
    // The body pitches by `φ` with `2·k_s·(l_f² + l_r²)·sin φ·cos φ` = the pull's
    // moment; the axles' springs then carry `2·k_s·(l_r − l_f)·sin φ` more than the
    // weight's normal component (no heave degree of freedom).
    let sin_phi = plant.state().pitch_rad.sin();
    let lever = p.lf_m.powi(2) + p.lr_m.powi(2);
    assert!(
        (-2.0 * p.ks_n_per_m * lever * sin_phi * plant.state().pitch_rad.cos() - pull).abs()
            < 1e-3 * pull,
        "pitch {} rad",
        plant.state().pitch_rad
    );
    let heave = -2.0 * p.ks_n_per_m * (p.lr_m - p.lf_m) * sin_phi;
    let sum: f64 = fz.iter().sum();
    assert!(
        (sum - weight * g.cos() - heave).abs() < 1e-4 * weight,
        "loads {fz:?}: {sum} N against {} N",
        weight * g.cos() + heave
    );
    let front = fz[FL] + fz[FR] - weight * g.cos() * p.lr_m / l;
    let rear = fz[RL] + fz[RR] - weight * g.cos() * p.lf_m / l;
    assert!(front < 0.0 && rear > 0.0, "front {front} N, rear {rear} N");
    let moment = p.lr_m * rear - p.lf_m * front;
    assert!(
        (moment - pull).abs() < 0.02 * pull,
        "the loads' moment {moment} N·m against the pull's {pull} N·m"
    );
}

/// The closed form of a rate-limited first-order lag behind a pure delay (see
/// `host_sim::model::actuator`): its output at `t` (s) for a step of `a` at 0.
fn lagged_step(a: f64, tau_s: f64, delay_s: f64, rate: f64, t: f64) -> f64 {
    if t < delay_s {
        return 0.0;
    }
    let (sign, a) = (a.signum(), a.abs());
    if a <= rate * tau_s {
        return sign * a * (1.0 - (-(t - delay_s) / tau_s).exp());
    }
    let t1 = delay_s + (a - rate * tau_s) / rate;
    sign * if t < t1 {
        rate * (t - delay_s)
    } else {
        a - rate * tau_s * (-(t - t1) / tau_s).exp()
    }
}

#[test]
fn the_actuators_step_responses_are_a_delay_a_lag_and_a_rate_limit() {
    // Steering: 0.25 rad asked with 80 ms of lag, 20 ms of delay and 0.5 rad/s at
    // most (a ramp, then the lag's tail); torque: -800 N·m with 50 ms, 10 ms and
    // 40 kN·m/s (the lag alone: its rate stays under the limit).
    let p = VehicleParams {
        actuators: ActuatorParams {
            steering_time_constant_s: 0.08,
            steering_delay_s: 0.02,
            steering_rate_limit_rad_per_s: 0.5,
            torque_time_constant_s: 0.05,
            torque_delay_s: 0.01,
            torque_rate_limit_nm_per_s: 40_000.0,
            brake_gain: 1.0,
        },
        ..VehicleParams::default()
    };
    let mut plant = Plant::new(p, State::at_speed(15.0, &p)).unwrap();
    let step = Inputs {
        torque_nm: [-800.0; 4],
        delta_rad: 0.25,
    };
    let h = plant.dt_s();
    let mut ramp_steps = 0;
    for k in 0..600 {
        plant.step(&step, 1.0).unwrap();
        let o = plant.outputs();
        // Step k applies the actuator's value at its end.
        let t = (k + 1) as f64 * h;
        let delta = lagged_step(0.25, 0.08, 0.02, 0.5, t);
        let torque = lagged_step(-800.0, 0.05, 0.01, 40_000.0, t);
        // The discrete switch from the ramp to the tail may fall a step from the
        // continuous one: within a step's worth of rate.
        assert!(
            (o.delta_rad - delta).abs() <= 0.5 * h + 1e-12,
            "t = {t} s: steering {} rad, closed form {delta} rad",
            o.delta_rad
        );
        for applied in o.torque_nm {
            assert!(
                (applied - torque).abs() <= 1e-9 * 800.0,
                "t = {t} s: torque {applied} N·m, closed form {torque} N·m"
            );
        }
        let ramp = 0.5 * (t - 0.02);
        if t > 0.02 && (o.delta_rad - ramp).abs() < 1e-12 {
            ramp_steps += 1;
        }
    }
    // The rate limit held the steering on its ramp up to 0.25 − 0.5·0.08 = 0.21 rad.
    assert!(ramp_steps >= 410, "{ramp_steps} steps on the ramp");
}
