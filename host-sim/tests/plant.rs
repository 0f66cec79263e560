//! The 9-DoF plant: loads, straight-line behaviour, standstill, determinism.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::model::plant::{Inputs, Plant, PlantError, RoadUnder, State, FL, FR, RL, RR};
use host_sim::model::vehicle::{VehicleParams, G};

fn run(plant: &mut Plant, inputs: &Inputs, seconds: f64) {
    let n = (seconds / plant.dt_s()).round() as usize;
    for _ in 0..n {
        plant.step(inputs, 1.0).unwrap();
    }
}

#[test]
fn static_loads_sum_to_the_weight() {
    let p = VehicleParams::default();
    let plant = Plant::new(p, State::at_rest()).unwrap();
    let fz = plant.outputs().fz_n;
    let sum: f64 = fz.iter().sum();
    assert!((sum - p.mass_kg * G).abs() < 1e-6 * sum, "{sum}");
    // More weight on the front axle (l_r > l_f), equal left and right.
    assert!(fz[FL] > fz[RL]);
    assert_eq!(fz[FL], fz[FR]);
    assert_eq!(fz[RL], fz[RR]);
}

#[test]
fn at_rest_with_zero_torque_the_car_stays_at_rest() {
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_rest()).unwrap();
    // Even with the wheels steered.
    let inputs = Inputs {
        torque_nm: [0.0; 4],
        delta_rad: 0.3,
    };
    for _ in 0..10_000 {
        plant.step(&inputs, 1.0).unwrap();
        let s = plant.state();
        assert!(s.x_m.abs() < 1e-9 && s.y_m.abs() < 1e-9 && s.psi_rad.abs() < 1e-9);
        assert!(s.speed_mps() < 1e-9);
        assert!(s.omega_radps.iter().all(|w| w.abs() < 1e-9));
    }
    let o = plant.outputs();
    assert!(o
        .kappa
        .iter()
        .chain(o.alpha_rad.iter())
        .all(|v| v.is_finite()));
}

#[test]
fn braking_to_a_standstill_is_smooth_and_the_car_does_not_creep_afterwards() {
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_speed(1.0, &p)).unwrap();
    let brake = Inputs {
        torque_nm: [-150.0; 4],
        delta_rad: 0.0,
    };
    let mut t = 0.0;
    while plant.state().vx_mps > 0.005 && t < 5.0 {
        plant.step(&brake, 1.0).unwrap();
        let o = plant.outputs();
        assert!(o
            .kappa
            .iter()
            .all(|k| k.is_finite() && k.abs() <= 1.0 + 1e-9));
        t += plant.dt_s();
    }
    assert!(t < 5.0, "did not stop");
    // Released: a car with no rolling resistance coasts, but never speeds up.
    let v0 = plant.state().speed_mps();
    for _ in 0..10_000 {
        plant.step(&Inputs::default(), 1.0).unwrap();
        assert!(plant.state().speed_mps() <= v0 + 1e-9);
    }
    assert!(plant.state().omega_radps.iter().all(|w| w.is_finite()));
}

#[test]
fn driving_torque_speeds_up_with_positive_slip() {
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_speed(10.0, &p)).unwrap();
    let inputs = Inputs {
        torque_nm: [400.0, 400.0, 0.0, 0.0],
        delta_rad: 0.0,
    };
    run(&mut plant, &inputs, 2.0);
    let s = *plant.state();
    let o = plant.outputs();
    assert!(s.vx_mps > 12.0, "{}", s.vx_mps);
    assert!(o.kappa[FL] > 0.0 && o.kappa[FR] > 0.0);
    assert!(o.fxp_n[FL] > 0.0);
    assert!(o.ax_mps2 > 0.0);
    // Driving pitches the nose up and loads the rear.
    assert!(s.pitch_rad < 0.0);
    assert!(o.fz_n[RL] > p.static_loads_n()[RL]);
    // Straight: no drift.
    assert!(s.y_m.abs() < 1e-6 && s.psi_rad.abs() < 1e-9, "{s:?}");
}

