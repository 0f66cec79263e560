//! Worst-case timing and memory analysis of the ECU binary (thumbv7em, Cortex-M4F).
//!
//! | module | concept |
//! |---|---|
//! | [`cfg`] | control-flow graphs from the Thumb-2 disassembly; per-block worst-case cycles |
//! | [`memory_model`] | the processor and memory model the cycles are worst cases under: Cortex-M4 timing, flash lines and wait states, the ART accelerator |
//! | [`flash_data`] | which data loads can read flash (the ELF's sections, the ways code forms addresses) |
//! | [`cache`] | the ART accelerator's instruction cache: loops whose lines stay cached fetch each once per entry (persistence) |
//! | [`data_cache`] | the ART accelerator's data cache: the literal-pool loads that hit on every path (LRU must analysis) |
//! | [`indirect`] | the targets of indirect calls, read from the binary: the functions whose address its data, literal pools or movw/movt pairs hold |
//! | [`loops`] | dominators and natural loops; irreducible cycles refused |
//! | [`graph`] | strongly connected components (recursion, irreducible cycles) |
//! | [`bounds`] | loop bounds recognised from the binary (counted loops) |
//! | [`annotations`] | loop bounds written beside the loops in the firmware source (`// wcet-bound: EXPR`), matched through the DWARF line table |
//! | [`coverage`] | the loops no trace executed, each with the reason read off the traces |
//! | [`copies`] | block copies and fills: the functions and the bytes each call site moves |
//! | [`flow_facts`] | the bounds over more than one loop entry (per activation, per call, counters, capped lines, retries), each with what it counts, checked on the traces |
//! | [`ipet`] | implicit path enumeration: a task's bound as a linear program (`good_lp`, `microlp`) |
//! | [`rta`] | response-time analysis, fixed priorities with RTIC's stack resource policy |
//! | [`clock`] | the core clock as the binary sets it (`clock` in `static.json` and `wcet.json`) |
//! | [`ecu_app`] | what the analyses know of the ECU's RTIC application: tasks, sections, schedule, priority levels, functions run once or masked |
//! | [`analysis`] | the static analysis put together (`static.json`, `static.md`) |
//! | [`trace_check`] | QEMU execution traces replayed against the graphs: loop trip counts per entry, activation costs with the same block costs |
//! | [`stack`] | static stack bound: frame sizes from `llvm-objdump` prologues, call graph, preemption levels, every vector-table handler |
//! | [`vector_table`] | the ELF's exception vector table: the handler of each exception |
//! | [`critical`] | the critical sections of the tasks' code (interrupts disabled, RTIC locks) and their bounds: the RTA's blocking |
//! | [`cpi`] | cycles-per-instruction bound from a QEMU execution trace and a Cortex-M4 timing table |
//! | [`report`] | the timing and memory report (`wcet.json`, `wcet.md`) from PIL runs, the ELF and the two bounds; CI comparison |
//!
//! All are library functions; the `host-sim wcet` command (`commands::wcet`) wires them together.

/// The ECU's core clock, Hz (STM32F405 at 168 MHz).
pub const CLOCK_HZ: u32 = firmware::timing::ECU_CLOCK_HZ;

pub mod analysis;
pub mod annotations;
pub mod bounds;
pub mod cache;
pub mod cfg;
pub mod clock;
pub mod copies;
pub mod coverage;
pub mod cpi;
pub mod critical;
pub mod data_cache;
pub mod ecu_app;
pub mod flash_data;
pub mod flow_facts;
pub mod graph;
pub mod indirect;
pub mod ipet;
pub mod loops;
pub mod memory_model;
pub mod report;
pub mod rta;
pub mod stack;
pub mod trace_check;
pub mod vector_table;

use std::path::{Path, PathBuf};

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

/// The bytes of an ELF file.
pub fn read_elf(elf: &Path) -> Result<Vec<u8>, WcetError> {
    std::fs::read(elf).map_err(|source| WcetError::Io {
        path: elf.to_path_buf(),
        source,
    })
}

/// Parses the bytes [`read_elf`] read.
pub fn parse_elf<'d>(elf: &Path, data: &'d [u8]) -> Result<object::File<'d>, WcetError> {
    object::File::parse(data).map_err(|e| WcetError::Elf {
        path: elf.to_path_buf(),
        message: e.to_string(),
    })
}

/// Whether an ELF section occupies memory on the target (`SHF_ALLOC`); `None` for
/// a section of another object format, which has no such flag.
pub fn allocated(flags: object::SectionFlags) -> Option<bool> {
    match flags {
        object::SectionFlags::Elf { sh_flags } => {
            Some(sh_flags & u64::from(object::elf::SHF_ALLOC) != 0)
        }
        _ => None,
    }
}

/// Demangles a Rust symbol (legacy or v0) without its hash; other symbols unchanged.
pub fn demangle(symbol: &str) -> String {
    format!("{:#}", rustc_demangle::demangle(symbol))
}
