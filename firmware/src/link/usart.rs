//! The flashed build's transport (`cargo ecu`): the frames over USART1 at a
//! fixed line rate, one interrupt entry per received byte. The ECU's interrupt
//! handler (`bin/support/usart_link.rs`) and the timing analysis
//! (`host-sim wcet`, the link interrupt's interference in the response-time
//! analysis) read the same constants.

use core::sync::atomic::{AtomicU16, Ordering};

use super::{
    MAX_ACTUATION_FRAME_BYTES, MAX_DOWN_FRAME_BYTES, MAX_DRIVING_DOWN_FRAME_BYTES,
    MAX_UP_FRAME_BYTES,
};

/// Baud rate of the link, bits/s.
pub const BAUD: u32 = 921_600;

/// Time of one byte on the line (a start bit, 8 data bits, a stop bit), ns: the
/// receive interrupt's minimum inter-arrival.
pub const BYTE_TIME_NS: u32 = (10 * 1_000_000_000_u64 / BAUD as u64) as u32;

/// Bytes received per control period at most, from the budget the control task
/// renews at its release: a sensor frame (68 bytes, 0.7 ms at [`BAUD`]).
pub const SENSOR_RX_BUDGET_BYTES: u16 = MAX_DRIVING_DOWN_FRAME_BYTES as u16;

/// Bytes received per plan period at most besides [`SENSOR_RX_BUDGET_BYTES`],
/// from the budget the plan task renews at its release: a route frame (281
/// bytes, 3 ms at [`BAUD`]; the host sends at most one per plan period). The
/// interrupt spends the sensor budget first, then this one, whatever the bytes
/// are (it does not sort them); past both it stops reading until a task renews
/// one.
pub const ROUTE_RX_BUDGET_BYTES: u16 = MAX_DOWN_FRAME_BYTES as u16;

/// Bytes received between two releases of the control task at most when the
/// host sends as it should (a sensor frame a control period, a route frame a
/// plan period): both budgets (68 + 281 = 349 bytes, 3.8 ms at [`BAUD`]).
pub const RX_BUDGET_BYTES: u16 = SENSOR_RX_BUDGET_BYTES + ROUTE_RX_BUDGET_BYTES;
// The budgets' bytes take less than a control period on the line.
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
/// tasks, below the link (a byte's time is the link's deadline; SysTick's
/// handler, the release clock, can wait).
pub const SYSTICK_PRIORITY: u8 = 3;

/// Entries of the USART1 interrupt per control period's budget at most, the
/// bound the response-time analysis charges per control period: each entry
/// that reads a byte spends one of the [`SENSOR_RX_BUDGET_BYTES`], one more may
/// find both budgets spent and mask the line (at most one per renewal); each
/// entry that sends sends at least one byte of an actuation frame (at most
/// [`MAX_ACTUATION_FRAME_BYTES`] without a plan event, one frame per control
/// activation), one more finds the transmit queue empty, and the control task's
/// write pends one that may find the transmitter busy.
pub const ENTRIES_PER_BUDGET: u64 =
    SENSOR_RX_BUDGET_BYTES as u64 + 1 + MAX_ACTUATION_FRAME_BYTES as u64 + 2;

/// Entries of the USART1 interrupt per plan period's budget at most, charged
/// besides [`ENTRIES_PER_BUDGET`]: the bytes of the [`ROUTE_RX_BUDGET_BYTES`]
/// and the mask entry of its renewal, and the bytes of one plan event in an
/// actuation frame ([`MAX_UP_FRAME_BYTES`] − [`MAX_ACTUATION_FRAME_BYTES`]: the
/// plan task leaves at most one event per activation for the control task's
/// next frame, a newer one replacing it, and its activations are released once
/// per plan period).
pub const ENTRIES_PER_PLAN_BUDGET: u64 =
    ROUTE_RX_BUDGET_BYTES as u64 + 1 + (MAX_UP_FRAME_BYTES - MAX_ACTUATION_FRAME_BYTES) as u64;

