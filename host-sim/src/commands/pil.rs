//! `host-sim pil`: the ECU application in QEMU against the plant ([`crate::pil`]);
//! writes what `run` writes plus `pil.json`, and the in-process run beside it for
//! the comparison. With `--link usart`, the binary you flash in a real-time loop
//! over its emulated USART instead ([`crate::pil::usart`], [`run_usart`]): what
//! `run` writes, its summary with `"link": "usart"` and the link's figures.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use firmware::link::{DoneFrame, LinkKey, Refusal, RefusalCounts};
use firmware::tasks::CONTROL_PERIOD_US;

use crate::closed_loop::cost_model::CostModel;
use crate::closed_loop::disturbed_ecu::DisturbedEcu;
use crate::closed_loop::ecu::SimulatedEcu;
use crate::closed_loop::plan_activation::PlanActivation;
use crate::closed_loop::set_up::SetUp;
use crate::closed_loop::summary::Summary;
use crate::closed_loop::timeline::{self, RunResult};
use crate::closed_loop::SimOptions;
use crate::closed_loop::{Precision, DEFAULT_CPI_BOUND};
use crate::commands::run::{friction_line, plant_line, prepare, summary_line, RunArgs, RunCommand};
use crate::model::vehicle::VehicleParams;
use crate::output::run_files::write_outputs;
use crate::pil::comparison::compare;
use crate::pil::deadlines::count_mismatches;
use crate::pil::link_fault::{LinkFault, LinkFaultSpec};
use crate::pil::qemu::{InjectedFrames, LinkCounters, PilOptions, QemuEcu, ECU_CLOCK_HZ};
use crate::pil::report::{LinkFaultReport, PilReport};
use crate::pil::usart::{HilClock, UsartEcu, UsartOptions, DEFAULT_LEAD_US};
use crate::stats::percentile;
use crate::world::disturbance::Disturbances;
use crate::world::faults::{FAULT_KINDS, FAULT_START_S};
use crate::world::scenario::Scenario;

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

/// How the ECU talks to the simulator.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum PilLink {
    /// The lock-step build (`cargo ecu-lockstep`) over semihosting FIFOs,
    /// `-icount sleep=off`: deterministic, bit-identical to the in-process run.
    #[default]
    Semihosting,
    /// The binary you flash (`cargo ecu`) over its USART1 on QEMU's
    /// stdio, in real time: QEMU's clock kept with the host's, the plant
    /// stepped on the host's clock (a hardware-in-the-loop run, as on a bench;
    /// not deterministic).
    Usart,
}

impl PilLink {
    /// Its name on the command line and in `summary.json`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Semihosting => "semihosting",
            Self::Usart => "usart",
        }
    }
}

