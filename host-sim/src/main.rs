//! `host-sim` command line.
//!
//! One subcommand per job, each implemented in its own module of
//! `host_sim::commands`: add a variant to
//! [`Command`] and a line to `run` to add one.

use clap::{Parser, Subcommand};
use host_sim::commands;

/// Host simulator of the consistent MPC + PID vehicle controller.
#[derive(Debug, Parser)]
#[command(name = "host-sim", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Tyre forces (PAC2002 combined slip) for a CSV of slips: kappa,alpha_rad,fz_n,mu.
    Tire(commands::tire::TireArgs),
    /// The paper's Figure 3: steering of the 9-DoF plant vs the kinematic bicycle on
    /// circles, up to the speed where the car cannot hold them.
    Validity(commands::validity::ValidityArgs),
    /// A closed-loop drive: the 9-DoF plant against the firmware's two tasks on a
    /// deterministic timeline; writes log.csv, summary.json and the figures.
    Run(commands::run::RunCommand),
    /// Processor in the loop: the ECU application in QEMU against the plant; writes
    /// what `run` writes plus plan_activations.csv and pil.json (measured ECU costs).
    Pil(commands::pil::PilCommand),
    /// The ECU's worst-case timing and memory report (wcet.md, wcet.json) from PIL
    /// laps, a QEMU trace for the cycles-per-instruction bound and the ELF.
    Wcet(commands::wcet::WcetArgs),
    /// Every QP the MPC solves over a kinematic closed loop, one JSON file each (for solver benchmarks).
    QpCorpus(commands::qp_corpus::QpCorpusArgs),
    /// Many closed-loop runs: the cross product of tracks, frictions, vehicles, loads,
    /// noise, delays, faults and seeds (the options of `run`, lists here), in
    /// parallel; writes sweep.csv (one row per run), sweep.json (the aggregate),
    /// figures and summary.txt. Exits non-zero when a run could not run.
    Sweep(commands::sweep::SweepArgs),
    /// Writes the figures of the README and docs/ from the timing report
    /// (`.ci/wcet-report`'s target/ci/wcet), between their `host-sim docs` markers;
    /// `--check` fails when they differ instead.
    Docs(commands::docs::DocsArgs),
    /// Joins the sweep.csv of shards (`sweep --only I/N`) into one sweep's outputs.
    SweepMerge(commands::sweep::MergeArgs),
}

fn run(cli: &Cli) -> anyhow::Result<()> {
    match &cli.command {
        Command::Tire(args) => commands::tire::run(args),
        Command::Validity(args) => commands::validity::run(args),
        Command::Run(args) => commands::run::command(args),
        Command::QpCorpus(args) => commands::qp_corpus::run(args),
        Command::Pil(args) => commands::pil::command(args),
        Command::Wcet(args) => commands::wcet::run(args),
        Command::Sweep(args) => commands::sweep::run(args),
        Command::SweepMerge(args) => commands::sweep::merge(args),
        Command::Docs(args) => commands::docs::run(args),
    }
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    match run(&cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // The whole chain of causes on one line, without a backtrace.
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
