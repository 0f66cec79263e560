//! The crate's one error type ([`WcetError`]), and why an IPET bound could not
//! be computed ([`IpetError`], one of its kinds).

use std::path::PathBuf;

/// What went wrong in a worst-case analysis, phrased so that whoever reads it knows
/// what to fix: the one error type of the crate's functions.
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
    /// A file or folder could not be written.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file or folder.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A root function asked for is not in the disassembly.
    #[error("no function named or starting with `{0}` in the disassembly: check the symbol name (demangled without hash, or mangled) with `llvm-nm -C`")]
    UnknownRoot(String),
    /// The ELF's DWARF line table could not be read.
    #[error("DWARF line table of {path}: {message}")]
    Dwarf {
        /// The file.
        path: PathBuf,
        /// The reader's message.
        message: String,
    },
    /// The ELF file could not be parsed.
    #[error("{path} is not a readable ELF file: {message}")]
    Elf {
        /// The file.
        path: PathBuf,
        /// The parser's message.
        message: String,
    },
    /// A loop annotation (`// wcet-bound: ...`) that cannot be read or does not
    /// fit the binary, or a target constant it names that is not one.
    #[error("{0}")]
    Annotation(String),
    /// The analysis refused the binary or its description: a task or section
    /// whose function is missing, a loop bound that cannot hold, a goal that
    /// names no task.
    #[error("{0}")]
    Analysis(String),
    /// A function's graph has a cycle with more than one entry (no header to
    /// bound): its blocks.
    #[error("irreducible cycle through blocks {0:?}")]
    Irreducible(Vec<usize>),
    /// No IPET bound (a loop without a bound, a recursion, the solver).
    #[error(transparent)]
    Ipet(#[from] IpetError),
    /// A report could not be encoded.
    #[error("encoding JSON: {0}")]
    Json(#[from] serde_json::Error),
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

/// Why no bound could be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IpetError {
    /// Loops reachable from the task without a bound.
    #[error("{} loop(s) without a bound: {}", .0.len(), .0.join("; "))]
    Unbounded(Vec<String>),
    /// The call graph is recursive.
    #[error("recursion: {}", .0.join(" -> "))]
    Recursion(Vec<String>),
    /// The linear program could not be solved.
    #[error("the IPET linear program failed: {0}")]
    Solver(String),
}
