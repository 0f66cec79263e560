//! The ECU's layer over the timing analyser (the `wcet` crate): what the
//! analyses know of this firmware, and the timing and memory report.
//!
//! | module | concept |
//! |---|---|
//! | [`ecu_app`] | the ECU's RTIC application as a target description ([`::wcet::target::Target`]): tasks, sections, schedule, priority levels, functions run once or masked, the STM32F405's memory model |
//! | [`ecu_sources`] | the firmware's constants the loop annotations name, the dependencies' loop bounds, the annotated crates' folders |
//! | [`clock`] | the core clock as the binary sets it (`clock` in `static.json` and `wcet.json`) |
//! | [`report`] | the timing and memory report (`wcet.json`, `wcet.md`) from PIL runs, the ELF and the two bounds; CI comparison |
//!
//! The analyses themselves are the `wcet` crate's, re-exported here under
//! their module names; the `host-sim wcet` command (`commands::wcet`) wires
//! them together.

/// The ECU's core clock, Hz (STM32F405 at 168 MHz).
pub const CLOCK_HZ: u32 = firmware::timing::ECU_CLOCK_HZ;

pub mod clock;
pub mod ecu_app;
pub mod ecu_sources;
pub mod report;

pub use ::wcet::{
    allocated, analysis, annotations, bounds, cache, cfg, copies, coverage, cpi, critical,
    data_cache, demangle, flash_data, flow_facts, graph, indirect, ipet, loops, memory_model,
    parse_elf, read_elf, rta, source_lines, stack, target, trace_check, vector_table, WcetError,
};

use std::path::{Path, PathBuf};

/// The static analysis of the ECU's ELF ([`analysis::analyse`]), with the
/// target description of the build it holds ([`ecu_app::EcuBuild::of_elf`]) and
/// the loop annotations of `sources` ([`ecu_sources::workspace_sources`]).
pub fn analyse(
    elf: &Path,
    sources: &[annotations::SourceDir],
    traces: &[PathBuf],
) -> anyhow::Result<analysis::StaticAnalysis> {
    let target = ecu_app::EcuBuild::of_elf(elf)?.target_of_elf(elf)?;
    Ok(analysis::analyse(elf, &target, sources, traces)?)
}
