//! Static worst-case stack bound of a thumbv7em ELF.
//!
//! The binary is disassembled with `llvm-objdump -d` (rustup component
//! `llvm-tools`). For every function the frame size is the sum of every
//! stack-pointer decrement in its body (`push`, `stmdb sp!`, `vpush`,
//! `str rX, [sp, #-N]!`, `sub sp, #N`, `sub sp, rX` after `movw`/`movt` into `rX`):
//! the compiler emits one prologue, so this is its size, and any other decrement
//! only makes the bound larger. Calls are `bl`/`blx <symbol>`; a branch to another
//! function (`b.w <other>`) is a tail call and counted like a call (the caller's
//! frame kept: sound, slightly pessimistic). The depth of a function is its frame
//! plus the deepest callee, computed by an iterative depth-first search with
//! memoisation; a cycle in the call graph is reported and makes the bound unsound.
//!
//! **Roots.** The application's priority levels are given (thread mode runs
//! `main`; each interrupt priority its tasks' handlers). With the ELF's vector
//! table ([`super::vector_table`]) every handler it lists is placed, or reported:
//!
//! * `Reset` is thread mode's entry: a root of the thread level;
//! * a handler that is a root of a given level is counted in that level;
//! * HardFault and NMI are counted on top of everything ([`Counted::FaultOnTop`]);
//! * the configurable exceptions and interrupts the application does not bind,
//!   which the vector table points at the default handler (`DefaultHandler`), share
//!   one level on top of the preemption chain ([`Counted::UnboundOnTop`]): the
//!   application leaves them at their reset priority, 0, the highest configurable
//!   one, and exceptions of one priority do not preempt each other;
//! * any other handler has a priority the analysis does not know: each is counted
//!   on top of the chain ([`Counted::OnTop`]), as if it could preempt all the
//!   others;
//! * an entry whose address starts no function of the disassembly cannot be
//!   placed: it is listed ([`StackReport::unplaced_handlers`]) and the bound is
//!   not sound.
//!
//! **Exception frames.** On a Cortex-M4F whose interrupted code has used the FPU
//! (CONTROL.FPCA set) exception entry stacks the extended frame of
//! [`EXCEPTION_FRAME_FPU_BYTES`]. Lazy stacking (FPCCR.LSPEN, the reset state)
//! defers only the stores of s0–s15 and FPSCR: the space is reserved on entry,
//! whatever the exception, so a fault or NMI taken in FPU code reserves 104 B like
//! an interrupt does. CCR.STKALIGN (set at reset) aligns the frame to 8 bytes: one
//! more word when the interrupted stack pointer is 4 mod 8, which code allows
//! between pushes ([`EXCEPTION_ALIGNMENT_PAD_BYTES`]). Every level but thread mode
//! and the once level adds both ([`EXCEPTION_ENTRY_BYTES`]).
//!
//! **Faults (ARMv7-M).** HardFault has the fixed priority −1 and NMI −2; every
//! other exception has a configurable priority ≥ 0. An exception preempts only
//! code of a lower priority: NMI preempts HardFault and everything else, HardFault
//! everything but NMI. Masking interrupts (PRIMASK, `cpsid i`) stops every
//! configurable exception, not HardFault or NMI. A fault raised while the core
//! runs at priority −1 or −2 (in HardFault or NMI) enters no exception: the core
//! locks up, stacking nothing. So at most one HardFault and one NMI frame are on
//! the stack, NMI above HardFault, at any depth of the rest: the bound adds both.
//!
//! **Once.** Functions entered at most once in a run, with interrupts disabled,
//! never returning (the panic path's work, behind a guard) are cut from every
//! chain and counted once, in a level of their own: no interrupt nests on them,
//! and wherever they start (under a priority level, after a panic, or under
//! HardFault, after a fault) one chain of them is on the stack at most.
//!
//! The bound: `max(thread + Σ priority levels + Σ handlers on top, init) + once +
//! HardFault + NMI`, each level its deepest root plus its exception frame, `init`
//! the thread's depth through the functions run with interrupts masked.

use super::disassembly::{parse_disassembly, parse_imm, Instruction};
use super::vector_table::{VectorEntry, HARD_FAULT, NMI, RESET};
use super::{demangle, WcetError};
use serde::Serialize;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Exception frame without FPU context: r0–r3, r12, lr, pc, xPSR, in bytes.
pub const EXCEPTION_FRAME_BASIC_BYTES: u32 = 32;
/// Exception frame with FPU context (adds s0–s15, FPSCR and a reserved word), in
/// bytes; lazy stacking reserves it whenever the FPU is enabled.
pub const EXCEPTION_FRAME_FPU_BYTES: u32 = 104;
/// Padding an exception entry may add below the interrupted code's stack pointer,
/// in bytes: CCR.STKALIGN (set at reset on the Cortex-M4) aligns the frame to 8
/// bytes, one word lower when that pointer is 4 mod 8, as it is between a push of
/// one word and its pop (`vpush {s0}` passing a float argument, a frame whose size
/// is 4 mod 8).
pub const EXCEPTION_ALIGNMENT_PAD_BYTES: u32 = 4;
/// What one exception entry adds to the stack at most, in bytes: the FPU frame and
/// the alignment padding.
pub const EXCEPTION_ENTRY_BYTES: u32 = EXCEPTION_FRAME_FPU_BYTES + EXCEPTION_ALIGNMENT_PAD_BYTES;

/// The stack frame of a function as read from its instructions.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub enum Frame {
    /// Every stack-pointer decrement was understood; their sum, in bytes.
    Known(u32),
    /// Some decrement could not be sized.
    Unknown {
        /// Sum of the decrements that were understood, in bytes (a lower bound).
        known_bytes: u32,
        /// The instruction that could not be sized, with its address.
        reason: String,
    },
}

impl Frame {
    /// The frame size counted in the bound, in bytes (the understood part).
    pub fn bytes(&self) -> u32 {
        match self {
            Frame::Known(b) => *b,
            Frame::Unknown { known_bytes, .. } => *known_bytes,
        }
    }
}

/// A direct call or tail call found in a function.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Call {
    /// Callee symbol as printed by the disassembler (mangled).
    pub target: String,
    /// Address of the call instruction.
    pub address: u32,
    /// `true` for a branch (`b`, `b.w`, `beq.w`) to another function.
    pub tail: bool,
}

/// A function of the disassembly.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Function {
    /// Symbol (mangled, as in the symbol table).
    pub name: String,
    /// Start address.
    pub address: u32,
    /// Stack frame.
    pub frame: Frame,
    /// Direct calls and tail calls.
    pub calls: Vec<Call>,
    /// Indirect calls and jumps (`blx rN`, `bx rN` other than `bx lr`, `mov pc, rN`,
    /// `ldr pc, [..]` not popping from the stack): `address: instruction`.
    pub indirect: Vec<String>,
}

/// The functions of a disassembled binary and the names they are known by.
#[derive(Debug, Clone, Default)]
pub struct Program {
    /// The functions, in address order.
    pub functions: Vec<Function>,
    /// Every name (symbol, alias) to an index into `functions`.
    names: HashMap<String, usize>,
}

impl Program {
    /// Replaces the indirect calls of the functions `targets` covers (the same
    /// rules as the timing analysis's control-flow graphs, [`super::cfg`]) by
    /// calls of every listed target: the stack bound then follows them like
    /// direct calls. A listed target that is no function of the disassembly
    /// leaves the call indirect (and the bound unsound).
    pub fn resolve_indirect(
        &mut self,
        targets: &super::cfg::IndirectTargets,
        demangle: impl Fn(&str) -> String,
    ) {
        let demangled: Vec<String> = self.functions.iter().map(|f| demangle(&f.name)).collect();
        for k in 0..self.functions.len() {
            if self.functions[k].indirect.is_empty() {
                continue;
            }
            let Some(callees) = targets.callees_of(&demangled[k]) else {
                continue;
            };
            // Every listed callee must be a function of the disassembly.
            let mut hits: Vec<usize> = Vec::new();
            let mut all_found = !callees.is_empty();
            for c in callees {
                let found: Vec<usize> = (0..self.functions.len())
                    .filter(|&j| {
                        let symbol = std::iter::once(self.functions[j].name.as_str());
                        super::cfg::IndirectTargets::lists(c, &demangled[j], symbol)
                    })
                    .collect();
                all_found &= !found.is_empty();
                hits.extend(found);
            }
            if !all_found {
                continue;
            }
            hits.sort_unstable();
            hits.dedup();
            let sites = std::mem::take(&mut self.functions[k].indirect);
            for site in sites {
                let address = site
                    .split(':')
                    .next()
                    .and_then(|a| u32::from_str_radix(a.trim().trim_start_matches("0x"), 16).ok())
                    .unwrap_or(0);
                for &j in &hits {
                    let target = self.functions[j].name.clone();
                    self.functions[k].calls.push(Call {
                        target,
                        address,
                        tail: false,
                    });
                }
            }
        }
    }

