//! `host-sim pil`: the ECU application in QEMU against the plant ([`crate::pil`]);
//! writes what `run` writes plus `pil.json`, and the in-process run beside it for
//! the comparison.

use std::fs;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use firmware::link::DoneFrame;

use crate::closed_loop::cost_model::CostModel;
use crate::closed_loop::ecu::SimulatedEcu;
use crate::closed_loop::plan_activation::PlanActivation;
use crate::closed_loop::set_up::SetUp;
use crate::closed_loop::timeline;
use crate::closed_loop::{Precision, DEFAULT_CPI_BOUND};
use crate::commands::run::{friction_line, plant_line, prepare, summary_line, RunArgs, RunCommand};
use crate::output::run_files::write_outputs;
use crate::pil::comparison::compare;
use crate::pil::deadlines::count_mismatches;
use crate::pil::qemu::{PilOptions, QemuEcu, ECU_CLOCK_HZ};
use crate::pil::report::PilReport;
use crate::stats::percentile;
use crate::world::faults::FAULT_KINDS;

/// `host-sim pil`'s command line: `run`'s ([`crate::commands::run::RunCommand`]: the same
/// scenario options, refused where PIL cannot apply them), and how to run the ECU.
#[derive(Debug, Clone, clap::Args)]
pub struct PilCommand {
    /// The scenario and outputs, as for `run` (`--precision` must stay f32 and
    /// `--ecu-mhz` 168: the ECU's own clock times the run).
    #[command(flatten)]
    pub run: RunCommand,
    /// How the ECU runs.
    #[command(flatten)]
    pub ecu: PilEcuArgs,
}

/// How `host-sim pil` runs the ECU.
#[derive(Debug, Clone, clap::Args)]
pub struct PilEcuArgs {
    /// The ECU application (build it with `cargo ecu`).
    #[arg(long, default_value = "target/thumbv7em-none-eabihf/release/ecu")]
    pub elf: PathBuf,
    /// QEMU's `-icount shift`: an instruction takes 2^shift ns of the ECU's virtual
    /// time (4: 16 ns, 2.69 cycles at 168 MHz, above the CPI bound).
    #[arg(long, default_value_t = 4)]
    pub icount_shift: u32,
    /// QEMU executable.
    #[arg(long, default_value = "qemu-system-arm")]
    pub qemu: PathBuf,
    /// Cycles per instruction that turn measured instructions into cycles (the
    /// timing report's bound).
    #[arg(long, default_value_t = DEFAULT_CPI_BOUND)]
    pub cpi: f64,
    /// Also write QEMU's execution trace here (for `host-sim wcet`; large).
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// Skip the comparison with the in-process run.
    #[arg(long)]
    pub no_compare: bool,
    /// Longest wall time to wait for one frame, s.
    #[arg(long, default_value_t = 60.0)]
    pub frame_timeout: f64,
    /// Fail when the simulator's cost model underestimates a measured plan
    /// activation by more than this, % (CI's check that the model stays honest).
    #[arg(long)]
    pub max_model_underestimate_pct: Option<f64>,
}

impl PilCommand {
    /// The PIL run's settings (one value of each scenario option, checked).
    pub fn resolve(&self) -> Result<PilArgs> {
        let e = self.ecu.clone();
        Ok(PilArgs {
            run: self.run.resolve("pil")?,
            elf: e.elf,
            icount_shift: e.icount_shift,
            qemu: e.qemu,
            cpi: e.cpi,
            trace: e.trace,
            no_compare: e.no_compare,
            frame_timeout: e.frame_timeout,
            max_model_underestimate_pct: e.max_model_underestimate_pct,
        })
    }
}

/// A PIL run's settings: the run's ([`crate::commands::run::RunArgs`]) and how to run the ECU
/// ([`PilEcuArgs`] has the meanings); what `pil`'s command line resolves to, or what
/// a program builds (`wcet`).
#[derive(Debug, Clone)]
pub struct PilArgs {
    /// The scenario and outputs.
    pub run: RunArgs,
    /// The ECU application.
    pub elf: PathBuf,
    /// QEMU's `-icount shift`.
    pub icount_shift: u32,
    /// QEMU executable.
    pub qemu: PathBuf,
    /// Cycles per instruction.
    pub cpi: f64,
    /// QEMU's execution trace, if wanted.
    pub trace: Option<PathBuf>,
    /// Skip the comparison with the in-process run.
    pub no_compare: bool,
    /// Longest wall time to wait for one frame, s.
    pub frame_timeout: f64,
    /// Largest underestimate of the cost model allowed, %.
    pub max_model_underestimate_pct: Option<f64>,
}

