//! `host-sim wcet`: runs the processor-in-the-loop laps (or reads finished ones),
//! traces two short PIL runs (the `paper` lap's start, and a run whose QP reaches
//! its iteration cap) to check the static analysis against, refits the cost model
//! on the measured activations, and writes the report (`wcet.md`, `wcet.json`).

use std::fs::{self, File};
use std::io::BufReader;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;

use crate::closed_loop::cost_model::CostModel;
use crate::commands::pil::{self, PilArgs};
use crate::commands::run::RunArgs;
use crate::pil::link_fault::{FaultKinds, LinkChannel, LinkFault, LinkFaultKind, LinkFaultSpec};
use crate::wcet::cpi::{self, CpiReport};
use crate::wcet::report::{self, ReportInputs};

/// Arguments of `host-sim wcet`.
#[derive(Debug, Clone, Args)]
pub struct WcetArgs {
    /// PIL output folders to report on (from `host-sim pil --out DIR`); default: run
    /// the four paper laps (obstacles none/paper × μ 1/0.5) into OUT/pil-*.
    #[arg(long, num_args = 1..)]
    pub pil: Vec<PathBuf>,
    /// The ECU binary. Default: with --static-only, the binary you flash (`cargo
    /// ecu`, target/thumbv7em-none-eabihf/board/ecu); else the lock-step build
    /// (`cargo ecu-lockstep`, target/thumbv7em-none-eabihf/release/ecu), the one
    /// the traced PIL runs need (its frames go over semihosting).
    #[arg(long)]
    pub elf: Option<PathBuf>,
    /// Simulated seconds of each of the two traced PIL runs: the `paper` lap's start
    /// (its cycles per instruction are reported) and the run towards a box ahead,
    /// whose QP reaches its iteration cap; both traces check the loop bounds and the
    /// task bounds.
    #[arg(long, default_value_t = 2.0)]
    pub trace_seconds: f64,
    /// Use this cycles-per-instruction bound instead of tracing a PIL run (a value
    /// from an earlier report's `traced_cycles_per_instruction`).
    #[arg(long)]
    pub cpi_bound: Option<f64>,
    /// Laps of the paper track to run when no --pil folder is given, s of simulated
    /// time each at most.
    #[arg(long, default_value_t = 200.0)]
    pub duration: f64,
    /// Compare with the expected values (`.ci/expected/wcet.json`, written by
    /// --write-expected); fail when a checked figure differs from its blessed value
    /// or grew past its baseline by more than --margin.
    #[arg(long, conflicts_with = "write_expected")]
    pub expected: Option<PathBuf>,
    /// Relative growth allowed over a baseline, by --expected and --write-expected.
    #[arg(long, default_value_t = 0.05)]
    pub margin: f64,
    /// Bless this report's figures into this expected-values file (CI's step:
    /// `.ci/bless-expected`); refused when one grew past its baseline by more than
    /// --margin, unless --accept-growth says why.
    #[arg(long, conflicts_with = "static_only")]
    pub write_expected: Option<PathBuf>,
    /// With --write-expected: accept growth past the margin, for this reason
    /// (recorded in the file beside the raised baselines).
    #[arg(long, requires = "write_expected")]
    pub accept_growth: Option<String>,
    /// The workspace root: the loop annotations (`// wcet-bound:`) are read from
    /// its firmware crates' sources, `firmware/src` and `qp/src`.
    #[arg(long, default_value = ".")]
    pub workspace: PathBuf,
    /// QEMU execution traces (`host-sim pil --trace FILE`) to check the loop bounds
    /// and the task bounds against, besides the one this command records.
    #[arg(long, num_args = 1..)]
    pub check_trace: Vec<PathBuf>,
    /// Fail when one of these goals of the report is missed, by id (`wcet.json`'s
    /// `goals[].id`, e.g. `control-response-time`, `stack-covered`,
    /// `plan-job-budget`); the others are reported only. With --static-only: the
    /// response times of the build's tasks and interrupts, `TASK-response-time`
    /// (`control`, `plan`, `systick`, and `link` in the flashed build), and
    /// `stack-bound` (the stack bound sound and within 8 KiB).
    #[arg(long, num_args = 1..)]
    pub require: Vec<String>,
    /// Keep the QEMU execution traces this command records (`OUT/trace*/qemu-trace.log`,
    /// tens of MB a simulated second) instead of removing them at the end: pass
    /// them to a later `--static-only --check-trace` to re-check an analysis
    /// without running QEMU again.
    #[arg(long)]
    pub keep_traces: bool,
    /// Only the static analysis of the ELF (control-flow graphs, loops, IPET):
    /// writes `static.json` and `static.md`, runs no PIL lap.
    #[arg(long)]
    pub static_only: bool,
    /// Output directory (created).
    #[arg(long)]
    pub out: PathBuf,
}

