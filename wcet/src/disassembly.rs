//! The Thumb-2 disassembly as `llvm-objdump -d` prints it (with raw bytes): its
//! functions, their instructions and the data between them (literal pools,
//! jump tables), and the operand and mnemonic helpers the analyses share.

use super::cpi::{instruction_timing, Class};

/// One instruction of the disassembly.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Instruction {
    /// Address (Thumb bit clear).
    pub address: u32,
    /// Encoding size, bytes (2 or 4).
    pub bytes: u32,
    /// Mnemonic as printed (`ldr.w`, `bne`, `vmla.f32`, `itte`).
    pub mnemonic: String,
    /// Operands, without the trailing `@ comment`.
    pub operands: String,
    /// Target address of a direct branch or call (`b`, `bl`, `cbz`, ...).
    pub target: Option<u32>,
}

impl Instruction {
    /// The mnemonic without width qualifier (`.w`, `.n`) or data type (`.f32`).
    pub fn base(&self) -> &str {
        self.mnemonic.split('.').next().unwrap_or(&self.mnemonic)
    }

    /// The first operand (`pc` in `pop {r4, pc}` is not it: see [`Self::pops_pc`]).
    pub fn first_operand(&self) -> &str {
        self.operands.split(',').next().unwrap_or("").trim()
    }

    /// Loads the program counter from the stack (`pop {.., pc}`, `ldm sp!, {.., pc}`,
    /// `ldr pc, [sp], #4`): a return.
    pub fn pops_pc(&self) -> bool {
        let b = strip_condition(self.base());
        let list_has_pc = || {
            self.operands
                .split(['{', '}', ','])
                .any(|r| r.trim() == "pc" || r.trim().ends_with("-pc"))
        };
        match b {
            "pop" => list_has_pc(),
            "ldm" | "ldmia" | "ldmfd" => self.operands.starts_with("sp!") && list_has_pc(),
            "ldr" => self.first_operand() == "pc" && self.operands.contains("[sp]"),
            _ => false,
        }
    }

    /// Worst-case cycles of the instruction alone (Cortex-M4 TRM table of
    /// [`super::cpi`]) and its class.
    pub fn timing(&self) -> (Class, u32) {
        instruction_timing(&self.mnemonic, &self.operands)
    }
}

/// Condition codes of the Thumb-2 instruction set.
const CONDITIONS: [&str; 16] = [
    "eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le",
];

/// `bne` → `b`, `popeq` → `pop`, `bx` unchanged (only a two-letter condition suffix
/// that leaves a known base is stripped).
pub fn strip_condition(base: &str) -> &str {
    if base.len() > 2 {
        let (head, tail) = base.split_at(base.len() - 2);
        if CONDITIONS.contains(&tail)
            && matches!(
                head,
                "b" | "bx" | "pop" | "ldm" | "ldmia" | "ldr" | "bl" | "blx" | "mov" | "tbb"
            )
        {
            return head;
        }
    }
    base
}

/// Whether the (width-stripped) mnemonic carries a condition suffix of its own
/// (`bne`, `popeq`).
pub(crate) fn has_condition(base: &str) -> bool {
    strip_condition(base) != base
}

/// Number of instructions an `IT` instruction makes conditional (1–4), if `base`
/// is one (`it`, `ite`, `ittt`, `itete`).
pub(crate) fn it_length(base: &str) -> Option<usize> {
    let rest = base.strip_prefix("it")?;
    (rest.len() <= 3 && rest.chars().all(|c| c == 't' || c == 'e')).then_some(rest.len() + 1)
}

/// Bytes of data inside `.text` (a literal pool or a jump table).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DataRun {
    /// Address of the first byte.
    pub address: u32,
    /// The bytes, in memory order.
    pub bytes: Vec<u8>,
}

/// A function of the disassembly: its instructions and the data between them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawFunction {
    /// Symbol (mangled).
    pub name: String,
    /// Other symbols at the same address.
    pub aliases: Vec<String>,
    /// Start address.
    pub address: u32,
    /// Instructions, in address order.
    pub instructions: Vec<Instruction>,
    /// Data inside the function (literal pools, jump tables), in address order.
    pub data: Vec<DataRun>,
}

fn hex(s: &str) -> Option<u32> {
    u32::from_str_radix(s.trim().trim_start_matches("0x"), 16).ok()
}

/// Parses `llvm-objdump -d` output (with raw bytes) into functions.
pub fn parse_disassembly(text: &str) -> Vec<RawFunction> {
    let mut functions: Vec<RawFunction> = Vec::new();
    for line in text.lines() {
        if let Some(rest) = line.strip_suffix(">:") {
            if let Some((addr, name)) = rest.split_once(" <") {
                if let Some(address) = hex(addr) {
                    // Several symbols at one address are printed one after the other,
                    // the body under the last.
                    if let Some(f) = functions
                        .last_mut()
                        .filter(|f| f.address == address && f.instructions.is_empty())
                    {
                        let old = std::mem::replace(&mut f.name, name.to_string());
                        f.aliases.push(old);
                    } else {
                        functions.push(RawFunction {
                            name: name.to_string(),
                            aliases: Vec::new(),
                            address,
                            instructions: Vec::new(),
                            data: Vec::new(),
                        });
                    }
                }
            }
            continue;
        }
        let Some(f) = functions.last_mut() else {
            continue;
        };
        if !line.starts_with(' ') {
            continue;
        }
        let mut fields = line.splitn(3, '\t');
        let head = fields.next().unwrap_or("");
        let Some((addr, raw)) = head.trim_start().split_once(':') else {
            continue;
        };
        let Some(address) = hex(addr) else {
            continue;
        };
        let raw_tokens: Vec<&str> = raw.split_whitespace().collect();
        let mnemonic = fields.next().unwrap_or("").trim();
        let rest = fields.next().unwrap_or("");
        if mnemonic.is_empty() {
            continue;
        }
        if mnemonic.starts_with('.') {
            // Data: raw bytes printed in memory order, two hex digits each.
            let bytes: Vec<u8> = raw_tokens
                .iter()
                .filter(|t| t.len() == 2)
                .filter_map(|t| u8::from_str_radix(t, 16).ok())
                .collect();
            match f.data.last_mut() {
                Some(d) if d.address + d.bytes.len() as u32 == address => d.bytes.extend(bytes),
                _ => f.data.push(DataRun { address, bytes }),
            }
            continue;
        }
        // Instruction: one or two 16-bit halfwords.
        let bytes = raw_tokens
            .iter()
            .filter(|t| t.len() == 4 && t.chars().all(|c| c.is_ascii_hexdigit()))
            .count() as u32
            * 2;
        let operands = rest.split('@').next().unwrap_or("").trim().to_string();
        // `b 0x80010fe <f+0x12>`, `cbz r0, 0x800033c <f+0x58>`.
        let target = operands
            .split_whitespace()
            .find(|t| t.starts_with("0x"))
            .and_then(hex);
        f.instructions.push(Instruction {
            address,
            bytes: bytes.max(2),
            mnemonic: mnemonic.to_string(),
            operands,
            target,
        });
    }
    functions.retain(|f| !f.instructions.is_empty());
    functions
}

/// An immediate operand (`#0x10`, `#16`, `16`), unsigned.
pub fn parse_imm(s: &str) -> Option<u32> {
    let s = s.trim().trim_start_matches('#');
    match s.strip_prefix("0x") {
        Some(hex) => u32::from_str_radix(hex, 16).ok(),
        None => s.parse().ok(),
    }
}