    /// Looks a function up by its exact (mangled) symbol or alias.
    pub fn get(&self, symbol: &str) -> Option<&Function> {
        self.names.get(symbol).and_then(|&i| self.functions.get(i))
    }

    /// The function starting at `address` (Thumb bit ignored).
    pub fn at(&self, address: u32) -> Option<usize> {
        self.functions
            .iter()
            .position(|f| f.address == address & !1)
    }

    /// Adds `alias` for the function starting at `address` (symbols sharing an
    /// address, e.g. interrupt names bound to `DefaultHandler`, which
    /// `llvm-objdump` prints once). Returns `false` if no function starts there.
    pub fn add_alias(&mut self, alias: &str, address: u32) -> bool {
        match self.at(address) {
            Some(i) => {
                self.names.entry(alias.to_string()).or_insert(i);
                true
            }
            None => false,
        }
    }

    /// Indices of the functions matching `root`: exact symbol, exact demangled name
    /// (without hash), or else every function whose demangled name starts with it.
    fn resolve(&self, root: &str) -> Vec<usize> {
        if let Some(&i) = self.names.get(root) {
            return vec![i];
        }
        let mut exact: Vec<usize> = Vec::new();
        let mut prefix: Vec<usize> = Vec::new();
        let mut names: Vec<(&String, &usize)> = self.names.iter().collect();
        names.sort();
        for (name, &i) in names {
            let d = demangle(name);
            if d == root && !exact.contains(&i) {
                exact.push(i);
            } else if d.starts_with(root) && !prefix.contains(&i) {
                prefix.push(i);
            }
        }
        if exact.is_empty() {
            prefix
        } else {
            exact
        }
    }
}

/// Path of `llvm-objdump` in the active toolchain's `llvm-tools` component.
pub fn llvm_objdump_path() -> Result<PathBuf, WcetError> {
    llvm_tool_path("llvm-objdump")
}

/// Path of an LLVM tool (`llvm-objdump`, `llvm-nm`) of the `llvm-tools` component.
pub fn llvm_tool_path(tool: &str) -> Result<PathBuf, WcetError> {
    let run = |args: &[&str]| -> Result<String, WcetError> {
        let out = Command::new("rustc")
            .args(args)
            .output()
            .map_err(|e| WcetError::Tool {
                tool: "rustc".into(),
                message: e.to_string(),
            })?;
        Ok(String::from_utf8_lossy(&out.stdout).to_string())
    };
    let sysroot = run(&["--print", "sysroot"])?.trim().to_string();
    let host = run(&["-vV"])?
        .lines()
        .find_map(|l| l.strip_prefix("host: "))
        .map(str::to_string)
        .ok_or_else(|| WcetError::Tool {
            tool: "rustc -vV".into(),
            message: "no `host:` line".into(),
        })?;
    let path = Path::new(&sysroot)
        .join("lib/rustlib")
        .join(host)
        .join("bin")
        .join(tool);
    if path.is_file() {
        Ok(path)
    } else {
        Err(WcetError::ObjdumpMissing { searched: path })
    }
}

/// Disassembles `elf` with `llvm-objdump -d --no-show-raw-insn` (mangled names).
pub fn disassemble(elf: &Path) -> Result<String, WcetError> {
    objdump(elf, &["-d", "--no-show-raw-insn"])
}

/// Disassembles `elf` with `llvm-objdump -d`, raw bytes shown (instruction sizes
/// and the data inside `.text`, for the control-flow graphs).
pub fn disassemble_with_bytes(elf: &Path) -> Result<String, WcetError> {
    objdump(elf, &["-d"])
}

fn objdump(elf: &Path, args: &[&str]) -> Result<String, WcetError> {
    let objdump = llvm_objdump_path()?;
    let out = Command::new(&objdump)
        .args(args)
        .arg(elf)
        .output()
        .map_err(|e| WcetError::Tool {
            tool: objdump.display().to_string(),
            message: e.to_string(),
        })?;
    if !out.status.success() {
        return Err(WcetError::Tool {
            tool: objdump.display().to_string(),
            message: String::from_utf8_lossy(&out.stderr).trim().to_string(),
        });
    }
    Ok(String::from_utf8_lossy(&out.stdout).to_string())
}

/// Parses `llvm-objdump -d` text (with or without raw bytes) into functions
/// with frames, calls and indirect jumps: the functions and instructions of
/// [`parse_disassembly`], the parser the control-flow graphs read too. Symbols
/// at one address printed once are known only by that name; add the others with
/// [`Program::add_alias`].
pub fn parse_objdump(text: &str) -> Program {
    let mut program = Program::default();
    for f in parse_disassembly(text) {
        let index = program.functions.len();
        program
            .functions
            .push(analyse_body(&f.name, f.address, &f.instructions));
        for name in f.aliases.iter().chain(std::iter::once(&f.name)) {
            program.names.entry(name.clone()).or_insert(index);
        }
    }
    program
}

/// Number of registers in a list `{r4, r5, d8-d9}`, in bytes (4 per core or
/// s-register, 8 per d-register); `None` if the list is not understood.
fn register_list_bytes(operands: &str) -> Option<u32> {
    let open = operands.find('{')?;
    let close = operands.rfind('}')?;
    let list = operands.get(open + 1..close)?;
    let mut bytes = 0;
    for item in list.split(',').map(str::trim) {
        let (first, last) = item.split_once('-').unwrap_or((item, item));
        let size = match first.chars().next()? {
            'd' => 8,
            _ => 4,
        };
        let number = |r: &str| -> Option<u32> {
            match r {
                "sp" => Some(13),
                "lr" => Some(14),
                "pc" => Some(15),
                "ip" => Some(12),
                "fp" => Some(11),
                "sb" => Some(9),
                "sl" => Some(10),
                _ => r.get(1..)?.parse().ok(),
            }
        };
        let count = number(last)?.checked_sub(number(first)?)? + 1;
        bytes += size * count;
    }
    Some(bytes)
}

/// The base mnemonic without width qualifier (`.w`, `.n`).
fn base(mnemonic: &str) -> &str {
    mnemonic.split('.').next().unwrap_or(mnemonic)
}

const CONDITIONS: [&str; 15] = [
    "eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt",
];

fn is_condition(s: &str) -> bool {
    CONDITIONS.contains(&s) || s == "le" || s == "al"
}

/// `Some(true)` for a call (`bl`, `blx`), `Some(false)` for a jump (`b`, `b<cond>`,
/// `bx`), `None` otherwise.
fn branch(mnemonic: &str) -> Option<bool> {
    let m = base(mnemonic);
    match m {
        "bl" | "blx" => Some(true),
        "b" | "bx" => Some(false),
        _ if m.len() == 3 && m.starts_with('b') && is_condition(&m[1..]) => Some(false),
        _ => None,
    }
}

/// The symbol in `<symbol>` or `<symbol+0x12>` and whether it had an offset.
fn target_symbol(operands: &str) -> Option<(&str, bool)> {
    let open = operands.find('<')?;
    let close = operands.rfind('>')?;
    let inner = operands.get(open + 1..close)?;
    Some(match inner.rfind("+0x") {
        Some(i) => (&inner[..i], true),
        None => (inner, false),
    })
}