#[test]
fn braking_slows_down_with_negative_slip_and_moves_load_forward() {
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_speed(20.0, &p)).unwrap();
    let inputs = Inputs {
        torque_nm: [-600.0; 4],
        delta_rad: 0.0,
    };
    run(&mut plant, &inputs, 1.0);
    let s = *plant.state();
    let o = plant.outputs();
    assert!(s.vx_mps < 15.0, "{}", s.vx_mps);
    assert!(o.kappa.iter().all(|k| *k < 0.0), "{:?}", o.kappa);
    assert!(o.ax_mps2 < -5.0);
    let fz0 = p.static_loads_n();
    assert!(s.pitch_rad > 0.0, "nose down");
    assert!(o.fz_n[FL] > fz0[FL] && o.fz_n[FR] > fz0[FR]);
    assert!(o.fz_n[RL] < fz0[RL] && o.fz_n[RR] < fz0[RR]);
}

#[test]
fn cornering_left_moves_load_to_the_right_wheels() {
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_speed(15.0, &p)).unwrap();
    let inputs = Inputs {
        torque_nm: [60.0, 60.0, 0.0, 0.0],
        delta_rad: 0.05,
    };
    run(&mut plant, &inputs, 3.0);
    let o = plant.outputs();
    assert!(o.ay_mps2 > 2.0, "{}", o.ay_mps2);
    assert!(plant.state().yaw_rate_radps > 0.0);
    assert!(plant.state().roll_rad > 0.0, "body rolls to the outside");
    assert!(o.fz_n[FR] > o.fz_n[FL] && o.fz_n[RR] > o.fz_n[RL]);
    assert!(o.alpha_rad[FL] > 0.0 && o.fyp_n[FL] > 0.0);
}

#[test]
fn two_runs_are_bit_identical() {
    let p = VehicleParams::default();
    let go = || {
        let mut plant = Plant::new(p, State::at_speed(12.0, &p)).unwrap();
        let mut trace = Vec::new();
        for k in 0..3000 {
            let t = k as f64 * 1e-3;
            let inputs = Inputs {
                torque_nm: [300.0 * (t * 2.0).sin(), 250.0, -100.0 * t, 40.0],
                delta_rad: 0.1 * (t * 3.0).sin(),
            };
            plant.step(&inputs, 0.8).unwrap();
            trace.push(*plant.state());
        }
        trace
    };
    let a = go();
    let b = go();
    assert!(a.iter().zip(&b).all(|(x, y)| {
        let bits = |s: &State| {
            [
                s.x_m,
                s.y_m,
                s.psi_rad,
                s.vx_mps,
                s.vy_mps,
                s.yaw_rate_radps,
                s.roll_rad,
                s.pitch_rad,
                s.omega_radps[0],
                s.omega_radps[3],
            ]
            .map(f64::to_bits)
        };
        bits(x) == bits(y)
    }));
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_speed(5.0, &p)).unwrap();
    let before = *plant.state();
    let bad = Inputs {
        torque_nm: [f64::NAN, 0.0, 0.0, 0.0],
        delta_rad: 0.0,
    };
    assert!(matches!(plant.step(&bad, 1.0), Err(PlantError::Input(_))));
    assert!(matches!(
        plant.step(&Inputs::default(), f64::INFINITY),
        Err(PlantError::Mu(_))
    ));
    for grade_rad in [f64::NAN, 0.8, -1.0] {
        let road = RoadUnder {
            mu: [1.0; 4],
            grade_rad,
        };
        let e = plant.step_on_road(&Inputs::default(), &road).unwrap_err();
        assert!(matches!(e, PlantError::Grade(_)), "{e}");
        assert!(e.to_string().contains("grade"), "{e}");
    }
    assert_eq!(*plant.state(), before);
    let nan_state = State {
        vy_mps: f64::NAN,
        ..State::default()
    };
    assert!(matches!(
        Plant::new(p, nan_state),
        Err(PlantError::State("vy_mps"))
    ));
    assert!(matches!(
        Plant::with_step(p, State::default(), 0.0),
        Err(PlantError::Step(_))
    ));
    let mut bad_p = p;
    bad_p.mass_kg = -1.0;
    let e = Plant::new(bad_p, State::default()).unwrap_err();
    assert!(e.to_string().contains("mass_kg"), "{e}");
    // Huge torques: stays finite or reports divergence, never panics.
    let mut plant = Plant::new(p, State::at_speed(5.0, &p)).unwrap();
    let wild = Inputs {
        torque_nm: [1e6, -1e6, 1e6, -1e6],
        delta_rad: 10.0,
    };
    for _ in 0..2000 {
        if plant.step(&wild, 1.0).is_err() {
            break;
        }
    }
    let _ = RR;
}

