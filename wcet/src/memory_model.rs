//! The processor and memory model of the cycle bounds: per-instruction worst
//! cases of the Cortex-M4 (TRM), the target's flash (wait states, 128-bit lines,
//! the ART accelerator as the ECU sets it up) and which loads may read flash. Its
//! assumptions are stated in the report ([`MemoryModel::assumptions`]).

use super::cpi::Class;
use super::disassembly::{strip_condition, Instruction};
use super::flash_data::FlashData;

/// The memory model under which the block cycles are worst cases: fetch never
/// overlaps execution, and the ART accelerator's caches are counted on only where
/// they provably hold a line: the instruction cache the line just read and a
/// persistent loop's lines ([`super::cache`]), the data cache a literal-pool line
/// every path to the load has read ([`super::data_cache`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MemoryModel {
    /// Flash wait states (5 at 168 MHz and 3.3 V, RM0090 table 10).
    pub flash_wait_states: u32,
    /// Bytes delivered by one flash access (128-bit lines).
    pub flash_line_bytes: u32,
    /// `[flash_start, flash_end)`: code there is fetched through the flash.
    pub flash: (u32, u32),
    /// Which data loads may read flash ([`FlashData::classify`] decides it for a
    /// binary; [`FlashData::Anywhere`] assumes nothing).
    pub flash_data: FlashData,
    /// What sets the flash accelerator up so (prefetch off, instruction cache
    /// on), for the report: e.g. `the ECU's clock set-up, firmware::clock_tree::configure,`.
    #[serde(skip)]
    pub accelerator_setup: &'static str,
}

impl MemoryModel {
    /// A hand-made model for the crate's tests: 5 wait states, 16-byte lines,
    /// flash at 0x0800_0000 (the figures the hand-counted cycles assume).
    #[cfg(test)]
    pub(crate) const TEST: MemoryModel = MemoryModel {
        flash_wait_states: 5,
        flash_line_bytes: 16,
        flash: (0x0800_0000, 0x0810_0000),
        flash_data: FlashData::Anywhere(Vec::new()),
        accelerator_setup: "the test's",
    };

    /// The assumptions, for the report.
    pub fn assumptions(&self) -> Vec<String> {
        vec![
            format!(
                "Core: Cortex-M4F; per-instruction worst cases from the Cortex-M4 TRM (r0p1, \
                 chapter 3): every branch taken with a 3-cycle pipeline refill (instructions \
                 skipped by IT included), except a conditional branch or return on the edge \
                 where it falls through (1 cycle, not taken), loads/stores 2 (LDRD/STRD 3), \
                 LDM/STM/PUSH/POP 1+N (+3 loading pc), SDIV/UDIV 12, VDIV/VSQRT 14, \
                 VMLA/VFMA family 3, VMOV core<->FPU 2, VLDM/VSTM 1+N; unknown instructions 4."
            ),
            format!(
                "Instruction fetch: from flash with {} wait states, {}-byte lines, the ART \
                 accelerator's prefetch off and its instruction cache on ({} \
                 sets FLASH_ACR so). Each line a block touches costs {} cycles, added to (not \
                 overlapped with) the block's execution, and once more after each call (the \
                 return address's line); a fall-through into the line the previous block \
                 ended in is not charged again (the flash interface's 128-bit line buffer, \
                 RM0090 3.5.2), nor is a taken branch's target in the branch's own line \
                 (the cache holds the line just read). The cache is counted on only in loops that call nothing and \
                 touch at most 64 lines: its 64 lines are replaced least recently used \
                 (RM0090 3.5.2), so such a loop fetches each line once per entry; a \
                 preemption is charged a refill of the whole cache.",
                self.flash_wait_states,
                self.flash_line_bytes,
                self.accelerator_setup,
                self.flash_wait_states + 1
            ),
            self.flash_data.describe(self.flash_wait_states),
            format!(
                "Bus: no DMA, no other master; the core is the only user of the flash and SRAM \
                 buses. Interrupt entry: 12 cycles (TRM, with FPU lazy stacking reserving the \
                 frame) and {} more for the vector read from flash; exit: 12 cycles and the \
                 preempted code's line fetched again ({}). Charged per preemption in the \
                 response-time analysis.",
                self.flash_wait_states,
                self.line_fetch_cycles()
            ),
        ]
    }

