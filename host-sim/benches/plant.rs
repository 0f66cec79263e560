//! Plant speed: steps of the 9-DoF plant at 1 kHz, and the real-time factor
//! (simulated seconds per wall-clock second).
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::hint::black_box;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion};
use host_sim::plant::{Inputs, Plant, State};
use host_sim::vehicle::VehicleParams;

/// A cornering, accelerating manoeuvre (all tyres in combined slip).
fn inputs(k: usize) -> Inputs {
    let t = k as f64 * 1e-3;
    Inputs {
        torque_nm: [150.0, 150.0, 0.0, 0.0],
        delta_rad: 0.05 * (0.5 * t).sin(),
    }
}

fn bench_plant(c: &mut Criterion) {
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_speed(15.0, &p)).unwrap();
    let mut k = 0usize;
    c.bench_function("plant step (1 kHz, RK4)", |b| {
        b.iter(|| {
            plant.step(black_box(&inputs(k)), black_box(1.0)).unwrap();
            k += 1;
        })
    });

    // Real-time factor over 60 simulated seconds.
    let mut plant = Plant::new(p, State::at_speed(15.0, &p)).unwrap();
    let steps = 60_000;
    let start = Instant::now();
    for k in 0..steps {
        plant.step(&inputs(k), 1.0).unwrap();
    }
    let wall = start.elapsed().as_secs_f64();
    let sim = steps as f64 * plant.dt_s();
    black_box(plant.state());
    println!(
        "real-time factor: {:.0}x ({sim:.0} s simulated in {wall:.3} s of wall time)",
        sim / wall
    );
}

criterion_group!(benches, bench_plant);
criterion_main!(benches);
