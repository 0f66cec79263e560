//! The ECU's release clock: SysTick counting monotonic ticks (one per
//! `firmware::timing::MONO_TICK_US`), and the future each periodic task awaits
//! its next release on.
//!
//! A timer queue made for the two tasks the ECU has, so that the timing
//! analysis bounds it exactly:
//!
//! - **A slot per task**, not a timer list: waiting and waking touch one slot, and
//!   the SysTick handler looks at both slots, with no list to walk (rtic-time's
//!   queue walks its list on insertion and deletion, paths the ECU's two tasks
//!   never take, which no trace can cover).
//! - **A tick count only SysTick writes**: a load and a store per tick, no
//!   load/store-exclusive retry loop. A task that reads the clock while SysTick is
//!   pending (interrupts disabled, or the tick just came) adds the pending tick
//!   from the SysTick's pending bit, which a read does not clear (the SysTick
//!   counter's `COUNTFLAG`, which rtic-monotonics reads, is cleared by its read, so
//!   each reader must then count the tick itself, by a retry loop).
//! - **SysTick enters once per tick**, as the response-time analysis counts it: a
//!   task that starts waiting never pends it (rtic-time pends SysTick whenever a
//!   new delay becomes its queue's head, an entry per job the schedule does not
//!   model).

use core::cell::Cell;
use core::future::Future;
use core::pin::Pin;
use core::sync::atomic::{AtomicU32, Ordering};
use core::task::{Context, Poll, Waker};

use cortex_m::interrupt::{self, Mutex};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};

/// The task a slot belongs to: each periodic task waits on its own slot, one
/// release at a time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// The 100 Hz control task.
    Control = 0,
    /// The 10 Hz plan task.
    Plan = 1,
}

/// Slots, one per [`Slot`].
const SLOTS: usize = 2;

/// A task waiting for a release: the tick it waits for and its waker.
struct Waiting {
    /// Monotonic tick of the release, ticks.
    tick: u32,
    /// The task's waker (RTIC's executor: pends the task's dispatcher).
    waker: Waker,
}

/// Monotonic ticks SysTick counted since [`start`], ticks (SysTick alone writes it).
static TICKS: AtomicU32 = AtomicU32::new(0);

/// The waiting tasks, by slot; touched only with interrupts disabled.
static WAITING: [Mutex<Cell<Option<Waiting>>>; SLOTS] =
    [Mutex::new(Cell::new(None)), Mutex::new(Cell::new(None))];

/// Starts SysTick on the core clock with `reload + 1` core clock ticks per
/// monotonic tick, and its interrupt. `reload` is 1 to `0x00FF_FFFF` (SysTick's
/// 24-bit reload register); the caller's constant is checked at compile time
/// (see `TICKS_PER_MONO` in the ECU binary).
pub fn start(mut syst: SYST, reload: u32) {
    syst.disable_counter();
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(reload);
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Monotonic ticks since [`start`], ticks: the count SysTick's handler keeps, plus
/// the tick whose interrupt is pending. The count is read on both sides of the
/// pending bit: equal, the bit belongs to that count; different, SysTick's
/// handler ran between the reads and took its tick, and the second count is the
/// time (another tick needs a whole tick period of preemption within the next
/// instructions, which the response-time analysis excludes). No retry loop.
pub fn now_ticks() -> u32 {
    let a = TICKS.load(Ordering::Acquire);
    let pending = SCB::is_pendst_pending();
    let b = TICKS.load(Ordering::Acquire);
    if a == b {
        a.wrapping_add(u32::from(pending))
    } else {
        b
    }
}

/// True when the tick count `now` has reached `tick` (both wrapping, ticks;
/// within half the counter's range of each other).
fn reached(now: u32, tick: u32) -> bool {
    (now.wrapping_sub(tick) as i32) >= 0
}

/// A future that completes once the monotonic tick count reaches `tick`
/// (ticks), for the task of `slot`: the task's next release.
pub fn wait_until(slot: Slot, tick: u32) -> WaitUntil {
    WaitUntil { slot, tick }
}

/// The future of [`wait_until`].
#[must_use = "a release is waited for only when awaited"]
pub struct WaitUntil {
    /// The waiting task's slot.
    slot: Slot,
    /// Monotonic tick of the release, ticks.
    tick: u32,
}

impl WaitUntil {
    /// The slot's cell, with interrupts disabled.
    fn with_slot<R>(&self, f: impl FnOnce(&Cell<Option<Waiting>>) -> R) -> R {
        interrupt::free(|cs| f(WAITING[self.slot as usize].borrow(cs)))
    }
}

impl Future for WaitUntil {
    type Output = ();

    // A wait that completes leaves its slot to `Drop`, which runs as the
    // `.await` completes.
    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        if reached(now_ticks(), self.tick) {
            return Poll::Ready(());
        }
        let waiting = Waiting {
            tick: self.tick,
            waker: cx.waker().clone(),
        };
        self.with_slot(|c| c.set(Some(waiting)));
        // A tick between the first look and the slot's write found the slot
        // empty: look again now the slot holds the waker.
        if reached(now_ticks(), self.tick) {
            return Poll::Ready(());
        }
        Poll::Pending
    }
}

impl Drop for WaitUntil {
    fn drop(&mut self) {
        // No waker of a wait that ended stays behind to wake the task later.
        self.with_slot(|c| c.set(None));
    }
}

/// SysTick's handler: counts the tick and wakes each task whose release it
/// reached (two slots, no list).
#[no_mangle]
#[allow(non_snake_case)]
extern "C" fn SysTick() {
    // SysTick alone writes the count: a load and a store.
    let now = TICKS.load(Ordering::Relaxed).wrapping_add(1);
    TICKS.store(now, Ordering::Release);
    for slot in &WAITING {
        let due = interrupt::free(|cs| {
            let cell = slot.borrow(cs);
            match cell.take() {
                Some(w) if reached(now, w.tick) => Some(w.waker),
                other => {
                    cell.set(other);
                    None
                }
            }
        });
        if let Some(waker) = due {
            waker.wake();
        }
    }
}
