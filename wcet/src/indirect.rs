//! The targets of indirect calls and jumps, read from the binary: a function can
//! be reached through a register only if its address (with the Thumb bit) was put
//! somewhere the code can load it from. This module collects those addresses: the
//! words of the ELF's data sections (vtables such as RTIC's waker table, function
//! pointers in statics) and the constants the code builds (`movw`/`movt` pairs,
//! literal pools: RTIC's pend closures, which its executor keeps as a waker's data).
//!
//! A call or jump whose target register the same block loads from memory
//! (`ldr rT, [rB, #off]`, `ldr pc, [..]`: a vtable's slot, a pointer in a struct)
//! may reach any of them. One whose register holds a value it did not load (an
//! argument: the waker's data that `waker_wake` jumps to) may reach the addresses
//! the code builds, not the data sections' words: the assumption that a pointer
//! read from a data table is called where it is read, which Rust's vtable calls
//! and RTIC's executor follow. A traced indirect transfer to a function outside
//! its site's set is an error ([`unexpected_targets`]): the sets missed a way an
//! address travels.

use super::cfg::{IndirectTargets, Program, RawFunction};
use super::trace_check::TraceCheck;
use std::collections::{BTreeMap, BTreeSet};

/// Where a function's address was found.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
pub struct Taken {
    /// The function's symbol.
    pub function: String,
    /// Where its address is: `section+offset`, `literal pool at ADDR`, `movw/movt
    /// in FUNCTION`.
    pub at: String,
    /// Built by the code (a `movw`/`movt` pair or a literal pool), not a word of a
    /// data section.
    pub built: bool,
}

/// The functions whose address the binary holds or builds: `data` are the ELF's
/// data sections that are not the vector table (`(name, bytes)`), `raw` the
/// disassembly. Keyed by function index in `raw`.
pub fn address_taken(
    raw: &[RawFunction],
    data: &[(String, Vec<u8>)],
) -> BTreeMap<usize, Vec<Taken>> {
    let starts: BTreeMap<u32, usize> = raw
        .iter()
        .enumerate()
        .map(|(k, f)| (f.address, k))
        .collect();
    let mut out: BTreeMap<usize, Vec<Taken>> = BTreeMap::new();
    let mut note = |w: u32, at: String, built: bool| {
        if w & 1 == 1 {
            if let Some(&k) = starts.get(&(w & !1)) {
                out.entry(k).or_default().push(Taken {
                    function: raw[k].name.clone(),
                    at,
                    built,
                });
            }
        }
    };
    for (name, bytes) in data {
        for (i, c) in bytes.chunks_exact(4).enumerate() {
            note(
                u32::from_le_bytes([c[0], c[1], c[2], c[3]]),
                format!("{name}+{:#x}", 4 * i),
                false,
            );
        }
    }
    for f in raw {
        for run in &f.data {
            // Pool words are word-aligned in memory.
            let skip = ((4 - run.address % 4) % 4) as usize;
            for (i, c) in run
                .bytes
                .get(skip..)
                .unwrap_or(&[])
                .chunks_exact(4)
                .enumerate()
            {
                note(
                    u32::from_le_bytes([c[0], c[1], c[2], c[3]]),
                    format!("literal pool at {:#x}", run.address as usize + skip + 4 * i),
                    true,
                );
            }
        }
        // `movw rX, #lo` then `movt rX, #hi`: the constant `hi << 16 | lo`.
        let mut low: BTreeMap<String, u32> = BTreeMap::new();
        for i in &f.instructions {
            let reg = i.first_operand().to_string();
            let imm = i
                .operands
                .split('#')
                .nth(1)
                .and_then(|v| u32::from_str_radix(v.trim().trim_start_matches("0x"), 16).ok());
            match (i.base(), imm) {
                ("movw", Some(v)) => {
                    low.insert(reg, v);
                }
                ("movt", Some(v)) => {
                    if let Some(lo) = low.remove(&reg) {
                        note((v << 16) | lo, format!("movw/movt in {}", f.name), true);
                    }
                }
                _ => {
                    low.remove(&reg);
                }
            }
        }
    }
    for v in out.values_mut() {
        v.sort();
        v.dedup();
    }
    out
}

/// How an indirect transfer gets its target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Site {
    /// Loaded from memory by its own block (a vtable's slot, a struct's pointer).
    Loaded,
    /// A value the block did not load (an argument, a register copy).
    Value,
}

/// The target register of indirect transfer `i` (`blx rN`, `bx rN`, `mov pc, rN`),
/// or `None` for `ldr pc, [..]` (loaded by itself).
fn target_register(i: &super::cfg::Instruction) -> Option<String> {
    let ops: Vec<&str> = i.operands.split(',').map(str::trim).collect();
    match i.base() {
        b if b.starts_with("ldr") => None,
        b if b.starts_with("mov") || b.starts_with("add") => ops.get(1).map(|r| r.to_string()),
        _ => ops.first().map(|r| r.to_string()),
    }
}

