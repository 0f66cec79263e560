//! ECU measurement binary: runs MPC steps on the Cortex-M4F and prints what each
//! costs, in instructions, under QEMU with `-icount shift=3` (see `.cargo/config.toml`).
//!
//! A stadium-shaped closed track (two 60 m straights, two 20 m-radius half circles,
//! 4 m half-widths) with a parked car on each straight is built at start-up; a
//! kinematic-bicycle stand-in for the car follows each plan
//! for 100 ms before the next step, so the steps are those of a real receding
//! horizon: one cold start, then warm starts through straights and curves.
//!
//! Run: `cargo run --release -p firmware --target thumbv7em-none-eabihf --features ecu --bin mpc_step`
//! (alias `cargo ecu-mpc`). SysTick counts the 168 MHz virtual clock; with
//! `shift=3` QEMU executes one instruction per 8 ns, so
//! `instructions = ticks × (1/168 MHz) / 8 ns`.
#![no_std]
#![no_main]
// Statics for the (large) planner workspace need one `unsafe` access at start-up.
#![allow(unsafe_code)]

#[path = "support/qemu_exit.rs"]
mod qemu_exit;

use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use firmware::bicycle::BicycleGeometry;
use firmware::low_level::LowLevelConfig;
use firmware::mpc::{Mpc, MpcSettings};
use firmware::obstacles::{Obstacle, ObstacleManager, ObstacleSettings};
use firmware::plan::Plan;
use firmware::reference_path::ReferencePath;
use firmware::state_estimate::StateEstimate;
use firmware::tasks::ControlTask;
use qemu_exit::exit;
use qp::real::f32_math;
use stm32f4 as _;

const PATH_CAP: usize = 256;
const STEPS: usize = 150;

static mut MPC: Mpc<f32> = Mpc::new();
static mut PATH: ReferencePath<f32, PATH_CAP> = ReferencePath::new();
static mut PLAN: Plan<f32> = Plan::zeroed();
static mut POINTS: [[f32; 4]; PATH_CAP] = [[0.0; 4]; PATH_CAP];

/// Stadium track: returns the number of points written.
fn stadium(points: &mut [[f32; 4]; PATH_CAP]) -> usize {
    let (straight, radius, ds) = (60.0f32, 20.0f32, 2.0f32);
    let mut n = 0;
    let mut push = |x: f32, y: f32| {
        if let Some(p) = points.get_mut(n) {
            *p = [x, y, 4.0, 4.0];
            n += 1;
        }
    };
    let arc_pts = (core::f32::consts::PI * radius / ds) as usize;
    let line_pts = (straight / ds) as usize;
    for i in 0..line_pts {
        push(i as f32 * ds, 0.0);
    }
    for i in 0..arc_pts {
        let a = -core::f32::consts::FRAC_PI_2 + core::f32::consts::PI * i as f32 / arc_pts as f32;
        push(
            straight + radius * f32_math::cos(a),
            radius + radius * f32_math::sin(a),
        );
    }
    for i in 0..line_pts {
        push(straight - i as f32 * ds, 2.0 * radius);
    }
    for i in 0..arc_pts {
        let a = core::f32::consts::FRAC_PI_2 + core::f32::consts::PI * i as f32 / arc_pts as f32;
        push(
            radius * f32_math::cos(a),
            radius + radius * f32_math::sin(a),
        );
    }
    n
}

fn ticks_between(start: u32, end: u32) -> u32 {
    // SysTick counts down from its reload value.
    start.wrapping_sub(end) & 0x00FF_FFFF
}