fn analyse_body(name: &str, address: u32, body: &[Instruction]) -> Function {
    let mut known: u32 = 0;
    let mut unknown: Option<String> = None;
    let mut calls = Vec::new();
    let mut indirect = Vec::new();
    // Constants moved into registers (movw/movt/mov #imm), for `sub sp, rX`.
    let mut regs: HashMap<&str, u32> = HashMap::new();
    for insn in body {
        let (mnemonic, operands) = (insn.mnemonic.as_str(), insn.operands.as_str());
        let m = base(mnemonic);
        let ops: Vec<&str> = operands.split(',').map(str::trim).collect();
        let first = ops.first().copied().unwrap_or("");
        let here = || format!("{:#x}: {} {}", insn.address, mnemonic, operands);
        let mut decrement = |bytes: Option<u32>| match bytes {
            Some(b) => known = known.saturating_add(b),
            None => {
                unknown.get_or_insert_with(here);
            }
        };
        match m {
            "push" | "vpush" => decrement(register_list_bytes(operands)),
            "stmdb" | "vstmdb" | "stmfd" if first == "sp!" => {
                decrement(register_list_bytes(operands))
            }
            "sub" | "subw" | "subs" if first == "sp" => {
                // `sub sp, #N`, `sub sp, sp, #N`, `sub sp, sp, rX`, `sub sp, rX`;
                // `sub sp, r7, #N` restores from the frame pointer.
                let (src, amount) = match ops.as_slice() {
                    [_, a] => ("sp", *a),
                    [_, s, a] => (*s, *a),
                    _ => ("?", ""),
                };
                if src == "sp" {
                    if amount.starts_with('#') {
                        decrement(parse_imm(amount));
                    } else {
                        decrement(regs.get(amount).copied());
                    }
                }
            }
            _ if m.starts_with("str")
                && operands.contains("[sp, #-")
                && operands.ends_with("]!") =>
            {
                let imm = insn
                    .operands
                    .split("[sp, #-")
                    .nth(1)
                    .and_then(|s| s.split(']').next())
                    .and_then(parse_imm);
                decrement(imm);
            }
            _ => {}
        }
        // Constant tracking.
        match m {
            "movw" | "mov" | "movs" if ops.get(1).is_some_and(|o| o.starts_with('#')) => {
                match ops.get(1).and_then(|o| parse_imm(o)) {
                    Some(v) => {
                        regs.insert(first, v);
                    }
                    None => {
                        regs.remove(first);
                    }
                }
            }
            "movt" => {
                let high = ops.get(1).and_then(|o| parse_imm(o));
                match (regs.get(first), high) {
                    (Some(&low), Some(h)) => {
                        regs.insert(first, (low & 0xffff) | (h << 16));
                    }
                    _ => {
                        regs.remove(first);
                    }
                }
            }
            _ if !(m.starts_with("str")
                || m.starts_with("cmp")
                || m.starts_with("cmn")
                || m.starts_with("tst")
                || m.starts_with("teq")
                || m.starts_with("push")
                || m.starts_with("vpush")) =>
            {
                regs.remove(first);
            }
            _ => {}
        }
        // Calls and indirect jumps.
        let register_operand = first.starts_with('r') || first == "ip" || first == "lr";
        if let Some(is_call) = branch(mnemonic) {
            if let Some((target, _)) = target_symbol(operands) {
                if is_call || target != name {
                    calls.push(Call {
                        target: target.to_string(),
                        address: insn.address,
                        tail: !is_call,
                    });
                }
            } else if register_operand && !(m == "bx" && first == "lr") {
                indirect.push(here());
            }
        } else if (m == "mov" && first == "pc")
            || (m.starts_with("ldr") && first == "pc" && !operands.contains("[sp"))
        {
            indirect.push(here());
        }
    }
    let frame = match unknown {
        None => Frame::Known(known),
        Some(reason) => Frame::Unknown {
            known_bytes: known,
            reason,
        },
    };
    Function {
        name: name.to_string(),
        address,
        frame,
        calls,
        indirect,
    }
}

/// One function on a worst path.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PathEntry {
    /// Demangled name (without hash).
    pub function: String,
    /// Frame counted, in bytes.
    pub frame_bytes: u32,
}

/// The worst-case depth from one root function.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct RootReport {
    /// The root as asked for (symbol or alias), or the matched name for a prefix;
    /// for a handler placed from the vector table alone, its exception's name.
    pub root: String,
    /// Demangled name of the function it resolved to; for a handler placed from
    /// the vector table its exception's symbol or `DefaultHandler` when the
    /// function has that symbol (the disassembly prints one symbol per address).
    pub function: String,
    /// Worst-case stack depth from the root's entry, in bytes (its own frame
    /// included, no exception frame).
    pub depth_bytes: u32,
    /// The call path reaching that depth, root first.
    pub worst_path: Vec<PathEntry>,
    /// The vector-table entries whose handler it is (`HardFault`, `IRQ 37`;
    /// [`super::vector_table::exception_name`]); empty for a root no entry names.
    pub exceptions: Vec<String>,
}

/// How a level's contribution enters the bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Counted {
    /// Thread mode or one interrupt priority of the application: a link of the
    /// preemption chain.
    PriorityLevel,
    /// The exceptions and interrupts the application does not bind, at the
    /// default handler and their reset priority: one level on top of the chain.
    UnboundOnTop,
    /// A handler of a priority the analysis does not know: on top of the chain.
    OnTop,
    /// Functions entered at most once, interrupts disabled: counted once.
    Once,
    /// HardFault or NMI: on top of everything.
    FaultOnTop,
}

impl Counted {
    /// How the report says it.
    pub fn label(self) -> &'static str {
        match self {
            Counted::PriorityLevel => "priority level",
            Counted::UnboundOnTop => "unbound, on top",
            Counted::OnTop => "priority unknown, on top",
            Counted::Once => "once",
            Counted::FaultOnTop => "fault, on top",
        }
    }
}

/// One root of the bound, as `wcet.json`'s `memory.stack_roots` lists it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct StackRoot {
    /// The root's name: as given (`main`, `USART1`) or its exception's.
    pub name: String,
    /// Demangled name of its function.
    pub symbol: String,
    /// The vector-table entries it handles (exception names).
    pub exceptions: Vec<String>,
    /// The level it is counted in.
    pub level: String,
    /// How that level is counted.
    pub counted: Counted,
    /// Its worst-case depth, in bytes (no exception frame).
    pub depth_bytes: u32,
}

/// One priority level: thread mode or the handlers sharing an interrupt priority.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct LevelReport {
    /// The level's name as given.
    pub name: String,
    /// How its contribution enters the bound.
    pub counted: Counted,
    /// Each root of the level.
    pub roots: Vec<RootReport>,
    /// Exception frame and alignment padding stacked on entry to this level, at
    /// most, in bytes ([`EXCEPTION_ENTRY_BYTES`]; 0 in thread mode and the once level).
    pub exception_frame_bytes: u32,
    /// This level's share of the bound: deepest root plus exception frame, in bytes.
    pub contribution_bytes: u32,
}

/// A function whose frame was not understood.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct UnknownFrame {
    /// Demangled name.
    pub function: String,
    /// The instruction not understood, and the bytes counted anyway.
    pub reason: String,
}

/// An indirect call or jump: its target, and so its stack use, is not in the bound.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct IndirectCall {
    /// Demangled name of the function containing it.
    pub function: String,
    /// `address: instruction`.
    pub instruction: String,
}

/// Worst-case stack bound of an application.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StackReport {
    /// Thread mode first, then each preemption level in increasing priority, the
    /// handlers on top of them, the once level, HardFault and NMI.
    pub levels: Vec<LevelReport>,
    /// The bound, in bytes: the larger of the chain (the priority levels and the
    /// handlers on top) and the thread's depth while interrupts are still disabled
    /// (`init_bytes`), plus the once level and the faults on top.
    pub total_bytes: u32,
    /// The thread roots' depth including the functions that run only with
    /// interrupts disabled (the set-up in `init`), in bytes; the thread level's
    /// contribution leaves those out (nothing can preempt them).
    pub init_bytes: u32,
    /// `false` if anything reachable was not analysed: an unknown frame, an indirect
    /// call, a call to a symbol not in the disassembly, a cycle, a vector-table
    /// entry not placed, or handlers outside the given roots (no vector table read).
    pub sound: bool,
    /// Reachable functions whose frame was not understood.
    pub unknown_frames: Vec<UnknownFrame>,
    /// Reachable indirect calls and jumps.
    pub indirect_calls: Vec<IndirectCall>,
    /// Reachable calls to symbols that are not functions of the disassembly:
    /// `caller -> callee`.
    pub unresolved_calls: Vec<String>,
    /// Call-graph cycles reachable from a root (demangled names, the first repeated
    /// at the end): recursion, whose depth the bound does not include.
    pub cycles: Vec<Vec<String>>,
    /// Whether the roots include every handler of a vector table (`false`: the
    /// roots were given, handlers outside them are not covered).
    pub vector_table: bool,
    /// Vector-table entries the bound could not place, each with why.
    pub unplaced_handlers: Vec<String>,
    /// What the analysis covers and misses.
    pub method: String,
}

/// A priority level of the application and its root functions (symbols, demangled
/// names or prefixes of demangled names).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PriorityLevel {
    /// Name in the report, e.g. `thread`, `priority 1`.
    pub name: String,
    /// Root functions, e.g. `main`, `USART1`, `SysTick`.
    pub roots: Vec<String>,
}