/// How the indirect transfer at index `k` of `f` gets its target: loaded if the
/// last write of its register before it in the same straight run of code is a
/// load (`ldr`), a value otherwise.
fn site_kind(f: &RawFunction, k: usize) -> Site {
    let i = &f.instructions[k];
    let Some(reg) = target_register(i) else {
        return Site::Loaded;
    };
    for j in f.instructions[..k].iter().rev() {
        // A branch or call before it: the register comes from elsewhere.
        if j.target.is_some() || j.base().starts_with('b') || j.base().starts_with("cb") {
            break;
        }
        let writes = j.first_operand() == reg
            || (j.base().starts_with("ldrd")
                && j.operands.split(',').nth(1).map(str::trim) == Some(&reg));
        if writes {
            return if j.base().starts_with("ldr") {
                Site::Loaded
            } else {
                Site::Value
            };
        }
    }
    Site::Value
}

/// Whether instruction `i` transfers control through a register (not a return).
fn is_indirect(i: &super::cfg::Instruction) -> bool {
    const CONDITIONS: [&str; 16] = [
        "eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt",
        "le",
    ];
    let mut base = i.base();
    if let Some(head) = CONDITIONS.iter().find_map(|c| base.strip_suffix(c)) {
        if matches!(head, "blx" | "bx" | "mov" | "ldr" | "add") {
            base = head;
        }
    }
    match base {
        "blx" => i.target.is_none(),
        "bx" => i.first_operand() != "lr",
        "mov" | "ldr" | "add" => i.first_operand() == "pc",
        _ => false,
    }
}

/// The data sections of an ELF that code can load addresses from: every section
/// with contents that is neither code, the vector table (exception entries, not
/// call targets) nor debug information, as `(name, bytes)`.
pub fn data_sections(file: &object::File<'_>) -> Vec<(String, Vec<u8>)> {
    use object::{Object, ObjectSection, SectionKind};
    file.sections()
        .filter(|s| {
            matches!(
                s.kind(),
                SectionKind::Data
                    | SectionKind::ReadOnlyData
                    | SectionKind::ReadOnlyDataWithRel
                    | SectionKind::ReadOnlyString
            )
        })
        .filter_map(|s| {
            let name = s.name().ok()?.to_string();
            (name != ".vector_table").then_some(())?;
            Some((name, s.data().ok()?.to_vec()))
        })
        .collect()
}

/// Indirect-call rules for [`super::cfg::build_program`]: every function with an
/// indirect call or jump (by its demangled name, as the rules match callers) may
/// reach every address-taken function (`taken`, keyed by index in `raw`), named
/// by their exact symbols.
pub fn targets(
    raw: &[RawFunction],
    taken: &BTreeMap<usize, Vec<Taken>>,
    demangle: impl Fn(&str) -> String,
) -> IndirectTargets {
    let all: Vec<String> = taken.keys().map(|&k| raw[k].name.clone()).collect();
    let built: Vec<String> = taken
        .iter()
        .filter(|(_, t)| t.iter().any(|x| x.built))
        .map(|(&k, _)| raw[k].name.clone())
        .collect();
    let rules = raw
        .iter()
        .filter_map(|f| {
            let kinds: BTreeSet<bool> = f
                .instructions
                .iter()
                .enumerate()
                .filter(|(_, i)| is_indirect(i))
                .map(|(k, _)| site_kind(f, k) == Site::Loaded)
                .collect();
            let callees = match (kinds.contains(&true), kinds.is_empty()) {
                (_, true) => return None,
                (true, false) => all.clone(),
                (false, false) => built.clone(),
            };
            Some((demangle(&f.name), callees))
        })
        .collect();
    IndirectTargets { rules }
}

/// [`targets`] of the ELF at `elf`: its disassembly and its data sections.
pub fn targets_of_elf(elf: &std::path::Path) -> Result<IndirectTargets, super::WcetError> {
    let text = super::stack::disassemble_with_bytes(elf)?;
    let raw = super::cfg::parse_disassembly(&text);
    let bytes = super::read_elf(elf)?;
    let file = super::parse_elf(elf, &bytes)?;
    let taken = address_taken(&raw, &data_sections(&file));
    Ok(targets(&raw, &taken, super::demangle))
}