impl WcetArgs {
    /// The ECU binary to analyse: `--elf`, else the default for the mode (see
    /// [`WcetArgs::elf`]).
    pub fn elf(&self) -> PathBuf {
        self.elf.clone().unwrap_or_else(|| {
            PathBuf::from(if self.static_only {
                crate::pil::ECU_BOARD_ELF
            } else {
                crate::pil::ECU_ELF
            })
        })
    }

    /// The firmware crates' source folders under `--workspace`.
    fn sources(&self) -> Vec<crate::wcet::annotations::SourceDir> {
        crate::wcet::ecu_sources::workspace_sources(&self.workspace)
    }
}

pub(crate) fn pil_args(
    out: PathBuf,
    obstacles: &str,
    mu: f64,
    duration: f64,
    elf: &Path,
) -> PilArgs {
    PilArgs {
        run: RunArgs {
            track: PAPER_TRACK.into(),
            open: false,
            obstacles: obstacles.into(),
            vehicle: None,
            mu,
            planner_mu: None,
            laps: 1,
            duration,
            initial_speed: PIL_INITIAL_SPEED_MPS,
            precision: crate::closed_loop::Precision::F32,
            ecu_mhz: f64::from(crate::wcet::CLOCK_HZ) / 1e6,
            no_plots: true,
            out,
            conditions: Default::default(),
        },
        elf: elf.to_path_buf(),
        icount_shift: 4,
        qemu: "qemu-system-arm".into(),
        cpi: crate::closed_loop::DEFAULT_CPI_BOUND,
        trace: None,
        no_compare: true,
        frame_timeout: 60.0,
        max_model_underestimate_pct: None,
        link_key: firmware::link::LINK_KEY,
        link_fault: None,
        link: crate::commands::pil::PilLink::Semihosting,
        hil_clock: Default::default(),
        hil_lead_us: crate::pil::usart::DEFAULT_LEAD_US,
    }
}

/// The built-in track the PIL laps and the first two traced runs drive.
const PAPER_TRACK: &str = "paper";

/// The speed the PIL runs start at, m/s.
const PIL_INITIAL_SPEED_MPS: f64 = 15.0;

/// Runs a short PIL run with QEMU's execution trace written to a file, and
/// returns the trace's CPI bound and the file (for the static analysis' check of
/// its loop bounds).
fn cpi_from_trace(args: &WcetArgs) -> Result<(CpiReport, PathBuf)> {
    let dir = args.out.join("trace");
    fs::create_dir_all(&dir)?;
    let log = traced_pil_run(
        args,
        &dir,
        PAPER_TRACK,
        "paper",
        PIL_INITIAL_SPEED_MPS,
        None,
    )?;
    let f = File::open(&log).with_context(|| format!("opening {}", log.display()))?;
    let report = cpi::analyse_log(BufReader::with_capacity(1 << 20, f), None, &[])
        .map_err(|e| anyhow!("{e}"))?;
    Ok((report, log))
}

/// The box of the traced run at the QP's iteration cap: 2 m × 2 m, on the centre
/// line of the `paper` track's start straight, its centre this far from the start,
/// m. At the runs' 15 m/s it is 1.7 s ahead from the first activation: the QP
/// reaches its iteration cap (`QP_MAX_ITER`) in the first activations, and the
/// trace holds the activations the paper laps never make (removals, rebuilds, a
/// full working set).
const CAP_BOX_AHEAD_M: f64 = 25.0;

/// Runs a short PIL run towards a box [`CAP_BOX_AHEAD_M`] ahead, with QEMU's
/// execution trace written to a file, and returns the file: activations at the
/// QP's iteration cap for the check of the loop bounds and of the tightness.
fn cap_trace(args: &WcetArgs) -> Result<PathBuf> {
    let dir = args.out.join("trace-cap");
    fs::create_dir_all(&dir)?;
    let boxes = write_box(&dir, "box_ahead", (CAP_BOX_AHEAD_M, 0.0), 1.0)?;
    traced_pil_run(
        args,
        &dir,
        PAPER_TRACK,
        &boxes.to_string_lossy(),
        PIL_INITIAL_SPEED_MPS,
        None,
    )
}