/// How `host-sim pil` runs the ECU.
#[derive(Debug, Clone, clap::Args)]
pub struct PilEcuArgs {
    /// How the ECU is linked: `semihosting` (the lock-step PIL, deterministic)
    /// or `usart` (the binary you flash, in real time over its emulated USART;
    /// the comparison with the in-process run, `--trace`, the cost model's check
    /// and `--link-fault` are lock-step only).
    #[arg(long, value_enum, default_value_t = PilLink::Semihosting)]
    pub link: PilLink,
    /// The ECU binary. Default: with `--link semihosting` the lock-step build
    /// `target/thumbv7em-none-eabihf/release/ecu` (`cargo ecu-lockstep`); with `--link
    /// usart` the binary you flash, `target/thumbv7em-none-eabihf/board/ecu`
    /// (`cargo ecu`; under `$CARGO_TARGET_DIR` when it is set).
    #[arg(long)]
    pub elf: Option<PathBuf>,
    /// With `--link usart`: QEMU's virtual clock (`host`: no `-icount`, the
    /// host's clock; `icount`: `-icount shift=N,align=on,sleep=on`, 2^N ns per
    /// instruction, held back to the host's).
    #[arg(long, value_enum, default_value_t = HilClock::Host)]
    pub hil_clock: HilClock,
    /// With `--link usart`: how far ahead of the ECU's control release the
    /// run's periods start (the sensor frames' lead while the two clocks agree), µs.
    #[arg(long, default_value_t = DEFAULT_LEAD_US, value_name = "US")]
    pub hil_lead_us: u64,
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
    /// Replace sensor frames, from the link fault's start: `forge` (a tag under
    /// another key), `replay` (frames sent before the fault, again), `corrupt`
    /// (a bit flipped) or `mix` (the three in turn), each `[:N]` frames (default
    /// 20). The ECU must refuse each, count it by reason and never act on it (a
    /// dropout: the safe actuation), and the lap go on; `host-sim pil` fails
    /// otherwise. With the prefix `route-` (e.g. `route-mix:3`), the next N
    /// frames of the road on the route channel instead: their window is lost,
    /// the car plans on the one it holds until the next. `noise[:N]` (sensor
    /// frames only) sends each of N frames after a run of line noise as long as
    /// the longest sensor frame, without a delimiter: the ECU must refuse the run
    /// (as `corrupt`) and act on the frame.
    #[arg(long, value_name = "[route-]forge|replay|corrupt|mix[:N], noise[:N]")]
    pub link_fault: Option<LinkFaultSpec>,
    /// When the link fault starts, s of simulated time (rounded down to a 10 ms
    /// control period).
    #[arg(long, default_value_t = FAULT_START_S, value_name = "S")]
    pub link_fault_at: f64,
    /// The link key, 32 hexadecimal digits: the one the ECU application was built
    /// with (`ECU_LINK_KEY` at its build). Default: the environment variable
    /// `ECU_LINK_KEY`, else this simulator's build's key (the development key
    /// unless it was built with `ECU_LINK_KEY`).
    #[arg(long, value_name = "HEX")]
    pub link_key: Option<String>,
}

/// The environment variable that gives the link key (as at the firmware's build).
pub const LINK_KEY_VAR: &str = "ECU_LINK_KEY";

/// The link key of 32 hexadecimal digits `hex` (`what` says where it came from,
/// for the error; the digits are never repeated: the key is a secret).
pub fn parse_link_key(hex: &str, what: &str) -> Result<LinkKey> {
    let hex = hex.trim();
    if hex.len() != 32 || !hex.is_ascii() {
        bail!(
            "{what}: a link key is 32 hexadecimal digits (16 bytes), got {} characters",
            hex.chars().count()
        );
    }
    let mut key = [0u8; 16];
    for (i, b) in key.iter_mut().enumerate() {
        *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).map_err(|_| {
            anyhow::anyhow!(
                "{what}: characters {}-{} are not hexadecimal digits (0-9, a-f)",
                2 * i + 1,
                2 * i + 2
            )
        })?;
    }
    Ok(key)
}

impl PilEcuArgs {
    /// The link key: `--link-key`, else `ECU_LINK_KEY`, else the build's.
    pub fn link_key(&self) -> Result<LinkKey> {
        if let Some(hex) = &self.link_key {
            return parse_link_key(hex, "--link-key");
        }
        match std::env::var(LINK_KEY_VAR) {
            Ok(hex) => parse_link_key(&hex, LINK_KEY_VAR),
            Err(_) => Ok(firmware::link::LINK_KEY),
        }
    }

    /// The link fault with its start, if any.
    pub fn link_fault(&self) -> Result<Option<LinkFault>> {
        let Some(spec) = self.link_fault else {
            return Ok(None);
        };
        if !(self.link_fault_at.is_finite() && self.link_fault_at >= 0.0) {
            bail!(
                "--link-fault-at must be a time in seconds, at least 0, got {}",
                self.link_fault_at
            );
        }
        let period = CONTROL_PERIOD_US as f64 * 1e-6;
        let start_us = (self.link_fault_at / period).floor() as u64 * CONTROL_PERIOD_US;
        Ok(Some(LinkFault { spec, start_us }))
    }
}