/// The indirect transfers a trace took that the program's graphs do not have:
/// one message each (site, its function, the target).
pub fn unexpected_targets(program: &Program, check: &TraceCheck) -> Vec<String> {
    let mut out = Vec::new();
    for o in &check.indirect_calls {
        let Some(func) = program.functions.get(o.from) else {
            continue;
        };
        let Some(b) = func.block_at(o.site) else {
            continue;
        };
        let block = &func.blocks[b];
        let listed: BTreeSet<usize> = block
            .calls
            .iter()
            .copied()
            .chain(match &block.exit {
                super::cfg::Exit::IndirectTail(ts) => ts.clone(),
                super::cfg::Exit::TailCall(t) => vec![*t],
                _ => Vec::new(),
            })
            .collect();
        if !listed.contains(&o.target) {
            out.push(format!(
                "indirect transfer at {:#x} in `{}` went to `{}` ({} times), which the binary's \
                 address-taken functions do not include: an address is made in a way the \
                 analysis does not read",
                o.site, func.demangled, o.target_name, o.count
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cfg::{build_program, parse_disassembly, MemoryModel};
    use crate::trace_check::IndirectObservation;

    /// `wake` jumps to its argument (a value: a built address may be there);
    /// `caller` calls through a vtable's slot (loaded: any taken address); `pend`
    /// is built with movw/movt in `caller`; `slot` is only in a data table;
    /// `never` is taken nowhere.
    const CODE: &str = "
/tmp/ecu:\tfile format elf32-littlearm

Disassembly of section .text:

08000100 <wake>:
 8000100: 4700         \tbx\tr0

08000110 <caller>:
 8000110: b580         \tpush\t{r7, lr}
 8000112: f240 1021    \tmovw\tr0, #0x121
 8000116: f6c0 0000    \tmovt\tr0, #0x800
 800011a: 6843         \tldr\tr3, [r0, #0x4]
 800011c: 4798         \tblx\tr3
 800011e: bd80         \tpop\t{r7, pc}

08000120 <pend>:
 8000120: 4770         \tbx\tlr

08000130 <slot>:
 8000130: 4770         \tbx\tlr

08000140 <never>:
 8000140: 4770         \tbx\tlr
";

    #[test]
    fn targets_come_from_the_data_and_the_code_and_a_value_reaches_only_built_ones(
    ) -> Result<(), String> {
        let raw = parse_disassembly(CODE);
        // A table of two function pointers in a data section: `slot` and `wake`.
        let table: Vec<u8> = [0x0800_0131u32, 0x0800_0101]
            .iter()
            .flat_map(|w| w.to_le_bytes())
            .collect();
        let taken = address_taken(&raw, &[(".rodata".into(), table)]);
        let name = |k: &usize| raw[*k].name.clone();
        let names: Vec<String> = taken.keys().map(name).collect();
        assert_eq!(names, vec!["wake", "pend", "slot"]);
        assert!(taken
            .values()
            .flatten()
            .any(|t| t.function == "pend" && t.built));
        assert!(taken
            .values()
            .flatten()
            .all(|t| t.function == "pend" || !t.built));
        let rules = targets(&raw, &taken, |s: &str| s.to_string());
        let of = |f: &str| -> Vec<String> {
            rules
                .rules
                .iter()
                .filter(|(c, _)| c == f)
                .flat_map(|(_, t)| t.clone())
                .collect()
        };
        assert_eq!(of("wake"), vec!["pend"]);
        assert_eq!(of("caller"), vec!["wake", "pend", "slot"]);
        assert!(of("pend").is_empty());
        // The graph has them: a trace to `never` is unexpected, to `pend` not.
        let program = build_program(&raw, &rules, &MemoryModel::TEST, |s: &str| s.to_string())
            .map_err(|e| e.to_string())?;
        let at = |a: u32| program.at(a).ok_or("no function");
        let observed = |target: usize| TraceCheck {
            loops: Vec::new(),
            counters: Vec::new(),
            sections: Vec::new(),
            indirect_calls: vec![IndirectObservation {
                site: 0x0800_0100,
                from: at(0x0800_0100).unwrap_or(0),
                target,
                target_name: program.functions[target].demangled.clone(),
                count: 3,
            }],
            blocks_run: Vec::new(),
            roots: Vec::new(),
            other_handlers: Vec::new(),
            tb_executions: 0,
            instructions: 0,
            block_entries: 0,
            exception_entries: 0,
            outside_functions: 0,
            untraced_executions: 0,
            abandoned_executions: 0,
            unexpected_transfers: 0,
            examples: Vec::new(),
        };
        assert!(unexpected_targets(&program, &observed(at(0x0800_0120)?)).is_empty());
        let wrong = unexpected_targets(&program, &observed(at(0x0800_0140)?));
        assert_eq!(wrong.len(), 1, "{wrong:?}");
        assert!(wrong[0].contains("`never`") && wrong[0].contains("0x8000100"));
        Ok(())
    }
}