impl PriorityLevel {
    /// A level named `name` whose tasks start at `roots`.
    pub fn new(name: &str, roots: &[&str]) -> Self {
        Self {
            name: name.to_string(),
            roots: roots.iter().map(|r| r.to_string()).collect(),
        }
    }

    /// One level per root, in increasing priority: `thread` for the first,
    /// `priority N` for the N-th after it.
    pub fn numbered(roots: &[&str]) -> Vec<Self> {
        let name = |i: usize| match i {
            0 => "thread".to_string(),
            _ => format!("priority {i}"),
        };
        roots
            .iter()
            .enumerate()
            .map(|(i, r)| Self::new(&name(i), &[r]))
            .collect()
    }
}

/// Depths of every function, computed once.
struct Depths {
    depth: Vec<u32>,
    next: Vec<Option<usize>>,
    cycles: Vec<Vec<usize>>,
    unresolved: Vec<(usize, String)>,
}

/// Iterative depth-first search with memoisation over the whole call graph; a
/// call into a function marked in `cut` adds nothing to its caller's depth (that
/// function is counted once, on its own).
fn compute_depths(program: &Program, cut: &[bool]) -> Depths {
    let n = program.functions.len();
    let mut depth = vec![0u32; n];
    let mut next: Vec<Option<usize>> = vec![None; n];
    let mut state = vec![0u8; n]; // 0 unvisited, 1 on the stack, 2 done
    let mut cycles = Vec::new();
    let mut unresolved = Vec::new();
    let edges: Vec<Vec<Option<usize>>> = program
        .functions
        .iter()
        .map(|f| {
            f.calls
                .iter()
                .map(|c| program.names.get(&c.target).copied())
                .collect()
        })
        .collect();
    for start in 0..n {
        if state[start] != 0 {
            continue;
        }
        let mut stack: Vec<(usize, usize)> = vec![(start, 0)];
        state[start] = 1;
        while let Some(&mut (node, ref mut edge)) = stack.last_mut() {
            let callees = &edges[node];
            if *edge < callees.len() {
                let e = *edge;
                *edge += 1;
                match callees[e] {
                    None => {
                        unresolved.push((node, program.functions[node].calls[e].target.clone()))
                    }
                    Some(c) if state[c] == 0 => {
                        state[c] = 1;
                        stack.push((c, 0));
                    }
                    Some(c) if state[c] == 1 => {
                        let from = stack.iter().position(|&(f, _)| f == c).unwrap_or(0);
                        let mut cycle: Vec<usize> = stack[from..].iter().map(|&(f, _)| f).collect();
                        cycle.push(c);
                        cycles.push(cycle);
                    }
                    Some(_) => {}
                }
            } else {
                let mut best: Option<(u32, usize)> = None;
                for &c in callees.iter().flatten() {
                    if cut[c] {
                        continue;
                    }
                    if state[c] == 2 && best.is_none_or(|(d, _)| depth[c] > d) {
                        best = Some((depth[c], c));
                    }
                }
                depth[node] = program.functions[node].frame.bytes() + best.map_or(0, |(d, _)| d);
                next[node] = best.map(|(_, c)| c);
                state[node] = 2;
                stack.pop();
            }
        }
    }
    Depths {
        depth,
        next,
        cycles,
        unresolved,
    }
}

/// Functions reachable from `roots` (roots included), iteratively.
fn reachable(program: &Program, roots: &[usize]) -> Vec<bool> {
    let mut seen = vec![false; program.functions.len()];
    let mut todo: Vec<usize> = roots.to_vec();
    while let Some(f) = todo.pop() {
        if std::mem::replace(&mut seen[f], true) {
            continue;
        }
        for c in &program.functions[f].calls {
            if let Some(&i) = program.names.get(&c.target) {
                if !seen[i] {
                    todo.push(i);
                }
            }
        }
    }
    seen
}

const METHOD: &str = "Static bound from the disassembly: each function's frame is the sum of its \
stack-pointer decrements (push, vpush, stmdb sp!, str [sp, #-N]!, sub sp by an immediate or by a \
movw/movt constant); the depth of a root is the deepest chain of direct calls (bl, blx <symbol>) \
and tail calls (a branch to another function, its caller's frame kept); each preemption level \
adds its deepest handler and 108 bytes of exception entry: the 104-byte FPU frame (lazy stacking \
reserves it for every exception, faults included) and up to 4 bytes that align it to 8. The panic path's work, entered once with interrupts disabled and \
never returning, is counted once as a level of its own; the set-up functions init runs before \
enabling interrupts leave the thread level (the bound is at least their depth plus that once \
level and the faults). Not covered: the targets of indirect calls (function pointers, trait \
objects: listed), recursion (cycles: listed), frames the parser did not understand (listed, their \
understood part counted), inline assembly that moves sp other than by these instructions.";

/// How the roots were found, after [`METHOD`].
const VECTOR_TABLE_METHOD: &str = "Every handler of the vector table is a root: Reset in \
thread mode, the tasks' interrupts in their levels, the exceptions and interrupts the application \
does not bind (the default handler, left at reset priority 0: none preempts another) one level on \
top of the chain, any other handler on top of its own, and HardFault and NMI (priorities -1 and \
-2: at any depth, NMI over HardFault, neither over itself or HardFault over NMI, a fault there \
locks up) on top of everything; an entry that starts no function is listed.";

/// What the roots leave out when no vector table was read.
const NO_VECTOR_TABLE: &str = "No vector table was read: handlers other than the given roots \
(HardFault, NMI) are not in the bound.";

/// Worst-case stack bound of `program` for `levels` (thread mode first, then each
/// preemption level in increasing priority), the roots given, no vector table.
pub fn stack_bound(program: &Program, levels: &[PriorityLevel]) -> Result<StackReport, WcetError> {
    stack_bound_once(program, levels, &[], &[])
}

/// [`stack_bound`] where the functions `once` (e.g. the panic handler's work) are
/// entered at most once in a run, with interrupts disabled, and never return: no
/// interrupt preempts them and one chain of them is on the stack at most, so they
/// are cut from every other chain and counted once, as one more level of the
/// bound (without an exception frame). The functions `masked` run only with
/// interrupts disabled (RTIC's `init` calls them before it enables interrupts):
/// the thread level's contribution leaves them out, and the bound is at least the
/// thread's depth with them (`init_bytes`) plus the once level.
pub fn stack_bound_once(
    program: &Program,
    levels: &[PriorityLevel],
    once: &[String],
    masked: &[String],
) -> Result<StackReport, WcetError> {
    bound(program, levels, once, masked, None)
}

/// [`stack_bound_once`] with every handler of the vector table `vectors` placed
/// (the module's **Roots**): HardFault, NMI and the handlers the levels do not
/// name are counted on top; an entry that starts no function of `program` is
/// listed in [`StackReport::unplaced_handlers`] and makes the bound unsound.
pub fn stack_bound_vectors(
    program: &Program,
    levels: &[PriorityLevel],
    once: &[String],
    masked: &[String],
    vectors: &[VectorEntry],
) -> Result<StackReport, WcetError> {
    bound(program, levels, once, masked, Some(vectors))
}

/// A root before its depth is known.
struct Root {
    name: String,
    index: usize,
    exceptions: Vec<String>,
    /// The symbol to name its function by, when the disassembly printed another
    /// one of that address (`WWDG` for `DefaultHandler`).
    symbol: Option<String>,
}

/// A level before its depths are known.
struct Level {
    name: String,
    counted: Counted,
    exception_frame_bytes: u32,
    roots: Vec<Root>,
}

/// The given levels' roots, resolved.
fn given_levels(program: &Program, levels: &[PriorityLevel]) -> Result<Vec<Level>, WcetError> {
    let mut out = Vec::new();
    for (k, level) in levels.iter().enumerate() {
        let mut roots = Vec::new();
        for root in &level.roots {
            let found = program.resolve(root);
            if found.is_empty() {
                return Err(WcetError::UnknownRoot(root.clone()));
            }
            for index in found {
                let function = demangle(&program.functions[index].name);
                let exact = program.names.get(root) == Some(&index) || function == *root;
                roots.push(Root {
                    name: if exact { root.clone() } else { function },
                    index,
                    exceptions: Vec::new(),
                    symbol: None,
                });
            }
        }
        out.push(Level {
            name: level.name.clone(),
            counted: Counted::PriorityLevel,
            // Thread mode stacks no exception frame; every interrupt priority does.
            exception_frame_bytes: if k == 0 { 0 } else { EXCEPTION_ENTRY_BYTES },
            roots,
        });
    }
    Ok(out)
}