#[entry]
fn main() -> ! {
    let (mpc, path, plan, points) = unsafe {
        (
            &mut *core::ptr::addr_of_mut!(MPC),
            &mut *core::ptr::addr_of_mut!(PATH),
            &mut *core::ptr::addr_of_mut!(PLAN),
            &mut *core::ptr::addr_of_mut!(POINTS),
        )
    };
    let mut syst = match cortex_m::Peripherals::take() {
        Some(p) => p.SYST,
        None => exit(false),
    };
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_counter();

    let n = stadium(points);
    if path.load_track(&points[..n], true).is_err() {
        hprintln!("mpc_step: track rejected");
        exit(false);
    }
    let geometry = BicycleGeometry {
        l_f_m: 1.2,
        l_r_m: 1.6,
    };
    let settings = MpcSettings::paper(geometry, 0.6, 1.8);
    // Two parked cars on the straights, one on each side.
    let mut obstacles = ObstacleManager::new();
    let boxes = [
        [[28.0, -2.5], [32.5, -2.5], [32.5, -0.6], [28.0, -0.6]],
        [[25.0, 40.6], [29.5, 40.6], [29.5, 42.5], [25.0, 42.5]],
    ];
    let mut list: heapless::Vec<Obstacle<f32>, 2> = heapless::Vec::new();
    for (k, b) in boxes.iter().enumerate() {
        if let Ok(o) = Obstacle::from_vertices(k as u32, b) {
            let _ = list.push(o);
        }
    }
    let obstacle_settings =
        ObstacleSettings::for_vehicle(1.8, 4.45, 1.0, settings.velocity.v_max_mps(1.0));
    if obstacles.update(&obstacle_settings, path, &list).is_err() {
        hprintln!("mpc_step: obstacles rejected");
        exit(false);
    }
    let mut est = StateEstimate {
        stamp_us: 0,
        x_m: 0.0,
        y_m: 0.0,
        psi_rad: 0.0,
        vx_mps: 15.0,
        vy_mps: 0.0,
        yaw_rate_radps: 0.0,
        delta_rad: 0.0,
        ..StateEstimate::zeroed()
    };
    let (mut max_warm, mut sum_warm, mut cold, mut failures) = (0u32, 0u64, 0u32, 0u32);
    let mut max_iter = 0u32;
    let mut control_max = 0u32;
    let mut control = match ControlTask::new(LowLevelConfig::default()) {
        Ok(c) => c,
        Err(_) => exit(false),
    };
    for step in 0..STEPS {
        let t0 = SYST::get_current();
        let result = mpc.step(&settings, path, obstacles.parabolas(), &est, 1.0, plan);
        let t1 = SYST::get_current();
        let ticks = ticks_between(t0, t1);
        match result {
            Ok(report) => {
                // One line per step, for the cost model's calibration (docs/architecture.md).
                hprintln!(
                    "step {} instructions={} passes={} iterations={} added={} removed={} refactorizations={} rows={}",
                    step,
                    ticks as u64 * 1_000_000_000 / u64::from(firmware::timing::ECU_CLOCK_HZ) / 8,
                    report.passes,
                    report.qp_iterations,
                    report.qp_added,
                    report.qp_removed,
                    report.qp_refactorizations,
                    report.rows
                );
                max_iter = max_iter.max(report.qp_iterations);
                if step == 0 {
                    cold = ticks;
                } else {
                    max_warm = max_warm.max(ticks);
                    sum_warm += ticks as u64;
                }
            }
            Err(_) => failures += 1,
        }
        // The car (a kinematic stand-in) follows the plan's inputs for 100 ms; the
        // control task runs every 10 ms on its state, for the control's cost.
        let mut xi = [
            0.0,
            est.x_m,
            est.y_m,
            est.speed_mps(),
            est.psi_rad,
            est.delta_rad,
        ];
        for k in 0..10u64 {
            let now = est.stamp_us + k * 10_000;
            let measured = estimate_of(&xi, now);
            let c0 = SYST::get_current();
            let _ = control.run(&measured, plan, now);
            let c1 = SYST::get_current();
            control_max = control_max.max(ticks_between(c0, c1));
            xi = geometry.discretize(&xi, &plan.inputs[0], 0.01).x_next;
        }
        est = estimate_of(&xi, est.stamp_us + 100_000);
    }
    let to_instr =
        |ticks: u64| ticks * 1_000_000_000 / u64::from(firmware::timing::ECU_CLOCK_HZ) / 8;
    let mean_warm = sum_warm / (STEPS as u64 - 1);
    hprintln!(
        "mpc_step: steps={} failures={} max_qp_iterations={}",
        STEPS,
        failures,
        max_iter
    );
    hprintln!("mpc_step: cold_instructions={}", to_instr(cold as u64));
    hprintln!("mpc_step: warm_mean_instructions={}", to_instr(mean_warm));
    hprintln!(
        "mpc_step: warm_max_instructions={}",
        to_instr(max_warm as u64)
    );
    hprintln!(
        "mpc_step: mpc_workspace_bytes={}",
        core::mem::size_of::<Mpc<f32>>()
    );
    hprintln!(
        "mpc_step: qp_solver_bytes={}",
        core::mem::size_of::<firmware::mpc::MpcQp<f32>>()
    );
    hprintln!(
        "mpc_step: control_max_instructions={}",
        to_instr(control_max as u64)
    );
    exit(failures == 0)
}

/// The estimate a perfect sensor gives at `stamp_us` (µs) of the kinematic
/// stand-in's state `xi` = [s, x (m), y (m), V (m/s), ψ (rad), δ (rad)].
fn estimate_of(xi: &[f32; 6], stamp_us: u64) -> StateEstimate<f32> {
    StateEstimate {
        stamp_us,
        x_m: xi[1],
        y_m: xi[2],
        psi_rad: xi[4],
        vx_mps: xi[3],
        vy_mps: 0.0,
        yaw_rate_radps: 0.0,
        delta_rad: xi[5],
        ..StateEstimate::zeroed()
    }
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    // The ECU's only panic path: report and stop (the actuators are not driven here).
    hprintln!("mpc_step: panic");
    exit(false)
}