/// The circle of the traced run at a full working set: its radius, m, its
/// half-widths, m, and the speed the run starts at, m/s. At 14 m/s on 20 m (a
/// lateral acceleration of 9.8 m/s², μ·g at μ 1) the validity and road rows of
/// every node bind at once: the QP's working set reaches 40–48 rows and the
/// iteration cap, the activations nearest the bound's worst case (which charges
/// every iteration a working set of `WS`). The heaviest traced activation of a
/// grid of such runs (radii 15–25 m, 12–18 m/s, half-widths 2.5–5 m:
/// `docs/tuning.md`, *The plan task within its budget*; re-measured with the
/// sideslip lag, which moved it from 22 m at 15 m/s).
const FULL_SET_CIRCLE: (f64, f64, f64) = (20.0, 3.5, 14.0);

/// The box beside the outer edge of [`FULL_SET_CIRCLE`]: the angle of its centre
/// along the circle from the start, rad, and its centre's offset outwards from
/// the centre line, m (its half-side is [`FULL_SET_BOX_HALF_M`]). 20 m ahead, it
/// is within the horizon from the first activation, near the edge the road rows
/// bind at: its rows nearly repeat theirs, so the QP adds rows that depend on its
/// working set (the dual null-space step, `qp::active_set`), and the working set
/// fills at the iteration cap (the heaviest of a grid of angles 0.8–1.8 rad,
/// offsets 1.5–3.5 m and speeds 13–16 m/s in the PIL's instruction counts:
/// docs/tuning.md, *Iterations instead of a refactorization*). The path is
/// closed (the circle fits in the ECU's window), so the obstacles' loops run on
/// a closed path too.
const FULL_SET_BOX: (f64, f64) = (1.0, 1.5);

/// Half the side of the box of [`FULL_SET_BOX`], m.
const FULL_SET_BOX_HALF_M: f64 = 0.5;

/// Runs a short PIL run on [`FULL_SET_CIRCLE`] with the box of [`FULL_SET_BOX`],
/// with QEMU's execution trace written to a file, and returns the file.
fn full_set_trace(args: &WcetArgs) -> Result<PathBuf> {
    let dir = args.out.join("trace-full-set");
    fs::create_dir_all(&dir)?;
    let (radius, half_width, speed) = FULL_SET_CIRCLE;
    // Points 1.5 m apart, counter-clockwise from the origin, heading +x.
    let n = (std::f64::consts::TAU * radius / 1.5).round() as usize;
    let mut csv = String::from("# x_m,y_m,w_tr_right_m,w_tr_left_m\n");
    for k in 0..n {
        let t = std::f64::consts::TAU * k as f64 / n as f64;
        csv.push_str(&format!(
            "{:.4},{:.4},{half_width},{half_width}\n",
            radius * t.sin(),
            radius * (1.0 - t.cos())
        ));
    }
    let track = dir.join("circle.csv");
    fs::write(&track, csv)?;
    let (angle, outwards) = FULL_SET_BOX;
    let centre = (
        (radius + outwards) * angle.sin(),
        radius - (radius + outwards) * angle.cos(),
    );
    let obstacles = write_box(&dir, "box_outer_edge", centre, FULL_SET_BOX_HALF_M)?;
    traced_pil_run(
        args,
        &dir,
        &track.to_string_lossy(),
        &obstacles.to_string_lossy(),
        speed,
        None,
    )
}

/// The straight of the traced run that receives and adopts a window of the road:
/// its length, m, its half-width, m, and the speed the run starts at, m/s (about
/// the car's top speed at μ 1, so the planner holds it). Its rows are 1 m apart:
/// more than a window's, so the ECU holds windows of it.
const WINDOW_STRAIGHT: (f64, f64, f64) = (480.0, 3.5, 25.0);

/// A box beside the line of the window run, m along and left of the centre line:
/// inside the second window, so its adoption places an obstacle.
const WINDOW_BOX: (f64, f64) = (230.0, 2.5);