/// Refuses what a PIL run cannot apply, saying why and where it applies: the
/// in-process ECU's arithmetic and clock, and the disturbances applied around the
/// in-process ECU (noise, delay, and every fault but those [`FaultKind::pil`] allows).
///
/// [`FaultKind::pil`]: crate::world::faults::FaultKind::pil
pub fn check_pil_args(args: &PilArgs) -> Result<()> {
    if args.run.precision != Precision::F32 {
        bail!("--precision: the ECU computes in f32; PIL runs are f32 only");
    }
    if (args.run.ecu_mhz - ECU_CLOCK_HZ / 1e6).abs() > 1e-9 {
        bail!("--ecu-mhz: in PIL the ECU's own (virtual) clock times the run; use --icount-shift to change the time per instruction");
    }
    if !(1..=10).contains(&args.icount_shift) {
        bail!(
            "--icount-shift must be in 1..=10 (2^shift ns per instruction), got {}",
            args.icount_shift
        );
    }
    if !(args.cpi.is_finite() && args.cpi > 0.0) {
        bail!(
            "--cpi must be a positive number of cycles per instruction, got {}",
            args.cpi
        );
    }
    let c = &args.run.conditions;
    if c.noise.0 != 0.0 || c.delay_ms != 0.0 {
        bail!("--noise and --delay-ms disturb the estimate around the in-process ECU; PIL does not apply them: use `host-sim run` or `host-sim sweep`");
    }
    if !c.fault.applies_to_pil() {
        let pil: Vec<String> = FAULT_KINDS
            .iter()
            .filter(|k| k.pil)
            .map(|k| k.usage())
            .collect();
        bail!(
            "--fault {}: PIL cannot apply it (dropouts, the steering rate limit and the late obstacle act around the in-process ECU; an overrun changes the modelled ECU's clock, and in PIL the ECU's own clock times the run); PIL takes {}; use `host-sim run` or `host-sim sweep`",
            c.fault,
            pil.join(", ")
        );
    }
    Ok(())
}

/// `host-sim pil` from its command line.
pub fn command(cmd: &PilCommand) -> Result<()> {
    run(&cmd.resolve()?)
}

