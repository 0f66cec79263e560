//! Which loads can read flash: the part of the memory model that decides whether a
//! data load pays the flash's wait states.
//!
//! A load reads flash only if its address is in flash. The ECU's linker script
//! (`memory.x`) copies `.rodata` to SRAM with `.data`, so the ELF holds no data in
//! flash except the vector table (read by the core on exception entry) and the
//! load images of the RAM sections (read by the reset handler). What is left in
//! flash that code can read is the code's own constant pools inside `.text`:
//!
//! * literal pools, read by pc-relative loads (`ldr r0, [pc, #8]`,
//!   `vldr s0, [pc, #16]`) and table branches (`tbb`, `tbh`): always charged;
//! * constant islands whose address a function forms with `adr` (a table of
//!   floats, `atanf`'s coefficients): every load of that function, and of every
//!   function it calls, is charged, since the pointer is in a register there.
//!
//! Any other way to a flash address makes every load pessimistic again, so the
//! check looks at the whole binary, not only at the tasks:
//!
//! * an allocated, non-executable section placed in flash other than the vector
//!   table (`.rodata` left in flash by another linker script);
//! * code outside the reset handler (the ELF's entry point) that forms an even flash address (a data
//!   pointer: Thumb function pointers are odd) from a literal-pool word or a
//!   `movw`/`movt` pair;
//! * `add rN, pc` (position-independent code), or an indirect call in a function
//!   that forms a flash address with `adr` (the pointer could reach any callee).

use super::disassembly::{parse_imm, RawFunction};
use object::{Object, ObjectSection, SectionKind};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};

/// Where data loads may read flash.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub enum FlashData {
    /// Any load not relative to sp may read flash; the reasons (empty for the
    /// default model, which assumes nothing about the binary).
    Anywhere(Vec<String>),
    /// Only pc-relative loads and table branches read flash, except in the
    /// listed functions (start addresses → names) and their callees, where every
    /// load not relative to sp may.
    ConstantPools(BTreeMap<u32, String>),
}

impl FlashData {
    /// Whether a load that is not relative to sp or pc, in the function starting
    /// at `function`, may read flash.
    pub fn may_read_flash(&self, function: u32) -> bool {
        match self {
            FlashData::Anywhere(_) => true,
            FlashData::ConstantPools(pessimistic) => pessimistic.contains_key(&function),
        }
    }

    /// The assumption in words, for the report.
    pub fn describe(&self, wait_states: u32) -> String {
        match self {
            FlashData::Anywhere(reasons) if reasons.is_empty() => format!(
                "Data: every load that is not relative to sp may read flash (literal pools, \
                 .rodata, jump tables, constants): each costs {wait_states} wait states more \
                 (the ART's data cache counted on only for a literal-pool line every path has \
                 just read, its 8 lines replaced least recently used: `wcet::data_cache`). \
                 Stack accesses and stores go to \
                 zero-wait SRAM."
            ),
            FlashData::Anywhere(reasons) => format!(
                "Data: every load that is not relative to sp may read flash, {wait_states} wait \
                 states more each (the ART's data cache counted on only for a literal-pool line \
                 every path has just read: `wcet::data_cache`), because {}. Stack \
                 accesses and stores go to zero-wait SRAM.",
                reasons.join("; ")
            ),
            FlashData::ConstantPools(pessimistic) => {
                let names: Vec<&str> = pessimistic.values().map(String::as_str).collect();
                format!(
                    "Data: the ELF holds no data in flash but the vector table and the RAM \
                     sections' load images (`.rodata` is copied to SRAM with `.data`), and no \
                     code but the reset handler forms a flash data address: only pc-relative \
                     loads (literal pools) and table branches read flash, {wait_states} wait \
                     states more each, but a literal-pool load of a line the ART's data \
                     cache holds on every path to it (its 8 lines replaced least recently \
                     used, RM0090 3.5.2; an LRU must analysis, `wcet::data_cache`; a \
                     preemption charged the reload of all 8); in the {} \
                     function(s) that address a constant island with `adr` and in their \
                     callees every load not relative to sp is charged so ({}). Other loads \
                     and all stores go to zero-wait SRAM.",
                    names.len(),
                    if names.is_empty() {
                        "none".to_string()
                    } else {
                        names.join(", ")
                    }
                )
            }
        }
    }
}