#[test]
fn a_hard_launch_from_rest_and_a_hard_stop_stay_finite_and_sensible() {
    let p = VehicleParams::default();
    for dt in [1e-3, 5e-3] {
        let mut plant = Plant::with_step(p, State::at_rest(), dt).unwrap();
        let launch = Inputs {
            torque_nm: [800.0, 800.0, 0.0, 0.0],
            delta_rad: 0.0,
        };
        run(&mut plant, &launch, 3.0);
        let s = *plant.state();
        // By hand: the torque's force less the rolling resistance, on the mass and
        // the wheels' inertia (drag is under 1 % here).
        let m_eff = p.mass_kg + 4.0 * p.wheel_inertia_kg_m2 / p.r_eff_m.powi(2);
        let v_hand = 3.0 * (1600.0 / p.r_eff_m - p.crr * p.mass_kg * G) / m_eff;
        assert!(
            (s.vx_mps - v_hand).abs() < 0.05 * v_hand,
            "dt={dt}: {s:?}, by hand {v_hand} m/s"
        );
        let o = plant.outputs();
        assert!(o.kappa[FL] > 0.0 && o.kappa[FL] < 0.2, "{:?}", o.kappa);
        let stop = Inputs {
            torque_nm: [-700.0, -700.0, -300.0, -300.0],
            delta_rad: 0.0,
        };
        let mut t = 0.0;
        while plant.state().vx_mps > 0.05 && t < 10.0 {
            plant.step(&stop, 1.0).unwrap();
            let o = plant.outputs();
            // Braking slip: -1 is a locked wheel. Checked above 1 m/s: below, the
            // friction brakes fade (a stopped wheel is not driven backwards) and the
            // slip is a floored slip velocity.
            let moving = plant.state().vx_mps > 1.0;
            assert!(
                t < 0.2 || !moving || o.kappa.iter().all(|k| *k < 0.0 && *k >= -1.0 - 1e-9),
                "dt={dt} t={t} v={} {:?}",
                plant.state().vx_mps,
                o.kappa
            );
            // Never beyond what the tyres can give (longitudinal peak mu about 1.2).
            assert!(o.ax_mps2 > -1.4 * G, "{}", o.ax_mps2);
            t += dt;
        }
        assert!(t < 10.0, "dt={dt}: did not stop");
        // A brake torque far beyond the tyres' grip: stays finite, the wheels lock
        // (friction brakes never spin a wheel backwards) and the car stops.
        let mut plant = Plant::with_step(p, State::at_speed(20.0, &p), dt).unwrap();
        let lock = Inputs {
            torque_nm: [-3000.0; 4],
            delta_rad: 0.0,
        };
        run(&mut plant, &lock, 2.0);
        let o = plant.outputs();
        assert!(o.kappa.iter().chain(o.fxp_n.iter()).all(|v| v.is_finite()));
        assert!(o.ax_mps2 > -1.4 * G);
        run(&mut plant, &lock, 3.0);
        // Stopped, up to the creep the brakes' low-speed fade allows at this step.
        assert!(
            plant.state().vx_mps.abs() < 0.5,
            "stopped: {:?}",
            plant.state()
        );
    }
}
