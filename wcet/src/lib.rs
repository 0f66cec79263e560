//! Static worst-case timing and stack analysis of Thumb-2 / Cortex-M4 ELF files.
//!
//! The analyser reads a binary (its disassembly from `llvm-objdump`, its symbols,
//! sections and DWARF line table) and a [`target::Target`] description the caller builds:
//! the core's clock, the memory map and its model (flash wait states and lines),
//! the roots (tasks and interrupts) with their priorities and schedule, the
//! sections bounded apart, the stack's priority levels, and the source folders
//! and constants of the flow facts (loop annotations). It knows nothing of any
//! one program: `host-sim` describes its ECU and writes the reports.
//!
//! | module | concept |
//! |---|---|
//! | [`target`] | the target description: roots, schedule, clock, memory model, flow facts' constants |
//! | [`error`] | the crate's one error type, [`WcetError`] (an IPET's refusal, [`IpetError`], is one of its kinds) |
//! | [`disassembly`] | the `llvm-objdump` disassembly parsed: functions, instructions, the data between them |
//! | [`cfg`] | control-flow graphs from the Thumb-2 disassembly; per-block worst-case cycles |
//! | [`memory_model`] | the processor and memory model the cycles are worst cases under: Cortex-M4 timing, flash lines and wait states, the flash accelerator |
//! | [`flash_data`] | which data loads can read flash (the ELF's sections, the ways code forms addresses) |
//! | [`cache`] | the flash accelerator's instruction cache: loops whose lines stay cached fetch each once per entry (persistence) |
//! | [`data_cache`] | the flash accelerator's data cache: the literal-pool loads that hit on every path (LRU must analysis) |
//! | [`indirect`] | the targets of indirect calls, read from the binary: the functions whose address its data, literal pools or movw/movt pairs hold |
//! | [`loops`] | dominators and natural loops; irreducible cycles refused |
//! | [`graph`] | strongly connected components (recursion, irreducible cycles) |
//! | [`bounds`] | loop bounds recognised from the binary (counted loops) |
//! | [`annotations`] | loop bounds written beside the loops in the target's source (`// wcet-bound: EXPR`), matched through the DWARF line table |
//! | [`source_lines`] | source locations of addresses from the DWARF line table |
//! | [`coverage`] | the loops no trace executed, each with the reason read off the traces |
//! | [`copies`] | block copies and fills: the functions and the bytes each call site moves |
//! | [`flow_facts`] | the bounds over more than one loop entry (per activation, per call, counters, capped lines, retries), each with what it counts, checked on the traces |
//! | [`ipet`] | implicit path enumeration: a task's bound as a linear program (`good_lp`, `microlp`) |
//! | [`rta`] | response-time analysis, fixed priorities with the stack resource policy |
//! | [`analysis`] | the static analysis put together (`static.json`, `static.md`) |
//! | [`trace_check`] | QEMU execution traces replayed against the graphs: loop trip counts per entry, activation costs with the same block costs |
//! | [`stack`] | static stack bound: frame sizes from `llvm-objdump` prologues, call graph, preemption levels, every vector-table handler |
//! | [`vector_table`] | the ELF's exception vector table: the handler of each exception |
//! | [`critical`] | the critical sections of the tasks' code (interrupts disabled, locks) and their bounds: the RTA's blocking |
//! | [`cpi`] | cycles-per-instruction bound from a QEMU execution trace and a Cortex-M4 timing table |

pub mod analysis;
pub mod annotations;
pub mod bounds;
pub mod cache;
pub mod cfg;
pub mod copies;
pub mod coverage;
pub mod cpi;
pub mod critical;
pub mod data_cache;
pub mod disassembly;
pub mod error;
pub mod flash_data;
pub mod flow_facts;
pub mod graph;
pub mod indirect;
pub mod ipet;
pub mod loops;
pub mod memory_model;
pub mod rta;
pub mod source_lines;
pub mod stack;
pub mod target;
pub mod trace_check;
pub mod vector_table;

use std::path::Path;

pub use error::{IpetError, WcetError};

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