/// `host-sim pil`.
pub fn run(args: &PilArgs) -> Result<()> {
    check_pil_args(args)?;
    // The disturbances are none (checked above): the ECU gets the estimate as is.
    let SetUp {
        scenario,
        nominal: vehicle,
        plant_car,
        mut opts,
        ..
    } = prepare(&args.run)?;
    opts.cycles_per_instruction = args.cpi;
    let pil_opts = PilOptions {
        elf: args.elf.clone(),
        qemu: args.qemu.clone(),
        icount_shift: args.icount_shift,
        work_dir: args.run.out.join("ecu"),
        frame_timeout_s: args.frame_timeout,
        cycles_per_instruction: args.cpi,
        trace: args.trace.clone(),
    };
    let wall = std::time::Instant::now();
    let mut ecu = QemuEcu::start(&scenario, &vehicle, &opts, &pil_opts)?;
    let bar = indicatif::ProgressBar::new(opts.max_duration_s.ceil() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} PIL: simulated {pos} s  {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
    );
    let result = timeline::run_with(&scenario, &plant_car, &opts, &mut ecu, |t, d| {
        bar.set_position(t as u64);
        bar.set_message(format!("{d:.0} m driven"));
    });
    bar.finish_and_clear();
    let counters = ecu.counters;
    let tick_overruns = ecu.tick_overruns;
    let ecu_counts = ecu.ecu_counts;
    let done = match &result {
        Ok(_) => Some(ecu.stop()?),
        Err(_) => None,
    };
    let result = result?;
    let done = done.unwrap_or(DoneFrame {
        stack_high_water_bytes: 0,
        stack_size_bytes: 0,
        rejected_frames: 0,
    });
    let wall_s = wall.elapsed().as_secs_f64();
    write_outputs(&args.run.out, &scenario, &result, !args.run.no_plots)?;

    let plans = &result.plan_activations;
    let max_of = |f: &dyn Fn(&PlanActivation) -> bool| {
        plans
            .iter()
            .filter(|a| f(a))
            .map(|a| a.instructions)
            .fold(0.0f64, f64::max)
    };
    let comparison = if args.no_compare {
        None
    } else {
        let mut host_ecu = SimulatedEcu::<f32>::new(&scenario, &vehicle, &opts)?;
        let host = timeline::run_with(&scenario, &plant_car, &opts, &mut host_ecu, |_, _| {})?;
        // The in-process run beside it, for a look at any divergence.
        write_outputs(&args.run.out.join("host"), &scenario, &host, false)?;
        Some(compare(&result, &host))
    };
    let report = PilReport {
        icount_shift: args.icount_shift,
        ns_per_instruction: pil_opts.ns_per_instruction(),
        elf: args.elf.display().to_string(),
        stack_high_water_bytes: done.stack_high_water_bytes,
        stack_size_bytes: done.stack_size_bytes,
        ecu_rejected_frames: done.rejected_frames,
        host_rejected_frames: counters.rejected,
        stale_frames: counters.stale,
        control_max_instructions: percentile(&result.control_instructions, 1.0),
        control_p50_instructions: percentile(&result.control_instructions, 0.5),
        plan_max_instructions: max_of(&|_| true),
        warm_max_instructions: max_of(&|a| a.plans_warm()),
        cold_max_instructions: max_of(&|a| a.plans_cold()),
        model_error: opts.cost_model.error_on(plans),
        refit: CostModel::fit(plans, percentile(&result.control_instructions, 1.0)),
        comparison,
        tick_overruns,
        count_mismatches: count_mismatches(&result.summary, &tick_overruns),
        ecu_counts,
        wall_s,
    };
    let pil_path = args.run.out.join("pil.json");
    fs::write(&pil_path, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("cannot write {}", pil_path.display()))?;

    let s = &result.summary;
    println!("{}", summary_line(&scenario, s));
    println!("{}", friction_line(s));
    if let Some(line) = plant_line(s) {
        println!("{line}");
    }
    if !s.completed {
        println!("stopped: {}", s.stop_reason);
    }
    println!(
        "ECU (QEMU, {} ns/instruction): plan max {:.0} instructions (warm {:.0}, cold {:.0}), p50 {:.0}; control max {:.0}; stack high-water {} of {} B; frames refused: ECU {}, host {}, stale {}",
        report.ns_per_instruction,
        report.plan_max_instructions,
        report.warm_max_instructions,
        report.cold_max_instructions,
        s.plan_p50_instructions,
        report.control_max_instructions,
        report.stack_high_water_bytes,
        report.stack_size_bytes,
        report.ecu_rejected_frames,
        report.host_rejected_frames,
        report.stale_frames,
    );
    let e = &report.model_error;
    println!(
        "cost model vs ECU over {} plan activations: |error| max {:.1} %, p99 {:.1} %, largest underestimate {:.1} %",
        e.activations, e.max_abs_pct, e.p99_abs_pct, e.max_under_pct
    );
    if let Some(c) = &report.comparison {
        match c.first_divergence_s {
            None => println!("against the in-process run: {}", c.cause),
            Some(t) => println!(
                "against the in-process run: first divergence at {t:.2} s: {}",
                c.cause
            ),
        }
    }
    let opt = |x: Option<u64>| x.map_or("-".to_string(), |v| v.to_string());
    println!(
        "deadlines, ECU's own count / host's: plan misses {} / {}, skipped releases {} / {}, budget overruns (ECU clock) {} / {}; control misses {} / {}, skipped releases {} / {}, budget overruns (ECU clock) {} / {}; watchdog trips {}; largest response times on the ECU: plan {} µs, control {} µs",
        opt(s.ecu_plan_deadline_misses),
        s.plan_deadline_misses,
        opt(s.ecu_skipped_releases),
        s.plan_skipped_releases,
        opt(s.ecu_plan_budget_overruns),
        tick_overruns.plan,
        opt(s.ecu_control_deadline_misses),
        s.control_deadline_misses,
        opt(s.ecu_control_skipped_releases),
        s.control_skipped_releases,
        opt(s.ecu_control_budget_overruns),
        tick_overruns.control,
        opt(s.ecu_watchdog_trips),
        opt(ecu_counts.map(|c| c.plan.max_response_us)),
        opt(ecu_counts.map(|c| c.control.max_response_us)),
    );
    println!(
        "PIL wall time {:.1} s; wrote {}",
        wall_s,
        args.run.out.display()
    );
    if !report.count_mismatches.is_empty() {
        bail!(
            "the ECU's own deadline counts differ from the host's: {} (pil.json: count_mismatches)",
            report.count_mismatches.join("; ")
        );
    }
    if let Some(limit) = args.max_model_underestimate_pct {
        if e.max_under_pct > limit {
            bail!(
                "the cost model underestimates a measured plan activation by {:.1} % (> {limit} %): refit it (`host-sim wcet` writes cost_model.json) and update CostModel::default",
                e.max_under_pct
            );
        }
    }
    Ok(())
}
