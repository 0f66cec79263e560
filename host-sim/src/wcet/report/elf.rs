//! What the ECU ELF's sections and symbol table say: flash and static-RAM sizes
//! by where each section lives, and whether a heap allocator or software
//! double-precision routines were linked in.

use crate::wcet::{parse_elf, read_elf};
use anyhow::{ensure, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Section sizes of the ECU ELF, in bytes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ElfMemory {
    /// `.vector_table`, in bytes (flash).
    pub vector_table_bytes: u64,
    /// `.text`, in bytes (flash).
    pub text_bytes: u64,
    /// Read-only data left in flash (`.rodata`), in bytes.
    pub rodata_bytes: u64,
    /// Initialised RAM: `.data` and read-only data copied to SRAM (`.rodata_ram`),
    /// in bytes (RAM, and their initial values in flash).
    pub data_bytes: u64,
    /// `.bss` plus `.uninit` (both zero- or un-initialised RAM), in bytes.
    pub bss_bytes: u64,
    /// `.uninit` alone (already in `bss_bytes`), in bytes.
    pub uninit_bytes: u64,
}

impl ElfMemory {
    /// Static RAM: initialised (`.data`, `.rodata_ram`) + `.bss` + `.uninit`, in bytes.
    pub fn static_ram_bytes(&self) -> u64 {
        self.data_bytes + self.bss_bytes
    }

    /// Flash image: `.vector_table` + `.text` + `.rodata` + `.data` (its load
    /// image), in bytes.
    pub fn flash_bytes(&self) -> u64 {
        self.vector_table_bytes + self.text_bytes + self.rodata_bytes + self.data_bytes
    }
}

/// What the symbol table says about the ECU ELF.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ElfSymbols {
    /// A heap allocator is linked in (any of [`ALLOCATOR_SYMBOLS`] is defined).
    pub allocator: bool,
    /// Software double-precision routines are linked in (`__aeabi_d*`,
    /// `__adddf3`, `__muldf3`, `__divdf3`).
    pub soft_double: bool,
    /// The symbols that set `allocator`.
    pub allocator_symbols: Vec<String>,
    /// The symbols that set `soft_double`.
    pub soft_double_symbols: Vec<String>,
}

/// Symbols whose definition means a heap allocator is in the binary.
pub const ALLOCATOR_SYMBOLS: [&str; 5] = [
    "__rust_alloc",
    "__rust_dealloc",
    "__rdl_alloc",
    "malloc",
    "free",
];

fn is_soft_double(name: &str) -> bool {
    name.starts_with("__aeabi_d") || ["__adddf3", "__muldf3", "__divdf3"].contains(&name)
}

/// The ECU's SRAM, `[start, end)` (memory.x: 128 KiB at 0x2000_0000).
const RAM_START: u64 = 0x2000_0000;
/// One past the ECU's SRAM.
const RAM_END: u64 = 0x2002_0000;

/// Section sizes of an ELF, by where each allocated section lives rather than by
/// its name: the vector table; executable code (`.text`); read-only data left in
/// flash (`.rodata`, empty when `memory.x` copies it to SRAM); initialised RAM
/// (`.data`, and `.rodata_ram`: read-only data copied to SRAM at reset); zeroed
/// and uninitialised RAM (`.bss`, `.uninit`).
pub fn elf_memory(elf: &Path) -> Result<ElfMemory> {
    use object::{Object, ObjectSection, SectionKind};
    let data = read_elf(elf)?;
    let file = parse_elf(elf, &data)?;
    let mut memory = ElfMemory::default();
    for s in file.sections() {
        let alloc = crate::wcet::allocated(s.flags()).unwrap_or(false);
        if !alloc || s.size() == 0 {
            continue;
        }
        let name = s.name().unwrap_or("");
        let in_ram = (RAM_START..RAM_END).contains(&s.address());
        match s.kind() {
            _ if name == ".vector_table" => memory.vector_table_bytes += s.size(),
            SectionKind::Text => memory.text_bytes += s.size(),
            SectionKind::UninitializedData | SectionKind::UninitializedTls if in_ram => {
                memory.bss_bytes += s.size();
                if name == ".uninit" {
                    memory.uninit_bytes += s.size();
                }
            }
            _ if in_ram => memory.data_bytes += s.size(),
            _ => memory.rodata_bytes += s.size(),
        }
    }
    ensure!(
        memory.text_bytes > 0,
        "{} has no .text section: is it the ECU binary (not a library or a stripped file)?",
        elf.display()
    );
    Ok(memory)
}

/// The section the ECU binary keeps its caps in (`firmware/src/bin/ecu.rs`'s
/// `ECU_CAPS`, not loaded: `memory.x`).
pub const CAPS_SECTION: &str = ".ecu_caps";

/// The plan task's caps as the ECU binary was built with them: the flow facts
/// its static bound rests on, read from the binary itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Caps {
    /// QP iterations per activation, summed over its passes, iterations.
    pub qp_max_iterations: u32,
    /// Linearise–solve passes on a cold start, passes.
    pub cold_start_passes: u32,
    /// QP refactorizations per activation, refactorizations.
    pub qp_max_refactorizations: u32,
    /// The QP's working set, rows.
    pub working_set: u32,
}

/// The caps of a [`CAPS_SECTION`]'s bytes: four little-endian `u32` in
/// [`Caps`]' order.
pub fn caps_of(bytes: &[u8]) -> Result<Caps> {
    ensure!(
        bytes.len() == 16,
        "{CAPS_SECTION} holds {} bytes, not the 16 of four u32: a binary of another version of firmware/src/bin/ecu.rs",
        bytes.len()
    );
    let word = |k: usize| {
        let mut w = [0u8; 4];
        w.copy_from_slice(&bytes[4 * k..4 * k + 4]);
        u32::from_le_bytes(w)
    };
    Ok(Caps {
        qp_max_iterations: word(0),
        cold_start_passes: word(1),
        qp_max_refactorizations: word(2),
        working_set: word(3),
    })
}

/// The ECU binary's caps ([`CAPS_SECTION`]); `None` for an ELF without the
/// section (not the ECU application).
pub fn elf_caps(elf: &Path) -> Result<Option<Caps>> {
    use object::{Object, ObjectSection};
    let data = read_elf(elf)?;
    let file = parse_elf(elf, &data)?;
    let Some(section) = file.section_by_name(CAPS_SECTION) else {
        return Ok(None);
    };
    let bytes = section
        .data()
        .map_err(|e| anyhow::anyhow!("{}: {CAPS_SECTION}: {e}", elf.display()))?;
    caps_of(bytes).map(Some)
}

/// Allocator and software-double symbols of an ELF.
pub fn elf_symbols(elf: &Path) -> Result<ElfSymbols> {
    use object::{Object, ObjectSymbol};
    let data = read_elf(elf)?;
    let file = parse_elf(elf, &data)?;
    let mut out = ElfSymbols::default();
    for symbol in file.symbols() {
        let Ok(name) = symbol.name() else { continue };
        if symbol.is_definition() && ALLOCATOR_SYMBOLS.contains(&name) {
            out.allocator_symbols.push(name.to_string());
        }
        if is_soft_double(name) {
            out.soft_double_symbols.push(name.to_string());
        }
    }
    out.allocator_symbols.sort();
    out.allocator_symbols.dedup();
    out.soft_double_symbols.sort();
    out.soft_double_symbols.dedup();
    out.allocator = !out.allocator_symbols.is_empty();
    out.soft_double = !out.soft_double_symbols.is_empty();
    Ok(out)
}
