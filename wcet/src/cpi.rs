//! Cycles-per-instruction bound from a QEMU execution trace.
//!
//! QEMU with `-icount` counts instructions, not cycles. Run with
//! `-d in_asm,exec,nochain -D LOG`, it prints each translation block (TB) once when
//! translated (`IN:` and one line per instruction, `0x08001234:  f8d0 1004  ldr.w r1,
//! [r0, #4]`) and one `Trace` line per execution (`Trace 0: 0x7f.. [cs_base/pc/flags/cflags]
//! sym`). This module streams such a log, weighs every executed instruction with its
//! worst case from the Cortex-M4 Technical Reference Manual (conditional branches taken,
//! pipeline refill 3 cycles on every branch), and adds the flash cost: per executed TB
//! `cycles = max(Σ instruction cycles, 6 · ⌈bytes / 16⌉) + 5` (one 128-bit flash line
//! per 5 wait states + 1 cycle for straight-line fetch, and an ART miss of 5 cycles at
//! the jump that ends the block). The result is an upper bound on cycles per
//! instruction for the code that ran, under the assumptions in [`JUSTIFICATION`].
//!
//! Executions are matched to translations by the TB's host code pointer and pc
//! printed in the `Trace` line (a pc can have several translations: icount
//! re-translates an I/O instruction as a 1-instruction TB).
//!
//! With `-icount`, QEMU sometimes starts a TB it does not run (`Stopped execution of TB
//! chain before`) or rewinds one at an I/O access (`cpu_io_recompile: rewound
//! execution of TB to PC`, PC being the I/O instruction, possibly in the middle of the
//! TB); the first execution is removed, the second counted up to the I/O instruction
//! (which then runs as its own TB), so instruction counts match QEMU's.
//!
//! **Idle.** A firmware with no idle task spins in `b .` between interrupts (RTIC's
//! default idle), and QEMU executes and counts that loop. A translation made only of
//! `nop`/`wfi`/`wfe` ending in a branch to its own start is an idle loop: its
//! executions are reported apart ([`CpiReport::idle`]) and are not in
//! [`CpiReport::total`], whose CPI bound is that of the code doing work (an idle
//! loop's bound, 11 cycles per `b .`, says nothing about the tasks).

use super::{demangle, WcetError};
use serde::Serialize;
use std::collections::HashMap;
use std::io::BufRead;
use std::path::Path;

/// The assumptions under which the cycle figures are an upper bound.
pub const JUSTIFICATION: &str = "Worst-case cycles of a Cortex-M4F at 168 MHz, 3.3 V, flash with \
5 wait states behind the ART accelerator: per executed translation block, max(sum of \
per-instruction worst cases from the Cortex-M4 TRM, 6 cycles per 16 bytes of code) + 5 cycles for \
an ART miss at the block's final jump (sequential fetch overlapped with execution, as the ART's \
prefetch would; the ECU runs with it off, so this average is an estimate, and the static bounds \
use the memory model of `static.md` instead). Per instruction: every \
branch taken with a 3-cycle pipeline refill (conditional ones included), loads and stores 2 \
(LDRD/STRD 3), LDM/STM/PUSH/POP 1+N (+3 when loading pc), SDIV/UDIV 12, MLA/MLS 2, VDIV/VSQRT 14, \
VFMA/VMLA family 3, VMOV between core and FPU 2, VLDM/VSTM/VPUSH/VPOP 1+N words, unknown \
instructions 4 (listed). Data in zero-wait-state SRAM, no DMA or bus contention, no interrupt \
entry or exit costs (they are in the trace only as the handlers' instructions).";

/// Worst-case cycles charged for an instruction the table does not know.
pub const UNKNOWN_INSTRUCTION_CYCLES: u32 = 4;
/// ART miss at the jump that ends a translation block, in cycles (5 wait states).
pub const BRANCH_MISS_CYCLES: u64 = 5;
/// Cycles to fetch one 16-byte flash line without the ART (5 wait states + 1).
pub const FLASH_LINE_CYCLES: u64 = 6;
/// Bytes per flash line (128 bits).
pub const FLASH_LINE_BYTES: u64 = 16;

/// Instruction classes of the timing table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub enum Class {
    /// ALU, moves, shifts, compares, bit fields, extends: 1 cycle.
    DataProcessing,
    /// MUL 1, MLA/MLS 2, long and DSP multiplies 1.
    Multiply,
    /// SDIV/UDIV: 2–12 cycles, 12 in the bound.
    Divide,
    /// LDR and variants: 2 (LDRD 3).
    Load,
    /// STR and variants: 2 (STRD 3).
    Store,
    /// LDM/POP: 1+N.
    LoadMultiple,
    /// STM/PUSH: 1+N.
    StoreMultiple,
    /// B, BL, BX, BLX, CBZ, CBNZ: 1+3.
    Branch,
    /// TBB/TBH: 2+3.
    TableBranch,
    /// IT: 1.
    It,
    /// Single-cycle FPU arithmetic, compares, conversions, moves, VMRS/VMSR.
    Fpu,
    /// VMOV between core and FPU registers: 2.
    FpuTransfer,
    /// VMLA/VMLS/VFMA/VFMS/VNMLA/VNMLS: 3.
    FpuMultiplyAccumulate,
    /// VDIV/VSQRT: 14.
    FpuDivideSqrt,
    /// VLDR/VSTR 2, VLDM/VSTM/VPUSH/VPOP 1+N.
    FpuLoadStore,
    /// Not in the table: [`UNKNOWN_INSTRUCTION_CYCLES`].
    Unknown,
}