impl FlashData {
    /// Decides [`FlashData`] for a binary: its sections, and every function's way of
    /// forming addresses. `flash` is `[start, end)`; `demangle` names functions.
    pub fn classify(
        file: &object::File,
        raw: &[RawFunction],
        flash: (u32, u32),
        demangle: impl Fn(&str) -> String,
    ) -> FlashData {
        let in_flash = |a: u32| (flash.0..flash.1).contains(&a);
        // The reset handler (the ELF's entry point) copies the load images to SRAM:
        // the one function allowed to form their flash addresses.
        let reset = (file.entry() as u32) & !1;
        let mut reasons = Vec::new();
        for s in file.sections() {
            // Not knowing, count it: a reason more, never a load charged less.
            let alloc = super::allocated(s.flags()).unwrap_or(true);
            let name = s.name().unwrap_or("?");
            if !alloc || s.size() == 0 || s.kind() == SectionKind::Text || name == ".vector_table" {
                continue;
            }
            if in_flash(s.address() as u32) {
                reasons.push(format!(
                    "section {name} ({} bytes) holds data in flash",
                    s.size()
                ));
            }
        }
        let mut adr_users: BTreeSet<usize> = BTreeSet::new();
        for (k, f) in raw.iter().enumerate() {
            let is_reset = f.address == reset;
            let name = || demangle(&f.name);
            let mut low: BTreeMap<&str, u32> = BTreeMap::new();
            for i in &f.instructions {
                let base = i.base();
                let dest = i.first_operand();
                match base {
                    "adr" => {
                        adr_users.insert(k);
                    }
                    "add" if i.operands.split(',').skip(1).any(|o| o.trim() == "pc") => {
                        reasons.push(format!(
                            "{} adds pc to a register at {:#x}",
                            name(),
                            i.address
                        ));
                    }
                    "movw" => {
                        if let Some(v) = immediate(&i.operands) {
                            low.insert(dest, v & 0xffff);
                        }
                    }
                    "movt" => {
                        if let (Some(&lo), Some(hi)) = (low.get(dest), immediate(&i.operands)) {
                            let a = (hi << 16) | lo;
                            if in_flash(a) && a & 1 == 0 && !is_reset {
                                reasons.push(format!(
                                    "{} forms the flash data address {a:#x} at {:#x}",
                                    name(),
                                    i.address
                                ));
                            }
                        }
                    }
                    _ => {}
                }
            }
            if is_reset {
                continue;
            }
            for d in &f.data {
                let start = d.address.next_multiple_of(4);
                let skip = (start - d.address) as usize;
                for (w, chunk) in d
                    .bytes
                    .get(skip..)
                    .unwrap_or(&[])
                    .chunks_exact(4)
                    .enumerate()
                {
                    let v = u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
                    if in_flash(v) && v & 1 == 0 {
                        reasons.push(format!(
                            "{} holds the flash data address {v:#x} in its literal pool at {:#x}",
                            name(),
                            start + 4 * w as u32
                        ));
                    }
                }
            }
        }
        // The functions that address a constant island, and everything they call.
        let by_address: BTreeMap<u32, usize> = raw
            .iter()
            .enumerate()
            .map(|(k, f)| (f.address, k))
            .collect();
        let mut pessimistic: BTreeSet<usize> = BTreeSet::new();
        let mut stack: Vec<usize> = adr_users.iter().copied().collect();
        while let Some(k) = stack.pop() {
            if !pessimistic.insert(k) {
                continue;
            }
            for i in &raw[k].instructions {
                let base = i.base();
                let direct = matches!(base, "bl" | "b" | "blx") && i.target.is_some();
                if direct {
                    if let Some(&c) = i.target.and_then(|t| by_address.get(&t)) {
                        if c != k {
                            stack.push(c);
                        }
                    }
                } else if matches!(base, "blx" | "bx") && i.operands.trim() != "lr" {
                    reasons.push(format!(
                        "{} addresses a constant island and calls through a register at {:#x}",
                        demangle(&raw[k].name),
                        i.address
                    ));
                }
            }
        }
        if !reasons.is_empty() {
            return FlashData::Anywhere(reasons);
        }
        FlashData::ConstantPools(
            pessimistic
                .into_iter()
                .map(|k| (raw[k].address, demangle(&raw[k].name)))
                .collect(),
        )
    }
}

/// The immediate of `movw r0, #0x1234` / `movt r0, #2048` (its second operand).
fn immediate(operands: &str) -> Option<u32> {
    operands
        .split(',')
        .nth(1)
        .filter(|o| o.trim_start().starts_with('#'))
        .and_then(parse_imm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn immediates_in_both_notations() {
        assert_eq!(immediate("r2, #0x800"), Some(0x800));
        assert_eq!(immediate("r2, #2048"), Some(2048));
        assert_eq!(immediate("r2, r3"), None);
    }

    #[test]
    fn only_listed_functions_read_flash_through_registers() {
        let d = FlashData::ConstantPools(BTreeMap::from([(0x0800_1000, "f".to_string())]));
        assert!(d.may_read_flash(0x0800_1000));
        assert!(!d.may_read_flash(0x0800_2000));
        assert!(FlashData::Anywhere(Vec::new()).may_read_flash(0x0800_2000));
    }
}