/// Runs a PIL run on [`WINDOW_STRAIGHT`] until just after the plan task adopted
/// the first window sent while driving (the feeder starts sending it when the car
/// is `BEHIND_M + ADVANCE_M` into the first window, a frame per plan release), with QEMU's execution trace
/// written to a file, and returns the file: the route frames received by the
/// control and plan tasks, the window's adoption (`window_job`), the obstacle
/// placed on the new window. The sensor frame of a plan release halfway through
/// the window's frames is forged ([`WINDOW_SENSOR_FAULT`]): the control task
/// refuses it, learns of that release's route frame from the next frame, and
/// the next plan activation finds two frames announced, reads one and leaves
/// the other for the one after.
fn window_trace(args: &WcetArgs) -> Result<PathBuf> {
    let frames = firmware::link::route_frames(crate::world::route::WINDOW_ROWS) as f64;
    let plan_period_s = firmware::timing::PLAN_PERIOD_US as f64 * 1e-6;
    // The window is due after BEHIND_M + ADVANCE_M at about the run's speed; its
    // frames go one per plan release on the route channel (at most
    // `route_frames` of a full window), and the plan activation after the last
    // adopts it; half a second more (and a period for the refused frame's)
    // leaves a plan on it.
    let seconds = window_due_s() + (frames + 1.0) * plan_period_s + 0.6;
    let (spec, after_s) = WINDOW_SENSOR_FAULT;
    let release_us = firmware::timing::PLAN_PERIOD_US;
    let start_us = ((window_due_s() + after_s) * 1e6) as u64 / release_us * release_us;
    let fault = LinkFault {
        spec: spec.parse().map_err(|e: String| anyhow!(e))?,
        start_us,
    };
    straight_trace(args, "trace-window", seconds, Some(fault))
}

/// The link fault of the window's traced run: one sensor frame forged, at the
/// first plan release this long after the window is due, s (about halfway
/// through its frames).
const WINDOW_SENSOR_FAULT: (&str, f64) = ("forge:1", 0.5);

/// When the run on [`WINDOW_STRAIGHT`] is due the first window sent while
/// driving, s: after `BEHIND_M + ADVANCE_M` at about the run's speed.
fn window_due_s() -> f64 {
    use crate::world::route::{ADVANCE_M, BEHIND_M};
    (BEHIND_M + ADVANCE_M) / WINDOW_STRAIGHT.2
}

/// The link fault of the traced run on the route channel's refusals: the
/// frames of the road replaced, forged, replayed and corrupted in turn, from
/// this long after the window is due, s (two of its frames sent before, for the
/// replay).
const ROUTE_FAULT: (&str, f64) = ("route-mix:3", 0.35);

/// Runs a PIL run on [`WINDOW_STRAIGHT`] whose first window sent while driving
/// loses three frames to [`ROUTE_FAULT`], until half a second after the last,
/// with QEMU's execution trace written to a file, and returns the file: the
/// route frames refused by reason and out of order (`RouteLink::receive`).
fn route_fault_trace(args: &WcetArgs) -> Result<PathBuf> {
    let (spec, after_s) = ROUTE_FAULT;
    let spec: LinkFaultSpec = spec.parse().map_err(|e: String| anyhow!(e))?;
    let plan_period_s = firmware::timing::PLAN_PERIOD_US as f64 * 1e-6;
    let start_s = window_due_s() + after_s;
    let fault = LinkFault {
        spec,
        start_us: (start_s * 1e6) as u64,
    };
    let seconds = start_s + f64::from(spec.frames + 3) * plan_period_s + 0.5;
    straight_trace(args, "trace-route-fault", seconds, Some(fault))
}

/// A traced PIL run of `seconds` on [`WINDOW_STRAIGHT`] with [`WINDOW_BOX`]
/// beside it and the link fault `fault`, in `args.out/name`; returns the trace's
/// file.
fn straight_trace(
    args: &WcetArgs,
    name: &str,
    seconds: f64,
    fault: Option<LinkFault>,
) -> Result<PathBuf> {
    let dir = args.out.join(name);
    fs::create_dir_all(&dir)?;
    let (length, half_width, speed) = WINDOW_STRAIGHT;
    let mut csv = String::from("# x_m,y_m,w_tr_right_m,w_tr_left_m\n");
    for k in 0..=(length as usize) {
        csv.push_str(&format!("{k}.0,0.0,{half_width},{half_width}\n"));
    }
    let track = dir.join("straight.csv");
    fs::write(&track, csv)?;
    let obstacles = write_box(&dir, "box_beside", WINDOW_BOX, 0.5)?;
    let mut a = pil_args(
        dir.join("run"),
        &obstacles.to_string_lossy(),
        1.0,
        seconds,
        &args.elf(),
    );
    a.run.track = track.to_string_lossy().into_owned();
    a.run.open = true;
    a.run.initial_speed = speed;
    a.link_fault = fault;
    traced_run(a, &dir)
}