const CONDITIONS: [&str; 17] = [
    "eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le",
    "al",
];

/// Words transferred by a register list `{r4-r7, d8}` (d-registers count 2) and
/// whether pc is loaded.
fn register_list(operands: &str) -> (u32, bool) {
    let (Some(open), Some(close)) = (operands.find('{'), operands.rfind('}')) else {
        return (1, false);
    };
    let Some(list) = operands.get(open + 1..close) else {
        return (1, false);
    };
    let mut words = 0;
    let mut pc = false;
    for item in list.split(',').map(str::trim) {
        let (first, last) = item.split_once('-').unwrap_or((item, item));
        pc |= first == "pc" || last == "pc";
        let size = if first.starts_with('d') { 2 } else { 1 };
        let n = |r: &str| r.get(1..).and_then(|x| x.parse::<u32>().ok());
        let count = match (n(first), n(last)) {
            (Some(a), Some(b)) if b >= a => b - a + 1,
            _ => 1,
        };
        words += size * count;
    }
    (words.max(1), pc)
}

fn first_operand(operands: &str) -> &str {
    operands.split(',').next().unwrap_or("").trim()
}

fn has_core_register(operands: &str) -> bool {
    operands.split(',').map(str::trim).any(|o| {
        o.strip_prefix('r')
            .is_some_and(|n| !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()))
            || matches!(o, "ip" | "lr" | "sb" | "sl" | "fp")
    })
}

/// Class and worst-case cycles of a base mnemonic (no condition, no `s`, no `.w`).
fn base_timing(base: &str, operands: &str) -> Option<(Class, u32)> {
    use Class::*;
    let writes_pc = first_operand(operands) == "pc";
    let refill = if writes_pc { 3 } else { 0 };
    let (words, loads_pc) = register_list(operands);
    Some(match base {
        "mov" | "movw" | "movt" | "mvn" | "add" | "addw" | "adc" | "sub" | "subw" | "sbc"
        | "rsb" | "and" | "orr" | "orn" | "eor" | "bic" | "cmp" | "cmn" | "tst" | "teq" | "lsl"
        | "lsr" | "asr" | "ror" | "rrx" | "ubfx" | "sbfx" | "bfi" | "bfc" | "uxtb" | "uxth"
        | "sxtb" | "sxth" | "uxtab" | "uxtah" | "sxtab" | "sxtah" | "uxtb16" | "sxtb16" | "rev"
        | "rev16" | "revsh" | "rbit" | "clz" | "usat" | "ssat" | "sel" | "adr" | "nop" | "neg"
        | "qadd" | "qsub" | "pkhbt" | "pkhtb" | "mrs" | "msr" | "cpsid" | "cpsie" | "pld"
        | "uadd8" | "usub8" | "sadd16" | "ssub16" => (DataProcessing, 1 + refill),
        "mul" | "umull" | "smull" | "umlal" | "smlal" | "smulbb" | "smulbt" | "smultb"
        | "smultt" | "smlabb" | "smmul" | "smmla" | "smlad" | "smuad" | "umaal" => (Multiply, 1),
        "mla" | "mls" => (Multiply, 2),
        "sdiv" | "udiv" => (Divide, 12),
        "ldr" | "ldrb" | "ldrh" | "ldrsb" | "ldrsh" | "ldrex" | "ldrexb" | "ldrexh" | "ldrt" => {
            (Load, 2 + refill)
        }
        "ldrd" => (Load, 3),
        "ldm" | "ldmia" | "ldmfd" | "ldmdb" | "pop" => {
            (LoadMultiple, 1 + words + if loads_pc { 3 } else { 0 })
        }
        "str" | "strb" | "strh" | "strex" | "strexb" | "strexh" | "strt" => (Store, 2),
        "strd" => (Store, 3),
        "stm" | "stmia" | "stmea" | "stmdb" | "stmfd" | "push" => (StoreMultiple, 1 + words),
        "b" | "bl" | "bx" | "blx" | "cbz" | "cbnz" => (Branch, 4),
        "tbb" | "tbh" => (TableBranch, 5),
        "vadd" | "vsub" | "vmul" | "vnmul" | "vabs" | "vneg" | "vcmp" | "vcmpe" | "vcvt"
        | "vcvtr" | "vcvtb" | "vcvtt" | "vmrs" | "vmsr" => (Fpu, 1),
        "vmov" if has_core_register(operands) => (FpuTransfer, 2),
        "vmov" => (Fpu, 1),
        "vmla" | "vmls" | "vfma" | "vfms" | "vnmla" | "vnmls" | "vfnma" | "vfnms" => {
            (FpuMultiplyAccumulate, 3)
        }
        "vdiv" | "vsqrt" => (FpuDivideSqrt, 14),
        "vldr" | "vstr" => (FpuLoadStore, 2),
        "vldm" | "vldmia" | "vldmdb" | "vstm" | "vstmia" | "vstmdb" | "vpush" | "vpop" => {
            (FpuLoadStore, 1 + words)
        }
        _ => return None,
    })
}