impl PilCommand {
    /// The PIL run's settings (one value of each scenario option, checked).
    pub fn resolve(&self) -> Result<PilArgs> {
        let e = self.ecu.clone();
        let elf = e.elf.clone().unwrap_or_else(|| match e.link {
            PilLink::Semihosting => PathBuf::from(crate::pil::ECU_ELF),
            PilLink::Usart => crate::pil::built_ecu_board_elf(Path::new(".")),
        });
        Ok(PilArgs {
            run: self.run.resolve("pil")?,
            link_key: e.link_key()?,
            link_fault: e.link_fault()?,
            link: e.link,
            hil_clock: e.hil_clock,
            hil_lead_us: e.hil_lead_us,
            elf,
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
    /// The link key.
    pub link_key: LinkKey,
    /// The link fault, if any.
    pub link_fault: Option<LinkFault>,
    /// How the ECU is linked.
    pub link: PilLink,
    /// With [`PilLink::Usart`]: what keeps QEMU's clock with the host's.
    pub hil_clock: HilClock,
    /// With [`PilLink::Usart`]: the sensor frame's lead over the release, µs.
    pub hil_lead_us: u64,
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
    if args.link == PilLink::Usart {
        // What only the lock-step run measures or injects.
        if args.trace.is_some() {
            bail!("--trace: the execution trace is the lock-step PIL's (deterministic instruction counts); drop --link usart to write it");
        }
        if args.max_model_underestimate_pct.is_some() {
            bail!("--max-model-underestimate-pct: the cost model is checked against the lock-step PIL's instruction counts; drop --link usart for that check");
        }
        if args.link_fault.is_some() {
            bail!("--link-fault: injected only in the lock-step PIL so far; drop --link usart");
        }
        if !(1..=50_000).contains(&args.hil_lead_us) {
            bail!(
                "--hil-lead-us must be in 1..=50000 µs, got {}",
                args.hil_lead_us
            );
        }
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
    if args.link == PilLink::Usart {
        return run_usart(args);
    }
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
        link_key: args.link_key,
        link_fault: args.link_fault,
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
    let tick_overruns = ecu.tick_overruns;
    let ecu_counts = ecu.ecu_counts;
    let mut injected = ecu.injected;
    let (done, counters) = match &result {
        Ok(_) => {
            let (done, counters) = ecu.stop()?;
            if args.link_fault.is_some_and(|f| f.route_frames().is_some()) {
                injected.judge_by_counts(&done.refused);
            }
            (Some(done), counters)
        }
        Err(_) => (None, ecu.counters),
    };
    let mut result = result?;
    result.summary.link = Some(PilLink::Semihosting.name().into());
    let done = done.unwrap_or(DoneFrame {
        stack_high_water_bytes: 0,
        stack_size_bytes: 0,
        rejected_frames: 0,
        refused: RefusalCounts::new(),
    });
    // The ECU's refusals at its end (the Done frame's: the last word), and the
    // host's of the ECU's frames.
    {
        let s = &mut result.summary;
        s.ecu_frames_refused_auth = Some(done.refused.auth.into());
        s.ecu_frames_refused_replay = Some(done.refused.replay.into());
        s.ecu_frames_refused_corrupt = Some(done.refused.corrupt.into());
        s.host_frames_refused_auth = Some(counters.refused.auth.into());
        s.host_frames_refused_replay = Some(counters.refused.replay.into());
        s.host_frames_refused_corrupt = Some(counters.refused.corrupt.into());
    }
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
        let host = in_process_run(args.link_fault, &scenario, &vehicle, &plant_car, &opts)?;
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
        ecu_refused_frames: done.refused,
        host_rejected_frames: counters.rejected,
        host_refused_frames: counters.refused,
        link_fault: args.link_fault.map(|f| LinkFaultReport {
            fault: f.spec.to_string(),
            start_s: f.start_us as f64 * 1e-6,
            frames: injected,
        }),
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
    print_pil(args, &scenario, s, &report, &done, &counters, &injected);
    if let Some(f) = args.link_fault {
        check_link_fault(f, s, &done, &injected)?;
    }
    if !report.count_mismatches.is_empty() {
        bail!(
            "the ECU's own deadline counts differ from the host's: {} (pil.json: count_mismatches)",
            report.count_mismatches.join("; ")
        );
    }
    if let Some(limit) = args.max_model_underestimate_pct {
        let e = &report.model_error;
        if e.max_under_pct > limit {
            bail!(
                "the cost model underestimates a measured plan activation by {:.1} % (> {limit} %): refit it (`host-sim wcet` writes cost_model.json) and update CostModel::default",
                e.max_under_pct
            );
        }
    }
    Ok(())
}

/// Fails when a link fault's frames were not all refused for their reason and
/// counted by the ECU, when a legitimate frame was refused, or when the run
/// stopped before its end.
fn check_link_fault(
    f: LinkFault,
    s: &Summary,
    done: &DoneFrame,
    injected: &InjectedFrames,
) -> Result<()> {
    let expected = u64::from(injected.injected.total());
    let counted = Refusal::ALL
        .iter()
        .all(|&r| done.refused.of(r) >= injected.injected.of(r));
    if injected.acted_on > 0
        || injected.refused_as_expected != expected
        || injected.legitimate_refused > 0
        || !counted
    {
        bail!(
            "link fault {}: of {expected} frames injected, the ECU refused {} for their reason and acted on {}; it refused {} legitimate frames; its own counts: {:?} against {:?} injected (pil.json: link_fault)",
            f.spec,
            injected.refused_as_expected,
            injected.acted_on,
            injected.legitimate_refused,
            done.refused,
            injected.injected
        );
    }
    if !s.completed && s.stop_reason != timeline::TIME_LIMIT_REASON {
        bail!(
            "link fault {}: the run stopped before its end ({}): the dropout policy (or, for route frames, the window the ECU holds) should carry the car through {} refused frames",
            f.spec,
            s.stop_reason,
            f.spec.frames
        );
    }
    Ok(())
}

/// The lines `host-sim pil` prints at the end of a lock-step run: the lap, the
/// ECU's figures, the comparison, the deadlines, the refusals, the link fault.
fn print_pil(
    args: &PilArgs,
    scenario: &Scenario,
    s: &Summary,
    report: &PilReport,
    done: &DoneFrame,
    counters: &LinkCounters,
    injected: &InjectedFrames,
) {
    println!("{}", summary_line(scenario, s));
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
        report.tick_overruns.plan,
        opt(s.ecu_control_deadline_misses),
        s.control_deadline_misses,
        opt(s.ecu_control_skipped_releases),
        s.control_skipped_releases,
        opt(s.ecu_control_budget_overruns),
        report.tick_overruns.control,
        opt(s.ecu_watchdog_trips),
        opt(report.ecu_counts.map(|c| c.plan.max_response_us)),
        opt(report.ecu_counts.map(|c| c.control.max_response_us)),
    );
    let r = |c: RefusalCounts| {
        format!(
            "auth {}, replay {}, corrupt {}",
            c.auth, c.replay, c.corrupt
        )
    };
    println!(
        "frames refused by reason: ECU {}; host {}",
        r(done.refused),
        r(counters.refused)
    );
    if let Some(f) = args.link_fault {
        println!(
            "link fault {} from {:.2} s: {} frames injected, {} refused for their reason by the ECU, {} acted on; {} legitimate frames refused",
            f.spec,
            f.start_us as f64 * 1e-6,
            injected.injected.total(),
            injected.refused_as_expected,
            injected.acted_on,
            injected.legitimate_refused
        );
    }
    println!(
        "PIL wall time {:.1} s; wrote {}",
        report.wall_s,
        args.run.out.display()
    );
}

/// The in-process run `host-sim pil` compares the ECU's with: the same
/// scenario, with the link fault's refused sensor frames as a dropout of the
/// same periods (to the ECU, periods without an estimate) and its refused route
/// frames dropped as the ECU drops them.
fn in_process_run(
    fault: Option<LinkFault>,
    scenario: &Scenario,
    vehicle: &VehicleParams,
    plant_car: &VehicleParams,
    opts: &SimOptions,
) -> Result<RunResult> {
    Ok(match fault.and_then(|f| f.dropout()) {
        None => {
            let mut host_ecu = SimulatedEcu::<f32>::new(scenario, vehicle, opts)?;
            if let Some(r) = fault.and_then(|f| f.route_frames()) {
                host_ecu.refuse_route_frames(r);
            }
            timeline::run_with(scenario, plant_car, opts, &mut host_ecu, |_, _| {})?
        }
        Some(dropout) => {
            let d = Disturbances {
                dropout: Some(dropout),
                ..Disturbances::default()
            };
            let mut host_ecu = DisturbedEcu::<f32>::new(scenario, vehicle, opts, d)?;
            timeline::run_with(scenario, plant_car, opts, &mut host_ecu, |_, _| {})?
        }
    })
}

/// `host-sim pil --link usart`: the binary you flash in QEMU, its USART1 piped to
/// the simulator, the plant stepped on the host's clock ([`crate::pil::usart`]).
/// Writes what `run` writes (`summary.json` with `"link": "usart"` and `hil`,
/// the link's figures); no `pil.json` and no comparison with the in-process run
/// (a real-time run is not deterministic: it is said, not done).
pub fn run_usart(args: &PilArgs) -> Result<()> {
    let SetUp {
        scenario,
        nominal: vehicle,
        plant_car,
        mut opts,
        ..
    } = prepare(&args.run)?;
    opts.cycles_per_instruction = args.cpi;
    let usart = UsartOptions {
        elf: args.elf.clone(),
        qemu: args.qemu.clone(),
        clock: args.hil_clock,
        icount_shift: args.icount_shift,
        work_dir: args.run.out.join("ecu"),
        frame_timeout_s: args.frame_timeout,
        cycles_per_instruction: args.cpi,
        link_key: args.link_key,
        lead_us: args.hil_lead_us,
    };
    if !args.no_compare {
        eprintln!("--link usart: a real-time run is not deterministic, so it is not compared with the in-process run (the lock-step PIL is that check)");
    }
    let wall = std::time::Instant::now();
    let mut ecu = UsartEcu::start(&scenario, &vehicle, &opts, &usart)?;
    let result = timeline::run_with(&scenario, &plant_car, &opts, &mut ecu, |_, _| {});
    let (done, ecu) = match result {
        Ok(_) => {
            let (done, ecu) = ecu.stop()?;
            (Some(done), ecu)
        }
        Err(_) => (None, ecu),
    };
    let mut result = result?;
    let done = done.unwrap_or(DoneFrame {
        stack_high_water_bytes: 0,
        stack_size_bytes: 0,
        rejected_frames: 0,
        refused: RefusalCounts::new(),
    });
    let wall_s = wall.elapsed().as_secs_f64();
    ecu.write_frames()?;
    let hil = ecu.summary(wall_s);
    {
        let s = &mut result.summary;
        s.link = Some(PilLink::Usart.name().into());
        // The host's recount of the control task's misses, from every frame.
        s.control_deadline_misses = ecu.hil.control_deadline_misses;
        s.control_skipped_releases = ecu.hil.control_skipped_releases;
        s.ecu_frames_refused_auth = Some(done.refused.auth.into());
        s.ecu_frames_refused_replay = Some(done.refused.replay.into());
        s.ecu_frames_refused_corrupt = Some(done.refused.corrupt.into());
        s.host_frames_refused_auth = Some(ecu.host_refused.auth.into());
        s.host_frames_refused_replay = Some(ecu.host_refused.replay.into());
        s.host_frames_refused_corrupt = Some(ecu.host_refused.corrupt.into());
        s.hil = Some(hil.clone());
    }
    write_outputs(&args.run.out, &scenario, &result, !args.run.no_plots)?;
    let s = &result.summary;
    println!("{}", summary_line(&scenario, s));
    if let Some(line) = plant_line(s) {
        println!("{line}");
    }
    if !s.completed {
        println!("stopped: {}", s.stop_reason);
    }
    let opt = |x: Option<u64>| x.map_or("-".to_string(), |v| v.to_string());
    let spread = |x: &crate::closed_loop::summary::Spread| {
        format!(
            "min {:.0} / median {:.0} / p99 {:.0} / max {:.0} µs",
            x.min, x.median, x.p99, x.max
        )
    };
    println!(
        "real-time HIL over the emulated USART ({}, lead {} µs): {} sensor frames sent, {} actuation frames received ({} answers, {} late), {} sensor frames missing at the ECU's release, {} refused by it; {} periods without an actuation frame, {} without an ECU release (not fed); {} plan events",
        hil.qemu_clock,
        hil.lead_us,
        hil.sensor_frames_sent,
        hil.actuation_frames_received,
        hil.answers,
        hil.late_answers,
        hil.sensor_missing_at_ecu,
        hil.sensor_refused_at_ecu,
        hil.periods_without_frame,
        hil.periods_not_fed,
        hil.plan_events
    );
    println!(
        "deadlines, the ECU's own count: control misses {}, skipped releases {}; plan misses {}, skipped releases {}; budget overruns control {}, plan {}; watchdog trips {} (host's recount: control misses {}, plan misses {})",
        opt(s.ecu_control_deadline_misses),
        opt(s.ecu_control_skipped_releases),
        opt(s.ecu_plan_deadline_misses),
        opt(s.ecu_skipped_releases),
        opt(s.ecu_control_budget_overruns),
        opt(s.ecu_plan_budget_overruns),
        opt(s.ecu_watchdog_trips),
        s.control_deadline_misses,
        s.plan_deadline_misses,
    );
    println!(
        "control response (ECU): {}",
        spread(&hil.control_response_us)
    );
    println!("plan response (ECU): {}", spread(&hil.plan_response_us));
    println!(
        "round trip sensor → actuation (host): {}",
        spread(&hil.round_trip_us)
    );
    println!(
        "lead at the ECU's release: {}",
        spread(&hil.lead_at_release_us)
    );
    let r = |c: RefusalCounts| {
        format!(
            "auth {}, replay {}, corrupt {}",
            c.auth, c.replay, c.corrupt
        )
    };
    println!(
        "frames refused by reason: ECU {}; host {}; stack high-water {} of {} B; clock offset drift {} µs",
        r(done.refused),
        r(ecu.host_refused),
        done.stack_high_water_bytes,
        done.stack_size_bytes,
        hil.clock_offset_drift_us
            .map_or("-".to_string(), |d| format!("{d:.0}"))
    );
    println!(
        "HIL wall time {:.1} s for {:.1} s simulated; wrote {}",
        wall_s,
        s.duration_s,
        args.run.out.display()
    );
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::pil::link_fault::{FaultKinds, LinkChannel, LinkFaultSpec};

    fn fault() -> LinkFault {
        LinkFault {
            spec: LinkFaultSpec {
                channel: LinkChannel::Route,
                kinds: FaultKinds::Mix,
                frames: 3,
            },
            start_us: 5_800_000,
        }
    }

    fn done(refused: RefusalCounts) -> DoneFrame {
        DoneFrame {
            stack_high_water_bytes: 0,
            stack_size_bytes: 0,
            rejected_frames: refused.total(),
            refused,
        }
    }

    #[test]
    fn a_link_fault_fails_the_run_when_a_frame_is_taken_or_the_run_stops_early() {
        let expected = FaultKinds::Mix.refusals(3);
        let mut injected = InjectedFrames {
            injected: expected,
            ..InjectedFrames::default()
        };
        injected.judge_by_counts(&expected);
        let ended = Summary {
            completed: false,
            stop_reason: timeline::TIME_LIMIT_REASON.into(),
            ..Summary::default()
        };
        assert!(check_link_fault(fault(), &ended, &done(expected), &injected).is_ok());
        // A run that stopped before its end fails, saying why.
        let stopped = Summary {
            stop_reason: "left the road at 12.0 s".into(),
            ..ended.clone()
        };
        let e = check_link_fault(fault(), &stopped, &done(expected), &injected)
            .unwrap_err()
            .to_string();
        assert!(e.contains("left the road"), "{e}");
        // A forged frame the ECU did not refuse fails.
        let mut short = RefusalCounts::new();
        short.count(Refusal::Replay);
        short.count(Refusal::Corrupt);
        let mut taken = InjectedFrames {
            injected: expected,
            ..InjectedFrames::default()
        };
        taken.judge_by_counts(&short);
        let e = check_link_fault(fault(), &ended, &done(short), &taken)
            .unwrap_err()
            .to_string();
        assert!(e.contains("acted on 1"), "{e}");
    }
}