/// Entries of the USART1 interrupt on silicon are spaced by the line: one reads
/// a byte that took a byte's time to arrive, one sends into the data register
/// the previous byte has left for the shift register, so at most two a byte's
/// time, ns, besides [`ENTRIES_AT_ONCE`]. (QEMU's transmitter takes a byte at
/// once: there the handler's transmit entries follow each other; the timing
/// analysis models silicon.)
pub const ENTRY_SPACING_NS: u32 = BYTE_TIME_NS / 2;

/// Entries that the line does not space, at most, in a window shorter than two
/// control periods: the first entry of each kind (a byte already waiting, the
/// data and shift registers both empty), per control budget and frame sent (two
/// of each in such a window) the one that masks the line, the one that finds
/// the transmit queue empty and the write's pend, and per plan budget (two, the
/// plan task's releases coming closer by its jitter) the one that masks the
/// line: 2 + 2 × 3 + 2 = 10, and one for the rounding of two kinds into one
/// spacing.
pub const ENTRIES_AT_ONCE: u64 = 11;

/// Budgets a window of any length can draw on besides one per period it spans,
/// for either budget: the one in force at its start, and one more because a
/// budget is renewed when its task runs, which can be up to its response time
/// after its release (two renewals less than a period apart). For the plan
/// events, likewise: the one waiting at the window's start, and one more
/// because a plan activation finishes up to its response time after its release.
/// A window of the renewing task's own response draws on one less: its next
/// renewal (and, for the plan task, its next event) comes after it completes.
pub const EXTRA_BUDGETS_PER_WINDOW: u64 = 2;

/// The receive budgets the USART1 interrupt spends a byte at a time: the
/// control period's ([`SENSOR_RX_BUDGET_BYTES`], renewed by the control task at
/// its release) first, then the plan period's ([`ROUTE_RX_BUDGET_BYTES`],
/// renewed by the plan task at its release). Over any run the bytes it admits
/// are at most the budgets it started with plus one budget per renewal, which
/// is what the response-time analysis charges ([`ENTRIES_PER_BUDGET`],
/// [`ENTRIES_PER_PLAN_BUDGET`]). A renewal stores, never adds: a task that
/// renews twice before the bytes come gives one budget.
///
/// Loads and stores, no read-modify-write (Cortex-M4 has them, but the
/// interrupt is the only one that decrements, and it runs above the tasks that
/// renew, so neither can interrupt the other's update of one counter).
#[derive(Debug)]
pub struct RxBudgets {
    sensor: AtomicU16,
    route: AtomicU16,
}

impl RxBudgets {
    /// Both budgets spent (the line stays masked until a renewal); a valid
    /// `const` initialiser for a static.
    pub const fn new() -> Self {
        Self {
            sensor: AtomicU16::new(0),
            route: AtomicU16::new(0),
        }
    }

    /// Spends one byte: from the control period's budget, else the plan
    /// period's. False, nothing spent, when both are spent (the caller stops
    /// reading).
    pub fn spend(&self) -> bool {
        let sensor = self.sensor.load(Ordering::Relaxed);
        if sensor > 0 {
            self.sensor.store(sensor - 1, Ordering::Relaxed);
            return true;
        }
        let route = self.route.load(Ordering::Relaxed);
        if route > 0 {
            self.route.store(route - 1, Ordering::Relaxed);
            return true;
        }
        false
    }

    /// The control task's release: its budget back to [`SENSOR_RX_BUDGET_BYTES`].
    pub fn renew_control(&self) {
        self.sensor.store(SENSOR_RX_BUDGET_BYTES, Ordering::Relaxed);
    }

    /// The plan task's release: its budget back to [`ROUTE_RX_BUDGET_BYTES`].
    pub fn renew_plan(&self) {
        self.route.store(ROUTE_RX_BUDGET_BYTES, Ordering::Relaxed);
    }

    /// Bytes left in both budgets.
    pub fn left(&self) -> u32 {
        u32::from(self.sensor.load(Ordering::Relaxed))
            + u32::from(self.route.load(Ordering::Relaxed))
    }
}

impl Default for RxBudgets {
    fn default() -> Self {
        Self::new()
    }
}