/// The link fault of the standstill's traced run: line noise before this many
/// sensor frames (the ECU gives up a run as long as the longest sensor frame and
/// reads on), from this far into the run, s.
const STANDSTILL_NOISE: (u32, f64) = (2, 0.5);

/// Runs a PIL run of `--trace-seconds` on the paper track from standstill, with
/// QEMU's execution trace written to a file, and returns the file: a cold start
/// at rest, the MPC's rows of the nodes below the speed the car may not reverse
/// from (`speed_row`), and line noise before two sensor frames
/// ([`STANDSTILL_NOISE`]: the control task's reception of a second run).
fn standstill_trace(args: &WcetArgs) -> Result<PathBuf> {
    let dir = args.out.join("trace-standstill");
    fs::create_dir_all(&dir)?;
    let (frames, after_s) = STANDSTILL_NOISE;
    let fault = LinkFault {
        spec: LinkFaultSpec {
            channel: LinkChannel::Sensor,
            kinds: FaultKinds::One(LinkFaultKind::Noise),
            frames,
        },
        start_us: (after_s * 1e6) as u64,
    };
    traced_pil_run(args, &dir, PAPER_TRACK, "paper", 0.0, Some(fault))
}

/// Writes the obstacle file `dir/ID.csv` of one square box `id`: its centre
/// `(x, y)` and its half-side `h`, m, corners to the mm; returns the file.
fn write_box(dir: &Path, id: &str, (x, y): (f64, f64), h: f64) -> Result<PathBuf> {
    let mut csv = String::from("id,x_m,y_m\n");
    for (dx, dy) in [(-h, -h), (-h, h), (h, h), (h, -h)] {
        csv.push_str(&format!("{id},{:.3},{:.3}\n", x + dx, y + dy));
    }
    let file = dir.join(format!("{id}.csv"));
    fs::write(&file, csv)?;
    Ok(file)
}

/// A PIL run of `--trace-seconds` on `track` at μ 1 with `obstacles`, starting at
/// `speed` m/s, with the link fault `fault`, its output and QEMU's execution
/// trace in `dir`; returns the trace's file.
fn traced_pil_run(
    args: &WcetArgs,
    dir: &Path,
    track: &str,
    obstacles: &str,
    speed: f64,
    fault: Option<LinkFault>,
) -> Result<PathBuf> {
    let mut a = pil_args(
        dir.join("run"),
        obstacles,
        1.0,
        args.trace_seconds,
        &args.elf(),
    );
    a.run.track = track.into();
    a.run.initial_speed = speed;
    a.link_fault = fault;
    traced_run(a, dir)
}

/// Runs the PIL run `a` with QEMU's execution trace written to `dir`; returns
/// the trace's file.
fn traced_run(mut a: PilArgs, dir: &Path) -> Result<PathBuf> {
    let log = dir.join("qemu-trace.log");
    a.trace = Some(std::path::absolute(&log)?);
    pil::run(&a)?;
    Ok(log)
}

/// A CPI report standing for a bound given on the command line.
pub(crate) fn given_cpi(c: f64) -> CpiReport {
    CpiReport {
        total: cpi::Figures {
            instructions: 0,
            worst_case_cycles: 0,
            cpi_bound: c,
            classes: Vec::new(),
        },
        idle: cpi::Figures {
            instructions: 0,
            worst_case_cycles: 0,
            cpi_bound: 0.0,
            classes: Vec::new(),
        },
        tb_executions: 0,
        translations: 0,
        untraced_executions: 0,
        abandoned_executions: 0,
        top_mnemonics: Vec::new(),
        unknown_mnemonics: Vec::new(),
        regions: Vec::new(),
        justification: format!(
            "given on the command line (--cpi-bound {c}): the bound of an earlier traced run; see its report"
        ),
    }
}

