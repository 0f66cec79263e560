//! The flashed build's transport (`cargo ecu`): the frames over USART1 at a
//! fixed line rate, one interrupt entry per received byte. The ECU's interrupt
//! handler (`bin/support/usart_link.rs`) and the timing analysis
//! (`host-sim wcet`, the link interrupt's interference in the response-time
//! analysis) read the same constants.

use super::{MAX_DOWN_FRAME_BYTES, MAX_DRIVING_DOWN_FRAME_BYTES, MAX_UP_FRAME_BYTES};

/// Baud rate of the link, bits/s.
pub const BAUD: u32 = 921_600;

/// Time of one byte on the line (a start bit, 8 data bits, a stop bit), ns: the
/// receive interrupt's minimum inter-arrival.
pub const BYTE_TIME_NS: u32 = (10 * 1_000_000_000_u64 / BAUD as u64) as u32;

/// Bytes received per control period at most: a sensor frame and a route frame
/// (68 + 281 = 349 bytes, 3.8 ms at [`BAUD`]). Past them the handler stops
/// reading until the control task's next release renews the budget.
pub const RX_BUDGET_BYTES: u16 = (MAX_DRIVING_DOWN_FRAME_BYTES + MAX_DOWN_FRAME_BYTES) as u16;
// The budget's bytes take less than a control period on the line.
const _: () = assert!(
    (RX_BUDGET_BYTES as u64) * (BYTE_TIME_NS as u64) < crate::timing::CONTROL_PERIOD_US * 1_000
);

/// The USART1 interrupt's priority in RTIC's logical numbering (higher preempts):
/// above the control task (2), the plan task (1), every lock's ceiling (2) and
/// SysTick ([`SYSTICK_PRIORITY`]), so that nothing but an interrupts-disabled
/// section delays a received byte: a byte not read within a byte's time is
/// overrun by the next.
pub const LINK_INTERRUPT_PRIORITY: u8 = 4;

/// SysTick's priority in the flashed build, RTIC's logical numbering: above both
/// tasks, below the link (its handler, the monotonic's timer queue, runs for
/// longer than a byte's time).
pub const SYSTICK_PRIORITY: u8 = 3;

/// Bytes the interrupt handler sends per entry at most: the data register and
/// the shift register, all silicon can take at once.
pub const TX_BYTES_PER_ENTRY: usize = 2;

/// Entries of the USART1 interrupt per receive budget at most, the bound the
/// response-time analysis charges: each entry that reads a byte spends one of the
/// [`RX_BUDGET_BYTES`], one more finds the budget spent and masks the line; each
/// entry that sends sends at least one byte of an actuation frame (at most
/// [`MAX_UP_FRAME_BYTES`], one frame per control activation), one more finds the
/// transmit queue empty, and the control task's write pends one that may find the
/// transmitter busy.
pub const ENTRIES_PER_BUDGET: u64 = RX_BUDGET_BYTES as u64 + 1 + MAX_UP_FRAME_BYTES as u64 + 2;

/// Entries of the USART1 interrupt on silicon are spaced by the line: one reads
/// a byte that took a byte's time to arrive, one sends into the data register
/// the previous byte has left for the shift register, so at most two a byte's
/// time, ns, besides [`ENTRIES_AT_ONCE`]. (QEMU's transmitter takes a byte at
/// once: there the handler's transmit entries follow each other; the timing
/// analysis models silicon.)
pub const ENTRY_SPACING_NS: u32 = BYTE_TIME_NS / 2;

/// Entries that the line does not space, at most, in a window shorter than two
/// control periods: the first entry of each kind (a byte already waiting, the
/// data and shift registers both empty), and per receive budget and frame sent
/// (two of each in such a window) the one that masks the line, the one that
/// finds the transmit queue empty and the write's pend: 2 + 2 × 3 = 8, and one
/// for the rounding of two kinds into one spacing.
pub const ENTRIES_AT_ONCE: u64 = 9;

/// Budgets a window of any length can draw on besides one per control period it
/// spans: the one in force at its start, and one more because a budget is
/// renewed when the control task runs, which can be up to its response time after
/// its release (two renewals less than a period apart).
pub const EXTRA_BUDGETS_PER_WINDOW: u64 = 2;