/// Class and worst-case cycles of one instruction as QEMU prints it (`ldr.w`,
/// `addseq`, `vmla.f32`, `itte`); unknown ones get [`UNKNOWN_INSTRUCTION_CYCLES`].
pub fn instruction_timing(mnemonic: &str, operands: &str) -> (Class, u32) {
    let m = mnemonic.split('.').next().unwrap_or(mnemonic);
    if m.len() <= 5 && m.starts_with("it") && m[2..].chars().all(|c| c == 't' || c == 'e') {
        return (Class::It, 1);
    }
    let strip_cond = |s: &str| -> Option<String> {
        let cut = s.len().checked_sub(2)?;
        let (head, tail) = (s.get(..cut)?, s.get(cut..)?);
        (CONDITIONS.contains(&tail) && !head.is_empty()).then(|| head.to_string())
    };
    let strip_s = |s: &str| s.strip_suffix('s').map(str::to_string);
    let candidates = [
        Some(m.to_string()),
        strip_cond(m),
        strip_s(m),
        strip_cond(m).and_then(|c| strip_s(&c)),
    ];
    candidates
        .iter()
        .flatten()
        .find_map(|c| base_timing(c, operands))
        .unwrap_or((Class::Unknown, UNKNOWN_INSTRUCTION_CYCLES))
}

/// One translated instruction.
#[derive(Debug, Clone)]
struct Insn {
    address: u32,
    bytes: u32,
    cycles: u32,
    class: Class,
    mnemonic: String,
    /// Target of an unconditional `b #ADDR`.
    target: Option<u32>,
}

/// Whether a translation is an idle loop: only `nop`, `wfi`, `wfe`, `yield`, then an
/// unconditional branch to its own start.
fn is_idle_loop(insns: &[Insn]) -> bool {
    let (Some(first), Some((last, body))) = (insns.first(), insns.split_last()) else {
        return false;
    };
    last.target == Some(first.address)
        && body.iter().all(|i| {
            matches!(
                i.mnemonic.split('.').next(),
                Some("nop" | "wfi" | "wfe" | "yield")
            )
        })
}

/// A function symbol of the ELF: name (mangled), start address, size in bytes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ElfSymbol {
    /// Symbol name (mangled).
    pub name: String,
    /// Start address (Thumb bit cleared).
    pub address: u32,
    /// Size, in bytes.
    pub size: u32,
}

/// Function symbols of an ELF file's symbol table.
pub fn elf_functions(elf: &Path) -> Result<Vec<ElfSymbol>, WcetError> {
    use object::{Object, ObjectSymbol, SymbolKind};
    let data = super::read_elf(elf)?;
    let file = super::parse_elf(elf, &data)?;
    Ok(file
        .symbols()
        .filter(|s| s.kind() == SymbolKind::Text)
        .filter_map(|s| {
            Some(ElfSymbol {
                name: s.name().ok()?.to_string(),
                address: (s.address() as u32) & !1,
                size: s.size() as u32,
            })
        })
        .collect())
}

/// A named set of address ranges whose figures are reported separately.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Region {
    /// Name in the report, e.g. `firmware::mpc`.
    pub name: String,
    /// Half-open address ranges `[start, end)`.
    pub ranges: Vec<(u32, u32)>,
}

impl Region {
    /// The functions of `symbols` whose demangled name starts with `prefix`.
    pub fn from_prefix(symbols: &[ElfSymbol], prefix: &str) -> Region {
        Region {
            name: prefix.to_string(),
            ranges: symbols
                .iter()
                .filter(|s| demangle(&s.name).starts_with(prefix))
                .map(|s| (s.address, s.address.saturating_add(s.size.max(1))))
                .collect(),
        }
    }

    fn contains(&self, pc: u32) -> bool {
        self.ranges.iter().any(|&(a, b)| (a..b).contains(&pc))
    }
}

/// Instructions of one class.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClassCount {
    /// The class.
    pub class: Class,
    /// Instructions executed.
    pub instructions: u64,
    /// Share of all instructions executed (0–1).
    pub fraction: f64,
    /// Their worst-case cycles (instruction table only, before the flash terms).
    pub cycles: u64,
}