/// `host-sim wcet`: the PIL laps and traced runs, the cost model, the static
/// analysis checked against the traces, then the report and its goals.
pub fn run(args: &WcetArgs) -> Result<()> {
    if !(args.trace_seconds.is_finite() && args.trace_seconds > 0.0) {
        bail!("--trace-seconds must be a positive number of seconds");
    }
    let elf = args.elf();
    if !elf.exists() {
        let build = if args.static_only && args.elf.is_none() {
            "cargo ecu"
        } else {
            "cargo ecu-lockstep"
        };
        bail!(
            "the ECU binary {} does not exist: build it with `{build}` (or name another with --elf)",
            elf.display()
        );
    }
    fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    if args.static_only {
        return static_analysis(args, &args.check_trace);
    }
    if crate::wcet::ecu_app::EcuBuild::of_elf(&elf)? == crate::wcet::ecu_app::EcuBuild::Board {
        bail!(
            "{} is the binary you flash (cargo ecu, frames over USART1): the traced report runs the lock-step PIL, which needs the lock-step build (cargo ecu-lockstep, {}); analyse the flashed binary with --static-only",
            elf.display(),
            crate::pil::ECU_ELF
        );
    }
    let run_dirs = pil_laps(args)?;
    // The given traces, then the ones this command records (removed at the end).
    let mut traces = args.check_trace.clone();
    let cpi = record_traces(args, &mut traces)?;

    // The cost model refitted on every measured activation, kept for the
    // simulator's timeline (an estimate, not a bound).
    let model = fit_cost_model(&run_dirs)?;
    // The static analysis of the binary, checked against the traced run: the
    // report's bounds.
    let analysis = crate::wcet::analyse(&args.elf(), &args.sources(), &traces)
        .with_context(|| format!("static analysis of {}", args.elf().display()))?;
    analysis.write(&args.out)?;
    print_static(&analysis, &args.out);
    let inputs = ReportInputs {
        run_dirs: run_dirs.clone(),
        elf: args.elf(),
        stack_levels: crate::wcet::ecu_app::EcuBuild::of_elf(&args.elf())?.priority_levels(),
        cpi,
        statics: report::StaticSummary::of(&analysis),
        plan_period_cycles: firmware::timing::PLAN_PERIOD_US as f64
            * f64::from(crate::wcet::CLOCK_HZ)
            / 1e6,
        plan_budget_cycles: crate::closed_loop::SimOptions::default().plan_budget_cycles,
        control_budget_cycles: crate::closed_loop::SimOptions::default().control_budget_cycles,
        clock_hz: u64::from(crate::wcet::CLOCK_HZ),
    };
    let r = report::build_report(&inputs)?;
    report::markdown::write_report(&args.out, &r)?;
    for log in traces
        .iter()
        .skip(args.check_trace.len())
        .filter(|_| !args.keep_traces)
    {
        // Large (tens of MB a simulated second) and fully read by now.
        let _ = fs::remove_file(log);
    }
    fs::write(
        args.out.join("cost_model.json"),
        serde_json::to_string_pretty(&model)?,
    )?;
    print_summary(&r, &args.out);
    let missed = report::goals::missed_required(&r.goals, &args.require).map_err(|e| anyhow!(e))?;
    if !missed.is_empty() {
        bail!("required goals missed:\n  {}", missed.join("\n  "));
    }
    if let Some(e) = &args.expected {
        report::expected::check_file(&r, e, args.margin)?;
    }
    if let Some(e) = &args.write_expected {
        // Figures from an analysis that failed are no reference to bless.
        analysis_errors(&analysis, &args.out)?;
        report::expected::write_file(&r, e, args.margin, args.accept_growth.as_deref())?;
    }
    analysis_errors(&analysis, &args.out)
}

/// The PIL runs the report reads: the given ones (`--pil`), else four laps
/// recorded now (no obstacle and the paper's, at μ = 1 and 0.5).
fn pil_laps(args: &WcetArgs) -> Result<Vec<PathBuf>> {
    if args.pil.is_empty() {
        let mut dirs = Vec::new();
        for (obstacles, mu) in [("none", 1.0), ("paper", 1.0), ("none", 0.5), ("paper", 0.5)] {
            let dir = args.out.join(format!("pil-{obstacles}-mu{mu}"));
            println!("PIL lap: obstacles {obstacles}, μ = {mu}");
            pil::run(&pil_args(
                dir.clone(),
                obstacles,
                mu,
                args.duration,
                &args.elf(),
            ))?;
            dirs.push(dir);
        }
        Ok(dirs)
    } else {
        Ok(args.pil.clone())
    }
}

