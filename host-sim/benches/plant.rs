//! Plant speed: steps of the 9-DoF plant at 1 kHz, and the real-time factor
//! (simulated seconds per wall-clock second).
//!
//! `PLANT_BENCH_STEPS=N cargo bench -p host-sim --bench plant` skips Criterion and
//! runs exactly `N` steps of the manoeuvre below, printing the end state (a fixed
//! workload for instruction counters such as `valgrind --tool=callgrind`); with
//! `PLANT_BENCH_TRAJECTORY=FILE` it also writes every step's state to `FILE` (CSV,
//! shortest round-trip decimals) to compare two builds' trajectories.
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::hint::black_box;
use std::io::Write;
use std::time::Instant;

use criterion::{criterion_group, Criterion};
use host_sim::model::plant::{Inputs, Plant, State};
use host_sim::model::vehicle::VehicleParams;

/// A cornering, accelerating manoeuvre (all tyres in combined slip).
fn inputs(k: usize) -> Inputs {
    let t = k as f64 * 1e-3;
    Inputs {
        torque_nm: [150.0, 150.0, 0.0, 0.0],
        delta_rad: 0.05 * (0.5 * t).sin(),
    }
}

/// `steps` steps of the manoeuvre; the end state printed, each state written to
/// `trajectory` if given.
fn fixed_steps(steps: usize, trajectory: Option<String>) {
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_speed(15.0, &p)).unwrap();
    let mut out = trajectory.map(|f| std::io::BufWriter::new(std::fs::File::create(f).unwrap()));
    for k in 0..steps {
        plant.step(black_box(&inputs(k)), black_box(1.0)).unwrap();
        if let Some(w) = out.as_mut() {
            let row: Vec<String> = plant
                .state()
                .to_array()
                .iter()
                .map(|v| format!("{v:?}"))
                .collect();
            writeln!(w, "{}", row.join(",")).unwrap();
        }
    }
    println!(
        "end state after {steps} steps: {:?}",
        plant.state().to_array()
    );
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
    let cpu0 = thread_cpu_s();
    let start = Instant::now();
    for k in 0..steps {
        plant.step(&inputs(k), 1.0).unwrap();
    }
    let wall = start.elapsed().as_secs_f64();
    let cpu = thread_cpu_s().zip(cpu0).map(|(b, a)| b - a);
    let sim = steps as f64 * plant.dt_s();
    black_box(plant.state());
    println!(
        "real-time factor: {:.0}x ({sim:.0} s simulated in {wall:.3} s of wall time)",
        sim / wall
    );
    if let Some(cpu) = cpu {
        println!(
            "real-time factor on CPU time: {:.0}x ({cpu:.3} s on the CPU; the wall-time \
             figure also counts time the thread waited for a busy core)",
            sim / cpu
        );
    }
}

/// Time this thread has run on a CPU, s (Linux's scheduler statistics; `None`
/// elsewhere).
fn thread_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}

criterion_group!(benches, bench_plant);

fn main() {
    if let Ok(n) = std::env::var("PLANT_BENCH_STEPS") {
        let steps = n.parse().expect("PLANT_BENCH_STEPS: a number of steps");
        fixed_steps(steps, std::env::var("PLANT_BENCH_TRAJECTORY").ok());
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