/// Instruction and cycle figures over some executed code.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figures {
    /// Instructions executed.
    pub instructions: u64,
    /// Worst-case cycles (instruction table and flash terms).
    pub worst_case_cycles: u64,
    /// `worst_case_cycles / instructions`.
    pub cpi_bound: f64,
    /// Per class, most instructions first.
    pub classes: Vec<ClassCount>,
}

/// Figures for one [`Region`] (TBs attributed by their start address).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RegionFigures {
    /// The region's name.
    pub name: String,
    /// Its figures.
    pub figures: Figures,
}

/// The CPI bound of a traced execution.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CpiReport {
    /// Whole trace except the idle loop.
    pub total: Figures,
    /// The idle loop (`b .` and the like, see the module documentation): not in
    /// `total`.
    pub idle: Figures,
    /// Executions of translation blocks counted (idle loop included).
    pub tb_executions: u64,
    /// Distinct translations seen.
    pub translations: u64,
    /// `Trace` lines without a translation in the log (not counted).
    pub untraced_executions: u64,
    /// Executions that QEMU stopped before they ran or rewound (removed, or counted
    /// up to where execution resumed).
    pub abandoned_executions: u64,
    /// The 20 most executed mnemonics with their counts.
    pub top_mnemonics: Vec<(String, u64)>,
    /// Mnemonics not in the timing table, with their counts.
    pub unknown_mnemonics: Vec<(String, u64)>,
    /// Per requested region.
    pub regions: Vec<RegionFigures>,
    /// Assumptions behind the bound.
    pub justification: String,
}

/// Streaming state of the log parser.
#[derive(Default)]
struct Trace {
    translations: Vec<Vec<Insn>>,
    /// Translation not yet executed, by start pc.
    pending: HashMap<u32, usize>,
    /// (TB host code pointer, pc) to translation.
    bound: HashMap<(u64, u32), usize>,
    /// Executions per (translation, instructions executed).
    executions: HashMap<(usize, usize), u64>,
    /// The last execution: translation, host pointer, pc.
    last: Option<(usize, u64, u32)>,
    rewound: Option<usize>,
    tb_executions: u64,
    untraced: u64,
    abandoned: u64,
}

fn hex(s: &str) -> Option<u32> {
    u32::from_str_radix(s.trim().trim_start_matches("0x"), 16).ok()
}

/// `0x080001a8:  f014 fffe  bl       #0x80151a8` → instruction.
fn parse_in_line(line: &str) -> Option<Insn> {
    let (addr, rest) = line.split_once(':')?;
    let address = hex(addr)?;
    let mut tokens = rest.split_whitespace();
    let mut bytes = 0;
    let mut mnemonic = "";
    for t in tokens.by_ref() {
        if bytes < 4 && t.len() == 4 && t.chars().all(|c| c.is_ascii_hexdigit()) {
            bytes += 2;
        } else {
            mnemonic = t;
            break;
        }
    }
    if bytes == 0 || mnemonic.is_empty() {
        return None;
    }
    let operands = tokens.collect::<Vec<_>>().join(" ");
    let (class, cycles) = instruction_timing(mnemonic, &operands);
    let target = matches!(mnemonic, "b" | "b.w" | "b.n")
        .then(|| operands.strip_prefix('#').and_then(hex))
        .flatten();
    Some(Insn {
        address,
        bytes,
        cycles,
        class,
        mnemonic: mnemonic.to_string(),
        target,
    })
}

impl Trace {
    fn record(&mut self, tb: usize, executed: usize, times: i64) {
        let entry = self.executions.entry((tb, executed)).or_insert(0);
        *entry = entry.saturating_add_signed(times);
    }

    /// Removes the last execution if it is of the TB at `host` (when given) starting
    /// at `pc`; returns its translation.
    fn undo_last(&mut self, host: Option<u64>, pc: u32) -> Option<usize> {
        match self.last {
            Some((tb, h, start)) if start == pc && host.is_none_or(|x| x == h) => {
                self.last = None;
                self.remove_execution(tb);
                Some(tb)
            }
            _ => None,
        }
    }

    fn remove_execution(&mut self, tb: usize) {
        let len = self.translations.get(tb).map_or(0, Vec::len);
        self.record(tb, len, -1);
        self.tb_executions = self.tb_executions.saturating_sub(1);
        self.abandoned += 1;
    }

    /// `cpu_io_recompile: rewound execution of TB to PC`: the last TB ran up to the
    /// instruction at `pc` (excluded), which is re-executed as its own TB. QEMU prints
    /// the I/O instruction's pc (or, in some versions, the TB's start: then the
    /// executed prefix is known at the next `Trace` line).
    fn rewind(&mut self, pc: u32) {
        let Some((tb, _, _)) = self.last else {
            return;
        };
        let Some(done) = self
            .translations
            .get(tb)
            .and_then(|insns| insns.iter().position(|i| i.address == pc))
        else {
            return;
        };
        self.last = None;
        self.remove_execution(tb);
        if done > 0 {
            self.record(tb, done, 1);
        } else {
            self.rewound = Some(tb);
        }
    }