/// Places every entry of `vectors` (the module's **Roots**): into `levels`, or in
/// the levels returned (the handlers on top of the chain, then the faults on top
/// of everything); what cannot be placed goes to `unplaced`.
fn place_vectors(
    program: &Program,
    levels: &mut [Level],
    vectors: &[VectorEntry],
    unplaced: &mut Vec<String>,
) -> (Vec<Level>, Vec<Level>) {
    let default = program.names.get(DEFAULT_HANDLER).copied();
    // A handler's function is named by its exception's symbol (`Reset`,
    // `HardFault`) or the default handler's when they are symbols of it.
    let symbol = |name: &str, index: usize| {
        [name, DEFAULT_HANDLER]
            .into_iter()
            .find(|s| program.names.get(*s) == Some(&index))
            .map(str::to_string)
    };
    let mut unbound: Vec<String> = Vec::new();
    let mut on_top = Vec::new();
    let mut faults = Vec::new();
    let single = |name: String, counted, index| Level {
        name: format!("{name} ({})", counted_level_name(counted)),
        counted,
        exception_frame_bytes: EXCEPTION_ENTRY_BYTES,
        roots: vec![Root {
            symbol: symbol(&name, index),
            name: name.clone(),
            index,
            exceptions: vec![name],
        }],
    };
    for entry in vectors {
        let name = entry.name();
        let Some(index) = program.at(entry.address) else {
            unplaced.push(format!(
                "{name} (vector {}) -> {:#010x}: no function of the disassembly starts there, \
                 so its stack use is unknown (a handler without a symbol, or a vector table \
                 that does not hold handlers)",
                entry.exception, entry.address
            ));
            continue;
        };
        // HardFault and NMI first: fixed priorities above every level, whatever
        // function handles them.
        if entry.exception == NMI || entry.exception == HARD_FAULT {
            faults.push((entry.exception, single(name, Counted::FaultOnTop, index)));
            continue;
        }
        // A handler that is a root of a given level runs at that level (RTIC binds
        // each task's interrupt to a handler of its own). The default handler
        // serves many entries: only the one a level names (`SysTick`) is that
        // level's; the others are unbound.
        let known = levels.iter_mut().find_map(|l| {
            l.roots.iter_mut().find(|r| {
                r.index == index
                    && l.counted == Counted::PriorityLevel
                    && (Some(index) != default || r.name == name)
            })
        });
        if let Some(root) = known {
            root.exceptions.push(name);
        } else if entry.exception == RESET {
            match levels.first_mut() {
                Some(thread) => thread.roots.push(Root {
                    symbol: symbol(&name, index),
                    name: name.clone(),
                    index,
                    exceptions: vec![name],
                }),
                None => unplaced.push(format!(
                    "{name} -> {:#010x}: no thread level to count thread mode's entry in \
                     (give the application's levels, thread mode first)",
                    entry.address
                )),
            }
        } else if Some(index) == default {
            unbound.push(name);
        } else {
            on_top.push(single(name, Counted::OnTop, index));
        }
    }
    let mut above_chain = Vec::new();
    if let (Some(index), false) = (default, unbound.is_empty()) {
        above_chain.push(Level {
            name: format!("unbound exceptions and interrupts ({})", DEFAULT_HANDLER),
            counted: Counted::UnboundOnTop,
            exception_frame_bytes: EXCEPTION_ENTRY_BYTES,
            roots: vec![Root {
                name: DEFAULT_HANDLER.to_string(),
                index,
                exceptions: unbound,
                symbol: Some(DEFAULT_HANDLER.to_string()),
            }],
        });
    }
    above_chain.extend(on_top);
    // HardFault below NMI, as they nest.
    faults.sort_by_key(|(exception, _)| std::cmp::Reverse(*exception));
    (above_chain, faults.into_iter().map(|(_, l)| l).collect())
}

/// The level name's suffix for a handler counted `counted`.
fn counted_level_name(counted: Counted) -> &'static str {
    match counted {
        Counted::FaultOnTop => "on top of everything",
        _ => "priority unknown, on top of the chain",
    }
}

/// The default handler's symbol (cortex-m-rt): the vector table's entry for every
/// exception and interrupt the application does not bind.
pub const DEFAULT_HANDLER: &str = "DefaultHandler";

/// The stack bound of `program` with its priority `levels`, the `once` roots
/// (entered once with interrupts disabled, never returning), the `masked` ones
/// (run only before interrupts are enabled: left out of the levels' depths, in
/// `init_bytes`) and the vector table's entries when known
/// ([`stack_bound_once`], [`stack_bound_vectors`]).
///
/// The phases: the call depths (with and without the init-only roots), the
/// levels placed (given, from the vector table, once, faults), each level's
/// deepest root, what the bound cannot see, then the sum.
fn bound(
    program: &Program,
    levels: &[PriorityLevel],
    once: &[String],
    masked: &[String],
    vectors: Option<&[VectorEntry]>,
) -> Result<StackReport, WcetError> {
    let mut cut = vec![false; program.functions.len()];
    mark_roots(program, once, &mut cut)?;
    let init_depths = compute_depths(program, &cut);
    mark_roots(program, masked, &mut cut)?;
    let depths = compute_depths(program, &cut);

    let (placed, unplaced_handlers) = place_levels(program, levels, once, vectors)?;
    let init_bytes = placed
        .first()
        .filter(|l| !levels.is_empty() && l.counted == Counted::PriorityLevel)
        .map(|l| {
            l.roots
                .iter()
                .map(|r| init_depths.depth[r.index])
                .max()
                .unwrap_or(0)
        })
        .unwrap_or(0);
    let mut all_roots = Vec::new();
    let level_reports: Vec<LevelReport> = placed
        .into_iter()
        .map(|level| level_report(program, &depths, level, &mut all_roots))
        .collect();
    let gaps = StackGaps::find(program, &depths, &all_roots);
    let sum = |which: &[Counted]| -> u32 {
        level_reports
            .iter()
            .filter(|l| which.contains(&l.counted))
            .map(|l| l.contribution_bytes)
            .sum()
    };
    let chain = sum(&[
        Counted::PriorityLevel,
        Counted::UnboundOnTop,
        Counted::OnTop,
    ]);
    let total_bytes = chain.max(init_bytes) + sum(&[Counted::Once]) + sum(&[Counted::FaultOnTop]);
    let sound = gaps.is_empty() && unplaced_handlers.is_empty() && vectors.is_some();
    let method = match vectors {
        Some(_) => format!("{METHOD} {VECTOR_TABLE_METHOD}"),
        None => format!("{METHOD} {NO_VECTOR_TABLE}"),
    };
    Ok(StackReport {
        levels: level_reports,
        total_bytes,
        init_bytes,
        sound,
        unknown_frames: gaps.unknown_frames,
        indirect_calls: gaps.indirect_calls,
        unresolved_calls: gaps.unresolved_calls,
        cycles: gaps.cycles,
        vector_table: vectors.is_some(),
        unplaced_handlers,
        method,
    })
}

/// Marks the functions of the roots `names` in `cut` (their calls not followed
/// in the depths); refuses a name no function has.
fn mark_roots(program: &Program, names: &[String], cut: &mut [bool]) -> Result<(), WcetError> {
    for root in names {
        let found = program.resolve(root);
        if found.is_empty() {
            return Err(WcetError::UnknownRoot(root.clone()));
        }
        for i in found {
            cut[i] = true;
        }
    }
    Ok(())
}

/// Every level, in the order they stack: the given `levels`, the vector table's
/// handlers above them, the `once` roots, then the faults; with the handlers
/// the vector table could not place.
fn place_levels(
    program: &Program,
    levels: &[PriorityLevel],
    once: &[String],
    vectors: Option<&[VectorEntry]>,
) -> Result<(Vec<Level>, Vec<String>), WcetError> {
    let mut placed = given_levels(program, levels)?;
    let mut unplaced_handlers = Vec::new();
    let (above_chain, faults) = match vectors {
        Some(v) => place_vectors(program, &mut placed, v, &mut unplaced_handlers),
        None => (Vec::new(), Vec::new()),
    };
    placed.extend(above_chain);
    if !once.is_empty() {
        let mut roots = Vec::new();
        for root in once {
            for index in program.resolve(root) {
                roots.push(Root {
                    name: demangle(&program.functions[index].name),
                    index,
                    exceptions: Vec::new(),
                    symbol: None,
                });
            }
        }
        placed.push(Level {
            name: "once (interrupts disabled, never returns)".into(),
            counted: Counted::Once,
            exception_frame_bytes: 0,
            roots,
        });
    }
    placed.extend(faults);
    Ok((placed, unplaced_handlers))
}

