//! The exception vector table of a Cortex-M ELF (`.vector_table`): word 0 the
//! initial stack pointer, then word `n` the handler of exception number `n`
//! (1 `Reset`, 2 NMI, 3 HardFault, 4–15 the other system exceptions, 16 + k
//! interrupt k), a Thumb address (bit 0 set), 0 for a reserved or unused entry.
//!
//! The stack bound places every handler it lists ([`super::stack`]); the trace
//! check recognises exception entries at them ([`super::trace_check`]).

use super::cfg::Program;
use super::WcetError;
use serde::Serialize;
use std::path::Path;

/// Exception number of `Reset` (thread mode's entry).
pub const RESET: u32 = 1;
/// Exception number of the non-maskable interrupt.
pub const NMI: u32 = 2;
/// Exception number of HardFault.
pub const HARD_FAULT: u32 = 3;
/// Exception number of the first external interrupt (IRQ 0).
pub const FIRST_IRQ: u32 = 16;

/// One entry of the vector table that names a handler.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct VectorEntry {
    /// Exception number (the word's index in the table).
    pub exception: u32,
    /// The handler's address, Thumb bit cleared.
    pub address: u32,
}

impl VectorEntry {
    /// The entry's exception name ([`exception_name`]).
    pub fn name(&self) -> String {
        exception_name(self.exception)
    }
}

/// ARMv7-M name of exception number `n`: `Reset`, `NMI`, `HardFault`,
/// `MemManage`, `BusFault`, `UsageFault`, `SVCall`, `DebugMonitor`, `PendSV`,
/// `SysTick`, `IRQ k` for `n = 16 + k`, `reserved n` otherwise.
pub fn exception_name(n: u32) -> String {
    match n {
        RESET => "Reset".into(),
        NMI => "NMI".into(),
        HARD_FAULT => "HardFault".into(),
        4 => "MemManage".into(),
        5 => "BusFault".into(),
        6 => "UsageFault".into(),
        11 => "SVCall".into(),
        12 => "DebugMonitor".into(),
        14 => "PendSV".into(),
        15 => "SysTick".into(),
        n if n >= FIRST_IRQ => format!("IRQ {}", n - FIRST_IRQ),
        n => format!("reserved {n}"),
    }
}

/// The handlers of `words`, a vector table's words: every entry from `Reset` on
/// whose word is not 0, in exception order.
pub fn vector_entries(words: &[u32]) -> Vec<VectorEntry> {
    words
        .iter()
        .enumerate()
        .skip(RESET as usize)
        .filter(|(_, &w)| w != 0)
        .map(|(n, &w)| VectorEntry {
            exception: n as u32,
            address: w & !1,
        })
        .collect()
}

/// The handlers of `elf`'s `.vector_table` ([`vector_entries`]).
pub fn read_vector_table(elf: &Path) -> Result<Vec<VectorEntry>, WcetError> {
    use object::{Object, ObjectSection};
    let data = super::read_elf(elf)?;
    let file = super::parse_elf(elf, &data)?;
    let section = file
        .section_by_name(".vector_table")
        .ok_or_else(|| WcetError::Elf {
            path: elf.to_path_buf(),
            message: "no .vector_table section (cortex-m-rt's link.x places the \
                      vector table there)"
                .to_string(),
        })?;
    let bytes = section.data().map_err(|e| WcetError::Elf {
        path: elf.to_path_buf(),
        message: e.to_string(),
    })?;
    let words: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Ok(vector_entries(&words))
}

/// The exception handlers of an ELF's vector table as function indices of
/// `program`, without `Reset`, each once (entries whose address starts no
/// function of `program` are left out).
pub fn vector_table_handlers(elf: &Path, program: &Program) -> Result<Vec<usize>, WcetError> {
    let entries = read_vector_table(elf)?;
    let reset = entries
        .iter()
        .find(|e| e.exception == RESET)
        .map(|e| e.address);
    let mut out: Vec<usize> = entries
        .iter()
        .filter(|e| e.exception != RESET && Some(e.address) != reset)
        .filter_map(|e| program.at(e.address))
        .collect();
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_skip_the_stack_pointer_and_the_empty_words() {
        let words = [0x2002_0000, 0x0800_01a9, 0x0800_0301, 0, 0x0800_0401];
        let entries = vector_entries(&words);
        assert_eq!(
            entries,
            vec![
                VectorEntry {
                    exception: 1,
                    address: 0x0800_01a8
                },
                VectorEntry {
                    exception: 2,
                    address: 0x0800_0300
                },
                VectorEntry {
                    exception: 4,
                    address: 0x0800_0400
                },
            ]
        );
        let names: Vec<String> = entries.iter().map(VectorEntry::name).collect();
        assert_eq!(names, ["Reset", "NMI", "MemManage"]);
        assert_eq!(exception_name(53), "IRQ 37");
        assert_eq!(exception_name(7), "reserved 7");
    }
}