/// The CPI bound (given, else from a traced run) and the QEMU traces the
/// analysis is checked against, each recorded now and added to `traces`: the QP
/// at its iteration cap, its working set near full, a window adopted, route
/// frames refused, a start from standstill with line noise before two sensor frames.
fn record_traces(args: &WcetArgs, traces: &mut Vec<PathBuf>) -> Result<CpiReport> {
    let cpi = match args.cpi_bound {
        Some(c) if c.is_finite() && c >= 1.0 => given_cpi(c),
        Some(c) => bail!("--cpi-bound must be at least 1 cycle per instruction, got {c}"),
        None => {
            println!(
                "PIL run with QEMU's execution trace ({} s) for the CPI bound",
                args.trace_seconds
            );
            let (report, log) = cpi_from_trace(args)?;
            traces.push(log);
            report
        }
    };
    println!(
        "PIL run with QEMU's execution trace ({} s) towards a box {CAP_BOX_AHEAD_M} m ahead: the QP at its iteration cap",
        args.trace_seconds
    );
    traces.push(cap_trace(args)?);
    let (radius, _, speed) = FULL_SET_CIRCLE;
    println!(
        "PIL run with QEMU's execution trace ({} s) at {speed} m/s on a circle of {radius} m, a box on its outer edge: the QP's working set full at its cap, rows that depend on it",
        args.trace_seconds
    );
    traces.push(full_set_trace(args)?);
    println!(
        "PIL run with QEMU's execution trace on a straight until the first window of the road sent while driving is adopted"
    );
    traces.push(window_trace(args)?);
    println!(
        "PIL run with QEMU's execution trace on that straight, frames of its window forged, replayed and corrupted on the route channel ({})",
        ROUTE_FAULT.0
    );
    traces.push(route_fault_trace(args)?);
    println!(
        "PIL run with QEMU's execution trace ({} s) on the paper track from standstill, line noise before two sensor frames",
        args.trace_seconds
    );
    traces.push(standstill_trace(args)?);
    Ok(cpi)
}

/// The cost model refitted on every activation the PIL runs in `run_dirs`
/// measured.
fn fit_cost_model(run_dirs: &[PathBuf]) -> Result<CostModel> {
    let runs = run_dirs
        .iter()
        .map(|d| report::pil_runs::load_pil_run(d))
        .collect::<Result<Vec<_>>>()?;
    let plans: Vec<_> = runs.iter().flat_map(|r| r.plan.iter().cloned()).collect();
    let control_max = runs
        .iter()
        .map(|r| r.summary.control_max_instructions)
        .fold(0.0f64, f64::max);
    CostModel::fit(&plans, control_max)
        .ok_or_else(|| anyhow!("too few plan activations to fit the cost model"))
}

/// Prints the plan's and control's figures and every goal, met or missed.
fn print_summary(r: &report::WcetReport, out: &Path) {
    let bound = |t: &report::TaskTiming| {
        let st = &t.statics;
        format!(
            "observed max {:.0} instructions; static bound {} instructions, {} cycles (job {} cycles, budget {:.0}); response time bound {} µs (deadline {} µs); tightness {}",
            t.observed_max_instructions,
            st.static_bound_instructions.map_or("none".into(), |v| v.to_string()),
            st.static_bound_cycles.map_or("none".into(), |v| v.to_string()),
            st.job_static_bound_cycles.map_or("none".into(), |v| v.to_string()),
            t.budget_cycles,
            st.response_time_bound_us.map_or("none within".into(), |v| format!("{v:.0}")),
            st.deadline_us.map_or("?".into(), |v| format!("{v:.0}")),
            st.tightness.map_or("–".into(), |v| format!("{v:.0}")),
        )
    };
    println!("plan: {}", bound(&r.tasks.plan));
    println!("control: {}", bound(&r.tasks.control));
    for g in &r.goals {
        println!(
            "  {} {} ({}): {}",
            if g.met { "met   " } else { "MISSED" },
            g.name,
            g.id,
            g.figures()
        );
    }
    println!("wrote {}", out.display());
}