/// One level's report: each root's depth and worst path, the deepest with the
/// exception frame its contribution; its roots added to `all_roots`.
fn level_report(
    program: &Program,
    depths: &Depths,
    level: Level,
    all_roots: &mut Vec<usize>,
) -> LevelReport {
    let mut roots = Vec::new();
    for root in level.roots {
        all_roots.push(root.index);
        let mut worst_path = Vec::new();
        let mut at = Some(root.index);
        let function = root
            .symbol
            .unwrap_or_else(|| demangle(&program.functions[root.index].name));
        while let Some(f) = at {
            let func = &program.functions[f];
            worst_path.push(PathEntry {
                function: if f == root.index {
                    function.clone()
                } else {
                    demangle(&func.name)
                },
                frame_bytes: func.frame.bytes(),
            });
            at = depths.next[f];
        }
        roots.push(RootReport {
            root: root.name,
            function,
            depth_bytes: depths.depth[root.index],
            worst_path,
            exceptions: root.exceptions,
        });
    }
    let deepest = roots.iter().map(|r| r.depth_bytes).max().unwrap_or(0);
    LevelReport {
        name: level.name,
        counted: level.counted,
        roots,
        exception_frame_bytes: level.exception_frame_bytes,
        contribution_bytes: deepest + level.exception_frame_bytes,
    }
}

/// What the stack bound cannot see in the functions the roots reach.
struct StackGaps {
    unknown_frames: Vec<UnknownFrame>,
    indirect_calls: Vec<IndirectCall>,
    unresolved_calls: Vec<String>,
    cycles: Vec<Vec<String>>,
}

impl StackGaps {
    /// The gaps of the functions `all_roots` reach: frames of unknown size,
    /// indirect calls, calls to no function, recursions.
    fn find(program: &Program, depths: &Depths, all_roots: &[usize]) -> Self {
        let seen = reachable(program, all_roots);
        let mut unknown_frames = Vec::new();
        let mut indirect_calls = Vec::new();
        for (f, func) in program.functions.iter().enumerate() {
            if !seen[f] {
                continue;
            }
            if let Frame::Unknown {
                known_bytes,
                reason,
            } = &func.frame
            {
                unknown_frames.push(UnknownFrame {
                    function: demangle(&func.name),
                    reason: format!("{reason} (counted {known_bytes} B)"),
                });
            }
            for instruction in &func.indirect {
                indirect_calls.push(IndirectCall {
                    function: demangle(&func.name),
                    instruction: instruction.clone(),
                });
            }
        }
        let unresolved_calls: Vec<String> = depths
            .unresolved
            .iter()
            .filter(|(f, _)| seen[*f])
            .map(|(f, callee)| format!("{} -> {}", demangle(&program.functions[*f].name), callee))
            .collect();
        let cycles: Vec<Vec<String>> = depths
            .cycles
            .iter()
            .filter(|c| c.iter().any(|&f| seen[f]))
            .map(|c| {
                c.iter()
                    .map(|&f| demangle(&program.functions[f].name))
                    .collect()
            })
            .collect();
        Self {
            unknown_frames,
            indirect_calls,
            unresolved_calls,
            cycles,
        }
    }

    /// Whether there is none (the bound is sound as far as the program goes).
    fn is_empty(&self) -> bool {
        self.unknown_frames.is_empty()
            && self.indirect_calls.is_empty()
            && self.unresolved_calls.is_empty()
            && self.cycles.is_empty()
    }
}

impl StackReport {
    /// Every root of the bound, level by level.
    pub fn roots(&self) -> Vec<StackRoot> {
        self.levels
            .iter()
            .flat_map(|l| {
                l.roots.iter().map(move |r| StackRoot {
                    name: r.root.clone(),
                    symbol: r.function.clone(),
                    exceptions: r.exceptions.clone(),
                    level: l.name.clone(),
                    counted: l.counted,
                    depth_bytes: r.depth_bytes,
                })
            })
            .collect()
    }

    /// The bound as a sum of its levels' contributions, e.g. `max(thread 820 B +
    /// … = 7000 B, init 4000 B) + once 828 B + HardFault (…) 128 B = 7956 B`.
    pub fn formula(&self) -> String {
        let terms = |which: &[Counted]| -> Vec<String> {
            self.levels
                .iter()
                .filter(|l| which.contains(&l.counted))
                .map(|l| format!("{} {} B", l.name, l.contribution_bytes))
                .collect()
        };
        let chain_levels = [
            Counted::PriorityLevel,
            Counted::UnboundOnTop,
            Counted::OnTop,
        ];
        let chain: u32 = self
            .levels
            .iter()
            .filter(|l| chain_levels.contains(&l.counted))
            .map(|l| l.contribution_bytes)
            .sum();
        let mut out = format!(
            "max({} = {chain} B, init {} B)",
            terms(&chain_levels).join(" + "),
            self.init_bytes
        );
        for term in terms(&[Counted::Once, Counted::FaultOnTop]) {
            out += &format!(" + {term}");
        }
        out + &format!(" = {} B", self.total_bytes)
    }
}

/// Disassembles `elf`, adds every function symbol of its symbol table as an alias
/// (interrupt handlers bound to `DefaultHandler` share its address), and bounds the
/// stack of `levels` and of every handler of its vector table.
pub fn analyse_elf(elf: &Path, levels: &[PriorityLevel]) -> Result<StackReport, WcetError> {
    analyse_elf_once(elf, levels, &[], &[], &Default::default())
}

