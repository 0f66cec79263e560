//! Worst-case timing and memory analysis of the ECU binary (thumbv7em, Cortex-M4F).
//!
//! | module | concept |
//! |---|---|
//! | [`stack`] | static stack bound: frame sizes from `llvm-objdump` prologues, call graph, preemption levels |
//! | [`cpi`] | cycles-per-instruction bound from a QEMU execution trace and a Cortex-M4 timing table |
//! | [`report`] | the timing and memory report (`wcet.json`, `wcet.md`) from PIL runs, the ELF and the two bounds; CI comparison |
//!
//! All are library functions; the `host-sim wcet` command wires them together.

pub mod command;
pub mod cpi;
pub mod report;
pub mod stack;

use std::path::PathBuf;

/// What went wrong in a worst-case analysis, phrased so that whoever reads it knows
/// what to fix.
#[derive(Debug, thiserror::Error)]
pub enum WcetError {
    /// `llvm-objdump` of the `llvm-tools` rustup component was not found.
    #[error(
        "llvm-objdump not found at {searched}: install it with `rustup component add llvm-tools`"
    )]
    ObjdumpMissing {
        /// Where it was looked for.
        searched: PathBuf,
    },
    /// An external tool could not be started or failed.
    #[error("running {tool} failed: {message}")]
    Tool {
        /// The tool's name.
        tool: String,
        /// What it reported (its stderr, or the OS error).
        message: String,
    },
    /// A file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A root function asked for is not in the disassembly.
    #[error("no function named or starting with `{0}` in the disassembly: check the symbol name (demangled without hash, or mangled) with `llvm-nm -C`")]
    UnknownRoot(String),
    /// The ELF file could not be parsed.
    #[error("{path} is not a readable ELF file: {message}")]
    Elf {
        /// The file.
        path: PathBuf,
        /// The parser's message.
        message: String,
    },
    /// A line of a QEMU log does not have the expected format.
    #[error("QEMU log line {line}: {message}: `{text}` (expected `-d in_asm,exec,nochain` output of qemu-system-arm)")]
    LogFormat {
        /// 1-based line number in the log.
        line: u64,
        /// What was expected.
        message: String,
        /// The offending line, shortened.
        text: String,
    },
}

/// Demangles a Rust symbol (legacy or v0) without its hash; other symbols unchanged.
pub fn demangle(symbol: &str) -> String {
    format!("{:#}", rustc_demangle::demangle(symbol))
}