    /// Worst-case cycles of a block's instructions, in the function that starts at
    /// `function`.
    pub fn block_cycles(&self, function: u32, insns: &[Instruction]) -> u64 {
        let through_registers = self.flash_data.may_read_flash(function);
        let mut cycles: u64 = 0;
        for i in insns {
            let (class, c) = i.timing();
            cycles += u64::from(c);
            if classify_flash_read(i, class, through_registers) != FlashRead::No {
                cycles += u64::from(self.flash_wait_states);
            }
        }
        // Fetch: every flash line the block's bytes touch, and after every call
        // the line of its return address once more (the callee's fetches went
        // elsewhere).
        if let Some((lo, hi)) = self.block_lines(insns) {
            {
                let calls = insns
                    .iter()
                    .filter(|i| matches!(strip_condition(i.base()), "bl" | "blx"))
                    .count() as u64;
                cycles += (hi - lo + 1 + calls) * self.line_fetch_cycles();
            }
        }
        cycles
    }

    /// Cycles one flash line fetch costs: the wait states and the access.
    pub fn line_fetch_cycles(&self) -> u64 {
        u64::from(self.flash_wait_states + 1)
    }

    fn in_flash(&self, address: u32) -> bool {
        (self.flash.0..self.flash.1).contains(&address)
    }

    fn line_of(&self, address: u32) -> u64 {
        u64::from(address) / u64::from(self.flash_line_bytes.max(1))
    }

    /// Cycles that [`Self::block_cycles`] charges a block ending in `last` and its
    /// fall-through successor starting with `next`, which falling through does not
    /// spend:
    ///
    /// * the pipeline refill of a conditional branch or return that is not taken
    ///   (`transfer`: the block ends in one): the TRM gives 1 cycle not taken, the
    ///   block charged 1 + 3;
    /// * the successor's first flash line when the block's last byte is in it: a
    ///   sequential fetch in the line just read is served by the flash interface's
    ///   128-bit line buffer (RM0090 §3.5.2), without a flash access. A block that
    ///   calls pays its return line in [`Self::block_cycles`].
    pub fn fall_through_saving(
        &self,
        last: Option<&Instruction>,
        next: Option<&Instruction>,
        transfer: bool,
    ) -> (u64, u64) {
        let (Some(last), Some(next)) = (last, next) else {
            return (0, 0);
        };
        let refill = match last.timing().0 {
            Class::Branch => true,
            Class::LoadMultiple => last.pops_pc(),
            _ => false,
        };
        let end = last.address + last.bytes - 1;
        let same_line = self.in_flash(end)
            && self.in_flash(next.address)
            && self.line_of(end) == self.line_of(next.address);
        (
            if transfer && refill { 3 } else { 0 },
            if same_line {
                self.line_fetch_cycles()
            } else {
                0
            },
        )
    }

    /// The first and last flash line a block's instructions touch; `None` outside
    /// flash.
    pub fn block_lines(&self, insns: &[Instruction]) -> Option<(u64, u64)> {
        let (first, last) = (insns.first()?, insns.last()?);
        self.in_flash(first.address).then(|| {
            (
                self.line_of(first.address),
                self.line_of(last.address + last.bytes - 1),
            )
        })
    }
}

/// How an instruction may read flash as data, each read paying the wait states
/// ([`MemoryModel::block_cycles`]) unless the ART's data cache holds its line
/// ([`super::data_cache`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlashRead {
    /// It reads no flash.
    No,
    /// A pc-relative load: a literal pool in the code's own lines.
    LiteralPool,
    /// A table branch (`tbb`, `tbh`): its table after the instruction.
    Table,
    /// A load through a register in a function that may read flash
    /// ([`FlashData::may_read_flash`]).
    ThroughRegister,
}

/// How `i` may read flash as data; `through_registers`: its function's loads
/// not relative to sp or pc may read flash.
pub fn flash_read(i: &Instruction, through_registers: bool) -> FlashRead {
    classify_flash_read(i, i.timing().0, through_registers)
}

fn classify_flash_read(i: &Instruction, class: Class, through_registers: bool) -> FlashRead {
    if class == Class::TableBranch {
        return FlashRead::Table;
    }
    let loads = matches!(class, Class::Load | Class::LoadMultiple)
        || (class == Class::FpuLoadStore
            && (i.base().starts_with("vldr") || i.base().starts_with("vldm")));
    if !loads {
        return FlashRead::No;
    }
    if i.operands.contains("[pc") {
        return FlashRead::LiteralPool;
    }
    // `pop`, `vpop` and `ldm sp!` read the stack too.
    let from_sp = i.operands.contains("[sp")
        || i.operands.starts_with("sp")
        || matches!(strip_condition(i.base()), "pop" | "vpop");
    if through_registers && !from_sp {
        FlashRead::ThroughRegister
    } else {
        FlashRead::No
    }
}