    fn trace(&mut self, host: u64, key: (u32, u32, u32, u32)) {
        let pc = key.1;
        if let Some(tb) = self.rewound.take() {
            // The rewound TB ran up to the instruction where execution resumes.
            if let Some(done) = self
                .translations
                .get(tb)
                .and_then(|insns| insns.iter().position(|i| i.address == pc))
            {
                if done > 0 {
                    self.record(tb, done, 1);
                }
            }
        }
        // QEMU prints a translation just before its first execution.
        if let Some(tb) = self.pending.remove(&pc) {
            self.bound.insert((host, pc), tb);
        }
        match self.bound.get(&(host, pc)).copied() {
            Some(tb) => {
                let len = self.translations.get(tb).map_or(0, Vec::len);
                self.record(tb, len, 1);
                self.tb_executions += 1;
                self.last = Some((tb, host, pc));
            }
            None => {
                self.untraced += 1;
                self.last = None;
            }
        }
    }
}

/// The TB host code pointer, the first `0x…` word of a `Trace` or `Stopped` line.
fn host_pointer(line: &str) -> Option<u64> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix("0x"))
        .and_then(|h| u64::from_str_radix(h, 16).ok())
}

/// Parses the bracketed `cs_base/pc/flags/cflags` of a `Trace` line.
fn trace_key(line: &str) -> Option<(u32, u32, u32, u32)> {
    let open = line.find('[')?;
    let close = line[open..].find(']')? + open;
    let mut f = line.get(open + 1..close)?.split('/').map(hex);
    Some((f.next()??, f.next()??, f.next()??, f.next()??))
}

/// Streams a QEMU `-d in_asm,exec,nochain` log and bounds its cycles. Stops after
/// `max_tb_executions` executions if given. `regions` get their own figures.
pub fn analyse_log<R: BufRead>(
    mut log: R,
    max_tb_executions: Option<u64>,
    regions: &[Region],
) -> Result<CpiReport, WcetError> {
    let mut t = Trace::default();
    let mut line = String::new();
    let mut number: u64 = 0;
    let mut block: Option<Vec<Insn>> = None;
    let limit = max_tb_executions.unwrap_or(u64::MAX);
    let format_error = |number: u64, message: &str, text: &str| WcetError::LogFormat {
        line: number,
        message: message.to_string(),
        text: text.chars().take(120).collect(),
    };
    loop {
        line.clear();
        let n = log.read_line(&mut line).map_err(|source| WcetError::Io {
            path: "QEMU log".into(),
            source,
        })?;
        if n == 0 || t.tb_executions >= limit {
            break;
        }
        number += 1;
        let text = line.trim_end();
        if let Some(insns) = block.as_mut() {
            if let Some(insn) = parse_in_line(text).filter(|_| text.starts_with("0x")) {
                insns.push(insn);
                continue;
            }
            if let Some(insns) = block.take() {
                if let Some(first) = insns.first() {
                    t.pending.insert(first.address, t.translations.len());
                    t.translations.push(insns);
                }
            }
        }
        if text.starts_with("Trace ") {
            let key = trace_key(text).ok_or_else(|| {
                format_error(number, "no [cs_base/pc/flags/cflags] in a Trace line", text)
            })?;
            let host = host_pointer(text)
                .ok_or_else(|| format_error(number, "no TB host pointer in a Trace line", text))?;
            t.trace(host, key);
        } else if text.starts_with("IN:") {
            block = Some(Vec::new());
        } else if let Some(rest) = text.strip_prefix("Stopped execution of TB chain before") {
            let pc = trace_key(rest).map(|k| k.0).or_else(|| {
                let open = rest.find('[')?;
                let close = rest.find(']')?;
                hex(rest.get(open + 1..close)?)
            });
            if let Some(pc) = pc {
                t.undo_last(host_pointer(rest), pc);
            }
        } else if let Some(rest) = text.strip_prefix("cpu_io_recompile: rewound execution of TB to")
        {
            if let Some(pc) = hex(rest) {
                t.rewind(pc);
            }
        }
    }
    Ok(summarise(&t, regions))
}

/// Worst-case cycles of one execution of the first `n` instructions of a TB.
fn tb_cycles(insns: &[Insn]) -> u64 {
    let table: u64 = insns.iter().map(|i| u64::from(i.cycles)).sum();
    let bytes: u64 = insns.iter().map(|i| u64::from(i.bytes)).sum();
    table.max(FLASH_LINE_CYCLES * bytes.div_ceil(FLASH_LINE_BYTES)) + BRANCH_MISS_CYCLES
}

#[derive(Default)]
struct Accumulator {
    instructions: u64,
    cycles: u64,
    classes: HashMap<Class, (u64, u64)>,
}