/// [`analyse_elf`] with functions counted once and functions run only with
/// interrupts disabled ([`stack_bound_once`]), and the indirect calls resolved by
/// `targets` ([`Program::resolve_indirect`]).
pub fn analyse_elf_once(
    elf: &Path,
    levels: &[PriorityLevel],
    once: &[String],
    masked: &[String],
    targets: &super::cfg::IndirectTargets,
) -> Result<StackReport, WcetError> {
    let text = disassemble(elf)?;
    let mut program = parse_objdump(&text);
    for symbol in super::cpi::elf_functions(elf)? {
        program.add_alias(&symbol.name, symbol.address);
    }
    program.resolve_indirect(targets, super::demangle);
    let vectors = super::vector_table::read_vector_table(elf)?;
    stack_bound_vectors(&program, levels, once, masked, &vectors)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// One exception entry, in bytes.
    const E: u32 = EXCEPTION_ENTRY_BYTES;

    /// The thread level with root `roots[0]`, then `priority i` with root `roots[i]`.
    pub(crate) fn levels(roots: &[&str]) -> Vec<PriorityLevel> {
        PriorityLevel::numbered(roots)
    }

    /// The bound of `levels` with a vector table read that lists no handler: only
    /// what the roots reach decides whether it is sound.
    fn bound_with_empty_vector_table(
        p: &Program,
        levels: &[PriorityLevel],
    ) -> Result<StackReport, WcetError> {
        let report = stack_bound_vectors(p, levels, &[], &[], &[])?;
        assert!(report.vector_table);
        Ok(report)
    }

    /// A hand-written disassembly: `main` calls `leaf` and `big` (large frame via
    /// movw/movt), `big` tail-calls `leaf`; `handler` calls through a register.
    const FIXTURE: &str = "
firmware:\tfile format elf32-littlearm

Disassembly of section .text:

08000100 <main>:
 8000100:      \tpush\t{r4, r5, r6, r7, lr}
 8000102:      \tadd\tr7, sp, #0xc
 8000104:      \tvpush\t{d8, d9}
 8000108:      \tsub\tsp, #0x10
 800010a:      \tbl\t0x8000200 <leaf>          @ imm = #0xf4
 800010e:      \tbl\t0x8000300 <big>           @ imm = #0x1f0
 8000112:      \tbeq\t0x8000100 <main+0x0>     @ imm = #-0x16
 8000114:      \tadd\tsp, #0x10
 8000116:      \tvpop\t{d8, d9}
 800011a:      \tpop\t{r4, r5, r6, r7, pc}

08000200 <leaf>:
 8000200:      \tpush.w\t{r4, r5, r6, r7, r8, r9, r10, r11, lr}
 8000204:      \tsub.w\tsp, sp, #0x400
 8000208:      \tadd.w\tsp, sp, #0x400
 800020c:      \tpop.w\t{r4, r5, r6, r7, r8, r9, r10, r11, pc}

08000300 <big>:
 8000300:      \tpush\t{r7, lr}
 8000302:      \tmovw\tr12, #0x2345
 8000306:      \tmovt\tr12, #0x1
 800030a:      \tsub.w\tsp, sp, r12
 800030e:      \tsub.w\tsp, r7, #0x8
 8000312:      \tpop.w\t{r7, lr}
 8000316:      \tb.w\t0x8000200 <leaf>         @ imm = #-0x11a

08000400 <handler>:
 8000400:      \tstr\tr11, [sp, #-4]!
 8000404:      \tldr\tr2, [r0]
 8000406:      \tblx\tr2
 8000408:      \tbx\tlr
";

    fn program() -> Program {
        parse_objdump(FIXTURE)
    }

    #[test]
    fn prologues_give_frame_sizes() {
        let p = program();
        // 5 core registers + 2 d-registers + 16 B.
        assert_eq!(
            p.get("main").map(|f| f.frame.clone()),
            Some(Frame::Known(20 + 16 + 16))
        );
        assert_eq!(
            p.get("leaf").map(|f| f.frame.clone()),
            Some(Frame::Known(36 + 0x400))
        );
        // push {r7, lr} + 0x12345 through r12; `sub.w sp, r7, #8` is a restore.
        assert_eq!(
            p.get("big").map(|f| f.frame.clone()),
            Some(Frame::Known(8 + 0x12345))
        );
        assert_eq!(
            p.get("handler").map(|f| f.frame.clone()),
            Some(Frame::Known(4))
        );
    }

    #[test]
    fn call_edges_and_tail_calls() {
        let p = program();
        let main = p.get("main").map(|f| f.calls.clone()).unwrap_or_default();
        let targets: Vec<(&str, bool)> = main.iter().map(|c| (c.target.as_str(), c.tail)).collect();
        // The branch back into main itself is not a call.
        assert_eq!(targets, vec![("leaf", false), ("big", false)]);
        let big = p.get("big").map(|f| f.calls.clone()).unwrap_or_default();
        assert_eq!(big.len(), 1);
        assert!(big.iter().all(|c| c.tail && c.target == "leaf"));
    }

    #[test]
    fn worst_path_and_preemption_levels() -> Result<(), WcetError> {
        let p = program();
        let levels = levels(&["main", "leaf"]);
        let report = stack_bound(&p, &levels)?;
        let main = 52;
        let leaf = 36 + 0x400;
        let big = 8 + 0x12345;
        let thread = &report.levels[0].roots[0];
        assert_eq!(thread.depth_bytes, main + big + leaf);
        let path: Vec<&str> = thread
            .worst_path
            .iter()
            .map(|e| e.function.as_str())
            .collect();
        assert_eq!(path, vec!["main", "big", "leaf"]);
        assert_eq!(report.levels[1].contribution_bytes, leaf + E);
        assert_eq!(report.total_bytes, main + big + leaf + leaf + E);
        assert!(report.indirect_calls.is_empty() && report.cycles.is_empty());
        // No vector table: the handlers outside the roots are not covered.
        assert!(!report.sound && !report.vector_table, "{report:?}");
        Ok(())
    }

    #[test]
    fn a_clean_program_with_its_vector_table_read_is_sound() -> Result<(), WcetError> {
        let report = bound_with_empty_vector_table(&program(), &levels(&["main", "leaf"]))?;
        assert!(report.sound, "{report:?}");
        Ok(())
    }

    #[test]
    fn indirect_call_makes_the_bound_unsound() -> Result<(), WcetError> {
        let report = bound_with_empty_vector_table(&program(), &levels(&["handler"]))?;
        assert!(!report.sound);
        assert_eq!(report.indirect_calls.len(), 1);
        assert_eq!(report.indirect_calls[0].function, "handler");
        assert!(report.indirect_calls[0].instruction.contains("blx r2"));
        Ok(())
    }

    #[test]
    fn a_function_counted_once_is_cut_from_every_level_and_added_once() -> Result<(), WcetError> {
        // `t` and `h` both call `stop` (1 KiB frame), which runs with interrupts off.
        let text = "
08000000 <t>:
 8000000:      \tpush\t{r7, lr}
 8000002:      \tbl\t0x8000020 <stop>
08000010 <h>:
 8000010:      \tpush\t{r4, r5, r7, lr}
 8000012:      \tbl\t0x8000020 <stop>
08000020 <stop>:
 8000020:      \tsub.w\tsp, sp, #0x400
 8000024:      \tb\t0x8000020 <stop>
";
        let levels = levels(&["t", "h"]);
        let p = parse_objdump(text);
        let every = stack_bound(&p, &levels)?;
        assert_eq!(every.total_bytes, (8 + 1024) + (16 + 1024 + E));
        let once = stack_bound_once(&p, &levels, &["stop".to_string()], &[])?;
        assert_eq!(once.total_bytes, 8 + (16 + E) + 1024);
        assert_eq!(once.levels.len(), 3);
        assert_eq!(once.levels[2].exception_frame_bytes, 0);
        Ok(())
    }

    #[test]
    fn functions_run_with_interrupts_disabled_leave_the_thread_level() -> Result<(), WcetError> {
        // `main` calls `setup` (2 KiB, interrupts disabled) then `idle`; `h` preempts.
        let text = "
08000000 <main>:
 8000000:      \tpush\t{r7, lr}
 8000002:      \tbl\t0x8000020 <setup>
 8000006:      \tbl\t0x8000030 <idle>
08000010 <h>:
 8000010:      \tpush\t{r4, r5, r7, lr}
 8000012:      \tsub\tsp, #0x100
08000020 <setup>:
 8000020:      \tsub.w\tsp, sp, #0x800
 8000024:      \tbx\tlr
08000030 <idle>:
 8000030:      \tpush\t{r7, lr}
 8000032:      \tb\t0x8000030 <idle>
";
        let levels = levels(&["main", "h"]);
        let p = parse_objdump(text);
        let h = 16 + 256 + E;
        assert_eq!(stack_bound(&p, &levels)?.total_bytes, 8 + 2048 + h);
        let r = stack_bound_once(&p, &levels, &[], &["setup".to_string()])?;
        assert_eq!(r.init_bytes, 8 + 2048);
        assert_eq!(r.levels[0].contribution_bytes, 8 + 8);
        // The set-up alone is deeper than idle under the handler.
        assert_eq!(r.total_bytes, (8 + 2048).max(8 + 8 + h));
        Ok(())
    }

    #[test]
    fn cycles_are_found_and_reported() -> Result<(), WcetError> {
        let text = "
08000000 <a>:
 8000000:      \tpush\t{r7, lr}
 8000002:      \tbl\t0x8000010 <b>
08000010 <b>:
 8000010:      \tpush\t{r4, lr}
 8000012:      \tbl\t0x8000000 <a>
 8000016:      \tbl\t0x8000020 <c>
08000020 <c>:
 8000020:      \tbx\tlr
";
        let report = bound_with_empty_vector_table(&parse_objdump(text), &levels(&["a"]))?;
        assert!(!report.sound);
        assert_eq!(
            report.cycles,
            vec![vec!["a".to_string(), "b".into(), "a".into()]]
        );
        Ok(())
    }

    #[test]
    fn unknown_frame_is_reported_not_zero() -> Result<(), WcetError> {
        let text = "
08000000 <f>:
 8000000:      \tpush\t{r7, lr}
 8000002:      \tsub.w\tsp, sp, r3
 8000006:      \tbx\tlr
";
        let p = parse_objdump(text);
        assert!(matches!(
            p.get("f").map(|f| f.frame.clone()),
            Some(Frame::Unknown { known_bytes: 8, .. })
        ));
        let report = bound_with_empty_vector_table(&p, &levels(&["f"]))?;
        assert!(!report.sound);
        assert_eq!(report.unknown_frames.len(), 1);
        Ok(())
    }

    /// A hand-written application: `Reset` calls `main` (284 B deep through
    /// `work`); `USART1` (72 B) is the only priority level; `HardFault` has a frame
    /// of `hard_fault_frame` bytes (8 B pushed, the rest by `sub.w`) and calls
    /// `stop`, the once function (48 B), which `work` reaches too (a panic);
    /// `DefaultHandler` (8 B) loops; `PendSV` (24 B) is a handler of its own.
    fn app(hard_fault_frame: u32) -> String {
        format!(
            "
08000000 <Reset>:
 8000000:      \tbl\t0x8000010 <main>
08000010 <main>:
 8000010:      \tpush\t{{r7, lr}}
 8000012:      \tbl\t0x8000020 <work>
08000020 <work>:
 8000020:      \tpush\t{{r4, r5, r6, r7, lr}}
 8000022:      \tsub\tsp, #0x100
 8000024:      \tbl\t0x8000060 <stop>
08000030 <USART1>:
 8000030:      \tpush\t{{r4, lr}}
 8000032:      \tsub\tsp, #0x40
08000040 <HardFault>:
 8000040:      \tpush\t{{r7, lr}}
 8000042:      \tsub.w\tsp, sp, #{:#x}
 8000046:      \tbl\t0x8000060 <stop>
08000050 <DefaultHandler>:
 8000050:      \tpush\t{{r7, lr}}
 8000052:      \tb\t0x8000052 <DefaultHandler+0x2>
08000060 <stop>:
 8000060:      \tsub\tsp, #0x30
 8000062:      \tb\t0x8000062 <stop+0x2>
08000070 <PendSV>:
 8000070:      \tpush\t{{r4, r5, r6, r7, r8, lr}}
",
            hard_fault_frame - 8
        )
    }

    /// The vector table of [`app`]: Reset, NMI and IRQ 1–3 at the default handler,
    /// HardFault, PendSV, USART1 at IRQ 0.
    fn app_vectors() -> Vec<VectorEntry> {
        let at = |exception: u32, address: u32| VectorEntry { exception, address };
        vec![
            at(1, 0x0800_0000),
            at(2, 0x0800_0050),
            at(3, 0x0800_0040),
            at(14, 0x0800_0070),
            at(16, 0x0800_0030),
            at(17, 0x0800_0050),
            at(18, 0x0800_0050),
            at(19, 0x0800_0050),
        ]
    }

    fn app_levels() -> Vec<PriorityLevel> {
        levels(&["main", "USART1"])
    }

    fn app_bound(hard_fault_frame: u32, vectors: &[VectorEntry]) -> Result<StackReport, WcetError> {
        let p = parse_objdump(&app(hard_fault_frame));
        stack_bound_vectors(&p, &app_levels(), &["stop".to_string()], &[], vectors)
    }

    #[test]
    fn every_vector_table_handler_is_placed_and_counted() -> Result<(), WcetError> {
        let r = app_bound(16, &app_vectors())?;
        assert!(
            r.sound && r.vector_table && r.unplaced_handlers.is_empty(),
            "{r:?}"
        );
        let names: Vec<(&str, Counted, u32)> = r
            .levels
            .iter()
            .map(|l| (l.name.as_str(), l.counted, l.contribution_bytes))
            .collect();
        let thread = 8 + 276;
        assert_eq!(
            names,
            vec![
                ("thread", Counted::PriorityLevel, thread),
                ("priority 1", Counted::PriorityLevel, 72 + E),
                (
                    "unbound exceptions and interrupts (DefaultHandler)",
                    Counted::UnboundOnTop,
                    8 + E
                ),
                (
                    "PendSV (priority unknown, on top of the chain)",
                    Counted::OnTop,
                    24 + E
                ),
                (
                    "once (interrupts disabled, never returns)",
                    Counted::Once,
                    48
                ),
                // `stop` is cut from HardFault's chain: it is counted once.
                (
                    "HardFault (on top of everything)",
                    Counted::FaultOnTop,
                    16 + E
                ),
                ("NMI (on top of everything)", Counted::FaultOnTop, 8 + E),
            ]
        );
        assert_eq!(
            r.total_bytes,
            thread + (72 + E) + (8 + E) + (24 + E) + 48 + (16 + E) + (8 + E)
        );
        // Every entry is some root's, once; Reset joined main in thread mode.
        let roots = r.roots();
        let mut listed: Vec<&str> = roots
            .iter()
            .flat_map(|root| root.exceptions.iter().map(String::as_str))
            .collect();
        listed.sort_unstable();
        let mut want: Vec<String> = app_vectors().iter().map(VectorEntry::name).collect();
        want.sort_unstable();
        assert_eq!(listed, want);
        let reset = roots.iter().find(|root| root.name == "Reset");
        assert_eq!(
            reset.map(|root| (root.level.as_str(), root.depth_bytes)),
            Some(("thread", thread))
        );
        let usart1 = roots.iter().find(|root| root.name == "USART1");
        assert_eq!(
            usart1.map(|root| root.exceptions.clone()),
            Some(vec!["IRQ 0".to_string()])
        );
        assert!(r.formula().ends_with(&format!("= {} B", r.total_bytes)));
        Ok(())
    }

    #[test]
    fn a_fault_handler_with_a_deep_frame_raises_the_bound_by_its_frame_and_exception_frame(
    ) -> Result<(), WcetError> {
        let vectors = app_vectors();
        let without: Vec<VectorEntry> = vectors
            .iter()
            .copied()
            .filter(|e| e.exception != HARD_FAULT)
            .collect();
        let frame = 2048 + 8;
        let shallow = app_bound(frame, &without)?;
        let deep = app_bound(frame, &vectors)?;
        assert_eq!(deep.total_bytes - shallow.total_bytes, frame + E);
        // Only the given roots: HardFault is left out, and the report says so.
        let given = stack_bound_once(
            &parse_objdump(&app(frame)),
            &app_levels(),
            &["stop".to_string()],
            &[],
        )?;
        assert!(given.total_bytes < shallow.total_bytes);
        assert!(!given.vector_table && given.method.contains("No vector table"));
        Ok(())
    }

    #[test]
    fn the_once_function_is_counted_once_under_a_panic_or_a_fault() -> Result<(), WcetError> {
        // Without `stop` counted once, it would be in the thread's chain and in
        // HardFault's: 48 B twice.
        let p = parse_objdump(&app(16));
        let every = stack_bound_vectors(&p, &app_levels(), &[], &[], &app_vectors())?;
        let once = app_bound(16, &app_vectors())?;
        assert_eq!(every.total_bytes, once.total_bytes + 48);
        Ok(())
    }

    #[test]
    fn a_vector_entry_that_starts_no_function_is_named_and_unsound() -> Result<(), WcetError> {
        let mut vectors = app_vectors();
        // Inside USART1's body, no function's start.
        vectors.push(VectorEntry {
            exception: 21,
            address: 0x0800_0032,
        });
        let r = app_bound(16, &vectors)?;
        assert!(!r.sound);
        assert_eq!(r.unplaced_handlers.len(), 1, "{:?}", r.unplaced_handlers);
        let line = &r.unplaced_handlers[0];
        assert!(
            line.contains("IRQ 5") && line.contains("0x08000032"),
            "{line}"
        );
        // The entries that could be placed still are.
        assert_eq!(r.total_bytes, app_bound(16, &app_vectors())?.total_bytes);
        Ok(())
    }

    #[test]
    fn the_default_handler_is_found_and_named_by_its_alias() -> Result<(), WcetError> {
        // llvm-objdump prints one symbol per address, here an interrupt's name.
        let mut p = parse_objdump(&app(16).replace("DefaultHandler", "WWDG"));
        assert!(p.add_alias(DEFAULT_HANDLER, 0x0800_0050));
        let r = stack_bound_vectors(&p, &app_levels(), &[], &[], &app_vectors())?;
        let named: Vec<(&str, &str)> = r
            .levels
            .iter()
            .filter(|l| l.counted != Counted::PriorityLevel)
            .map(|l| (l.roots[0].root.as_str(), l.roots[0].function.as_str()))
            .collect();
        assert_eq!(
            named,
            [
                ("DefaultHandler", "DefaultHandler"),
                ("PendSV", "PendSV"),
                ("HardFault", "HardFault"),
                ("NMI", "DefaultHandler"),
            ]
        );
        assert_eq!(
            r.levels[2].roots[0].worst_path[0].function,
            "DefaultHandler"
        );
        Ok(())
    }

    #[test]
    fn without_a_default_handler_symbol_each_handler_is_on_top() -> Result<(), WcetError> {
        let p = parse_objdump(&app(16).replace("DefaultHandler", "Loop"));
        let r = stack_bound_vectors(&p, &app_levels(), &[], &[], &app_vectors())?;
        // IRQ 1–3 and PendSV: four levels of their own.
        let on_top = r.levels.iter().filter(|l| l.counted == Counted::OnTop);
        assert_eq!(on_top.count(), 4);
        Ok(())
    }

    #[test]
    fn aliases_and_unknown_roots() {
        let mut p = program();
        assert!(p.add_alias("USART1", 0x0800_0401));
        assert_eq!(p.get("USART1").map(|f| f.name.as_str()), Some("handler"));
        assert!(!p.add_alias("nowhere", 0x0900_0000));
        let err = stack_bound(&p, &levels(&["missing"]));
        assert!(matches!(err, Err(WcetError::UnknownRoot(_))));
    }
}