/// The static analysis of the ELF (control-flow graphs, loops, IPET), written as
/// `static.json` and `static.md`, with a line per task.
fn static_analysis(args: &WcetArgs, traces: &[PathBuf]) -> Result<()> {
    let analysis = crate::wcet::analyse(&args.elf(), &args.sources(), traces)
        .with_context(|| format!("static analysis of {}", args.elf().display()))?;
    analysis.write(&args.out)?;
    print_static(&analysis, &args.out);
    // The stack bound of the same build: every priority level its schedule has
    // (the flashed build's link interrupt among them) and every fault handler.
    let build = crate::wcet::ecu_app::EcuBuild::of_id(analysis.build)
        .with_context(|| format!("no ECU build named `{}`", analysis.build))?;
    let stack = crate::wcet::stack::analyse_elf_once(
        &args.elf(),
        &build.priority_levels(),
        &crate::wcet::ecu_app::ecu_once(),
        &build.masked(),
        &crate::wcet::indirect::targets_of_elf(&args.elf())?,
    )
    .with_context(|| format!("stack bound of {}", args.elf().display()))?;
    let path = args.out.join("stack.json");
    std::fs::write(&path, serde_json::to_string_pretty(&stack)?)
        .with_context(|| format!("writing {}", path.display()))?;
    println!(
        "stack bound: {} B ({}; levels: {}); wrote {}",
        stack.total_bytes,
        if stack.sound { "sound" } else { "NOT sound" },
        stack
            .levels
            .iter()
            .map(|l| l.name.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        path.display()
    );
    // The build's section sizes, flash and static RAM, as the report counts them
    // (the keys of `wcet.json`'s `memory`).
    let memory = report::elf::elf_memory(&args.elf())?;
    let path = args.out.join("memory.json");
    let mut json = serde_json::to_value(memory)?;
    json["flash_bytes"] = memory.flash_bytes().into();
    json["static_ram_bytes"] = memory.static_ram_bytes().into();
    std::fs::write(&path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", path.display()))?;
    println!(
        "flash {} B, static RAM {} B; wrote {}",
        memory.flash_bytes(),
        memory.static_ram_bytes(),
        path.display()
    );
    analysis_errors(&analysis, &args.out)?;
    let (stack_goal, response_times): (Vec<String>, Vec<String>) = args
        .require
        .iter()
        .cloned()
        .partition(|id| id == report::goals::STACK_BOUND_GOAL);
    let mut missed = crate::wcet::analysis::missed_response_times(&analysis.tasks, &response_times)
        .map_err(|e| anyhow!("{e}, {}", report::goals::STACK_BOUND_GOAL))?;
    if !stack_goal.is_empty() {
        missed.extend(report::goals::missed_stack_bound(
            stack.total_bytes,
            stack.sound,
        ));
    }
    if !missed.is_empty() {
        bail!("required goals missed:\n  {}", missed.join("\n  "));
    }
    Ok(())
}

/// A line per task of the static analysis, and its totals.
fn print_static(analysis: &crate::wcet::analysis::StaticAnalysis, out: &std::path::Path) {
    for t in &analysis.tasks {
        let response = match (
            t.deadline_us,
            t.response_time_bound_us,
            t.response_time_past_deadline_us,
        ) {
            (Some(d), Some(r), _) => format!("; response time {r:.2} of {d:.2} µs"),
            (Some(d), None, Some(p)) => {
                format!("; response time MISSED: {p:.2} µs against a deadline of {d:.2}")
            }
            (Some(d), None, None) => format!(
                "; response time MISSED: none within {} × its deadline of {d:.2} µs",
                crate::wcet::rta::PAST_DEADLINE_FACTOR
            ),
            _ => String::new(),
        };
        println!(
            "static analysis, {}: {} functions, {} loops ({} bounded), {}{response}",
            t.name,
            t.functions,
            t.loops,
            t.bounded_loops,
            match (
                t.static_bound_instructions,
                t.static_bound_cycles,
                &t.refused
            ) {
                (Some(i), Some(c), _) => format!(
                    "bound {i} instructions, {c} cycles{}",
                    if t.optimum.as_deref() == Some("relaxation") {
                        " (a relaxation's: the branch and bound reached its node cap)"
                    } else {
                        ""
                    }
                ),
                (_, _, Some(why)) => format!("no bound: {why}"),
                _ => "no bound".to_string(),
            }
        );
    }
    println!(
        "static analysis: {}; wrote {}",
        analysis.gaps(),
        out.join("static.md").display()
    );
}

/// What the analysis cannot give a bound through is an error, not a footnote; so
/// is a trace that contradicts it.
fn analysis_errors(
    analysis: &crate::wcet::analysis::StaticAnalysis,
    out: &std::path::Path,
) -> Result<()> {
    if !analysis.is_complete() {
        bail!(
            "the static analysis is incomplete: {} (see {})",
            analysis.gaps(),
            out.join("static.md").display()
        );
    }
    if !analysis.violations.is_empty() {
        bail!(
            "the static analysis is contradicted by execution ({} violation(s)): {}",
            analysis.violations.len(),
            analysis.violations.join("; ")
        );
    }
    Ok(())
}