impl Accumulator {
    fn add(&mut self, insns: &[Insn], times: u64) {
        self.instructions += insns.len() as u64 * times;
        self.cycles += tb_cycles(insns) * times;
        for i in insns {
            let e = self.classes.entry(i.class).or_insert((0, 0));
            e.0 += times;
            e.1 += u64::from(i.cycles) * times;
        }
    }

    fn figures(&self) -> Figures {
        let mut classes: Vec<ClassCount> = self
            .classes
            .iter()
            .map(|(&class, &(n, c))| ClassCount {
                class,
                instructions: n,
                fraction: n as f64 / self.instructions.max(1) as f64,
                cycles: c,
            })
            .collect();
        classes.sort_by(|a, b| {
            b.instructions
                .cmp(&a.instructions)
                .then(a.class.cmp(&b.class))
        });
        Figures {
            instructions: self.instructions,
            worst_case_cycles: self.cycles,
            cpi_bound: self.cycles as f64 / self.instructions.max(1) as f64,
            classes,
        }
    }
}

fn summarise(t: &Trace, regions: &[Region]) -> CpiReport {
    let mut total = Accumulator::default();
    let mut idle = Accumulator::default();
    let mut per_region: Vec<Accumulator> = regions.iter().map(|_| Accumulator::default()).collect();
    let mut mnemonics: HashMap<&str, u64> = HashMap::new();
    let mut unknown: HashMap<&str, u64> = HashMap::new();
    for (&(tb, n), &times) in &t.executions {
        let Some(insns) = t.translations.get(tb).and_then(|i| i.get(..n)) else {
            continue;
        };
        if times == 0 || insns.is_empty() {
            continue;
        }
        if t.translations.get(tb).is_some_and(|all| is_idle_loop(all)) {
            idle.add(insns, times);
            continue;
        }
        total.add(insns, times);
        for (region, acc) in regions.iter().zip(per_region.iter_mut()) {
            if region.contains(insns[0].address) {
                acc.add(insns, times);
            }
        }
        for i in insns {
            *mnemonics.entry(&i.mnemonic).or_insert(0) += times;
            if i.class == Class::Unknown {
                *unknown.entry(&i.mnemonic).or_insert(0) += times;
            }
        }
    }
    let sorted = |m: HashMap<&str, u64>, keep: usize| {
        let mut v: Vec<(String, u64)> = m.into_iter().map(|(k, n)| (k.to_string(), n)).collect();
        v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        v.truncate(keep);
        v
    };
    CpiReport {
        total: total.figures(),
        idle: idle.figures(),
        tb_executions: t.tb_executions,
        translations: t.translations.len() as u64,
        untraced_executions: t.untraced,
        abandoned_executions: t.abandoned,
        top_mnemonics: sorted(mnemonics, 20),
        unknown_mnemonics: sorted(unknown, usize::MAX),
        regions: regions
            .iter()
            .zip(per_region)
            .map(|(r, acc)| RegionFigures {
                name: r.name.clone(),
                figures: acc.figures(),
            })
            .collect(),
        justification: JUSTIFICATION.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two TBs: A (4 instructions, 12 bytes) executed 3 times, B (2 instructions)
    /// twice, one execution of B stopped before it ran, one of A rewound after 2
    /// instructions.
    const LOG: &str = "\
----------------
IN: f
0x08000100:  b580       push     {r7, lr}
0x08000102:  f8d0 1004  ldr.w    r1, [r0, #4]
0x08000106:  ee20 0a01  vmul.f32 s0, s0, s2
0x0800010a:  fbb0 f0f1  udiv     r0, r0, r1

Trace 0: 0x7f0000000100 [00800408/08000100/00000110/ff020200] f
----------------
IN: g
0x08000200:  2800       cmp      r0, #0
0x08000202:  d1fd       bne      #0x8000100

Trace 0: 0x7f0000000200 [00800408/08000200/00000110/ff020200] g
Trace 0: 0x7f0000000100 [00800408/08000100/00000110/ff020200] f
Trace 0: 0x7f0000000200 [00800408/08000200/00000110/ff020200] g
Stopped execution of TB chain before 0x7f0000000200 [08000200] g
Trace 0: 0x7f0000000200 [00800408/08000200/00000110/ff020200] g
Trace 0: 0x7f0000000100 [00800408/08000100/00000110/ff020200] f
cpu_io_recompile: rewound execution of TB to 08000100
----------------
IN: f
0x08000106:  ee20 0a01  vmul.f32 s0, s0, s2

Trace 0: 0x7f0000000300 [00800408/08000106/00000110/ff028001] f
Trace 0: 0x7f0000000100 [00800408/08000100/00000110/ff020200] f
";

    #[test]
    fn timing_table() {
        assert_eq!(
            instruction_timing("push", "{r4, r5, r6, r7, lr}"),
            (Class::StoreMultiple, 6)
        );
        assert_eq!(
            instruction_timing("pop", "{r4, r5, r7, pc}"),
            (Class::LoadMultiple, 8)
        );
        assert_eq!(instruction_timing("bls", "#0x8000"), (Class::Branch, 4));
        assert_eq!(
            instruction_timing("movs", "r0, #1"),
            (Class::DataProcessing, 1)
        );
        assert_eq!(
            instruction_timing("muls", "r0, r1, r0"),
            (Class::Multiply, 1)
        );
        assert_eq!(
            instruction_timing("mls", "r0, r1, r2, r3"),
            (Class::Multiply, 2)
        );
        assert_eq!(
            instruction_timing("addseq", "r0, r1"),
            (Class::DataProcessing, 1)
        );
        assert_eq!(instruction_timing("ittet", "eq"), (Class::It, 1));
        assert_eq!(
            instruction_timing("vmov", "r0, s0"),
            (Class::FpuTransfer, 2)
        );
        assert_eq!(instruction_timing("vmov.f32", "s0, #1.0"), (Class::Fpu, 1));
        assert_eq!(
            instruction_timing("vfma.f32", "s0, s1, s2"),
            (Class::FpuMultiplyAccumulate, 3)
        );
        assert_eq!(
            instruction_timing("vpush", "{d8, d9}"),
            (Class::FpuLoadStore, 5)
        );
        assert_eq!(
            instruction_timing("vsqrt.f32", "s0, s0"),
            (Class::FpuDivideSqrt, 14)
        );
        assert_eq!(instruction_timing("ldr", "pc, [r0]"), (Class::Load, 5));
        assert_eq!(instruction_timing("ldrd", "r0, r1, [r2]"), (Class::Load, 3));
        assert_eq!(
            instruction_timing("tbb", "[pc, r0]"),
            (Class::TableBranch, 5)
        );
        assert_eq!(instruction_timing("bkpt", "#0xab"), (Class::Unknown, 4));
    }

    #[test]
    fn synthetic_log_counts_and_cycles() -> Result<(), WcetError> {
        let report = analyse_log(LOG.as_bytes(), None, &[])?;
        // A: 3 full executions + the rewound one's first 2 instructions; B: 2;
        // the 1-instruction I/O TB once.
        assert_eq!(report.total.instructions, 3 * 4 + 2 + 2 * 2 + 1);
        assert_eq!(report.tb_executions, 3 + 2 + 1);
        assert_eq!(report.abandoned_executions, 2);
        // A: push 1+2, ldr 2, vmul 1, udiv 12 = 18 > 6·⌈12/16⌉ → 18 + 5 = 23.
        // A's first two: 3 + 2 = 5 < 6 (fetch floor) → 6 + 5 = 11.
        // B: cmp 1, bne 4 = 5 < 6·1 → 6 + 5 = 11.  I/O TB: vmul 1 < 6 → 11.
        assert_eq!(report.total.worst_case_cycles, 3 * 23 + 11 + 2 * 11 + 11);
        let divides = report
            .total
            .classes
            .iter()
            .find(|c| c.class == Class::Divide);
        assert_eq!(divides.map(|c| c.instructions), Some(3));
        assert!(report.unknown_mnemonics.is_empty());
        Ok(())
    }

    #[test]
    fn regions_and_limits() -> Result<(), WcetError> {
        let region = Region {
            name: "g".into(),
            ranges: vec![(0x0800_0200, 0x0800_0204)],
        };
        let report = analyse_log(LOG.as_bytes(), Some(2), std::slice::from_ref(&region))?;
        assert_eq!(report.tb_executions, 2);
        assert_eq!(report.total.instructions, 6);
        assert_eq!(report.regions[0].figures.instructions, 2);
        assert_eq!(report.regions[0].figures.worst_case_cycles, 11);
        Ok(())
    }

    /// As QEMU 7.2 with `-icount` writes it on the ECU: a TB (4 instructions) rewound
    /// at its third instruction (an I/O store), which then runs as a 1-instruction TB
    /// at the same pc as another translation, and the rest of the block as a third
    /// translation; the interrupted TB's first two instructions ran once.
    const REWIND_MID_TB: &str = "\
----------------
IN: main
0x08000100:  2040       movs     r0, #0x40
0x08000102:  2100       movs     r1, #0
0x08000104:  6008       str      r0, [r1]
0x08000106:  2200       movs     r2, #0

Trace 0: 0x7f0000000100 [00800408/08000100/00000010/ff020200] main
cpu_io_recompile: rewound execution of TB to 08000104
----------------
IN: main
0x08000104:  6008       str      r0, [r1]

Trace 0: 0x7f0000000200 [00800408/08000104/00000010/ff038201] main
----------------
IN: main
0x08000106:  2200       movs     r2, #0

Trace 0: 0x7f0000000300 [00800408/08000106/00000010/ff020200] main
----------------
IN: main
0x08000104:  6008       str      r0, [r1]
0x08000106:  2200       movs     r2, #0

Trace 0: 0x7f0000000400 [00800408/08000104/00000010/ff020200] main
Trace 0: 0x7f0000000200 [00800408/08000104/00000010/ff038201] main
Trace 0: 0x7f0000000400 [00800408/08000104/00000010/ff020200] main
";

    #[test]
    fn rewind_in_the_middle_of_a_tb_counts_each_instruction_once() -> Result<(), WcetError> {
        let report = analyse_log(REWIND_MID_TB.as_bytes(), None, &[])?;
        // 2 (prefix of the rewound TB) + 1 (I/O TB) + 1 (rest) + 2 + 1 + 2.
        assert_eq!(report.total.instructions, 2 + 1 + 1 + 2 + 1 + 2);
        assert_eq!(report.abandoned_executions, 1);
        assert_eq!(report.tb_executions, 5);
        // Prefix movs, movs: 2 < 6 → 11; I/O str 2 → 11; movs → 11; str, movs → 11.
        assert_eq!(report.total.worst_case_cycles, 6 * 11);
        Ok(())
    }

    /// Start-up (one TB), then the idle loop `b .` spinning between two interrupt
    /// handler executions.
    const IDLE: &str = "\
----------------
IN: main
0x08000100:  2040       movs     r0, #0x40
0x08000102:  b662       cpsie    i

Trace 0: 0x7f0000000100 [00800408/08000100/00000010/ff020200] main
----------------
IN: main
0x08000104:  e7fe       b        #0x8000104

Trace 0: 0x7f0000000200 [00800400/08000104/00000010/ff020200] main
Trace 0: 0x7f0000000200 [00800400/08000104/00000010/ff020200] main
Trace 0: 0x7f0000000200 [00800400/08000104/00000010/ff020200] main
----------------
IN: SysTick
0x08000200:  2000       movs     r0, #0
0x08000202:  4770       bx       lr

Trace 0: 0x7f0000000300 [00800408/08000200/00000010/ff020200] SysTick
Trace 0: 0x7f0000000200 [00800400/08000104/00000010/ff020200] main
Trace 0: 0x7f0000000200 [00800400/08000104/00000010/ff020200] main
Trace 0: 0x7f0000000300 [00800408/08000200/00000010/ff020200] SysTick
";

    #[test]
    fn the_idle_loop_is_reported_apart() -> Result<(), WcetError> {
        let report = analyse_log(IDLE.as_bytes(), None, &[])?;
        assert_eq!(report.idle.instructions, 5);
        assert_eq!(report.idle.worst_case_cycles, 5 * 11);
        // Start-up 2 instructions, the handler 2 × 2.
        assert_eq!(report.total.instructions, 2 + 2 * 2);
        assert_eq!(report.total.worst_case_cycles, 3 * 11);
        assert_eq!(report.tb_executions, 8);
        assert!(report.top_mnemonics.iter().all(|(m, _)| m != "b"));
        Ok(())
    }

    #[test]
    fn a_branch_elsewhere_is_not_idle() {
        let insn = |address, mnemonic: &str, target| Insn {
            address,
            bytes: 2,
            cycles: 1,
            class: Class::Branch,
            mnemonic: mnemonic.into(),
            target,
        };
        assert!(is_idle_loop(&[insn(0x10, "b", Some(0x10))]));
        assert!(is_idle_loop(&[
            insn(0x10, "wfi", None),
            insn(0x12, "b", Some(0x10))
        ]));
        assert!(!is_idle_loop(&[insn(0x10, "b", Some(0x20))]));
        assert!(!is_idle_loop(&[
            insn(0x10, "adds", None),
            insn(0x12, "b", Some(0x10))
        ]));
        assert!(!is_idle_loop(&[]));
        assert_eq!(
            parse_in_line("0x08018e26:  e7fe       b        #0x8018e26").and_then(|i| i.target),
            Some(0x0801_8e26)
        );
    }

    /// Tool, not a check: `CPI_LOG=/path/to/qemu.log cargo test --release -p wcet
    /// --lib cpi::tests::analyse_the_log_in_cpi_log -- --ignored --nocapture` prints
    /// the analysis of a saved `-d in_asm,exec,nochain` log (`/dev/stdin` works).
    #[test]
    #[ignore = "needs a QEMU log in CPI_LOG"]
    fn analyse_the_log_in_cpi_log() -> Result<(), Box<dyn std::error::Error>> {
        let path = std::env::var("CPI_LOG")?;
        let file = std::fs::File::open(&path)?;
        let mut report = analyse_log(std::io::BufReader::with_capacity(1 << 20, file), None, &[])?;
        report.justification.clear();
        eprintln!("{}", serde_json::to_string_pretty(&report)?);
        Ok(())
    }

    #[test]
    fn a_broken_trace_line_is_named() {
        let err = analyse_log("Trace 0: garbage\n".as_bytes(), None, &[]);
        assert!(matches!(err, Err(WcetError::LogFormat { line: 1, .. })));
    }
}
