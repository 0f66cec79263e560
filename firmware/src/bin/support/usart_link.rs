//! The flashed ECU's link (feature `board-usart`): USART1 (PA9 TX, PA10 RX,
//! alternate function 7) at [`BAUD`], 8 data bits, no parity, one stop bit.
//!
//! * **Set-up** (in `init`, interrupts off): polled. Once the receiver is on, the
//!   ECU writes one `0x00` (an empty frame, which frame readers skip): the host
//!   sends its set-up after it. The set-up's frames are read byte by byte from the
//!   data register, and its answer is written by polling, each byte's wait
//!   bounded.
//! * **Driving**: interrupt-driven both ways into bounded `heapless` SPSC queues.
//!   The USART1 interrupt (NVIC priority above both tasks and SysTick,
//!   [`USART1_PRIORITY`]) queues one received byte or sends one byte per
//!   entry (QEMU 7.2's USART raises no transmit-empty
//!   interrupt, so the handler pends itself again while bytes wait and the
//!   transmitter takes them), and drains the transmit queue the control task
//!   fills. The control task sorts the received bytes at its release
//!   ([`Port::sort_and_rearm`], [`firmware::link::demux`]: sensor and stop frames for
//!   itself, the windows of the road into the plan task's queue), as the
//!   lock-step build's two host files do. The interrupt takes at most
//!   [`firmware::link::usart::SENSOR_RX_BUDGET_BYTES`] per control period and
//!   [`firmware::link::usart::ROUTE_RX_BUDGET_BYTES`] per plan period: past them it stops reading (on
//!   silicon the peripheral then drops bytes, with an overrun; QEMU holds them
//!   back), so its load is bounded whatever the other end sends; the control
//!   task renews its budget at each release, together with counting the bytes
//!   it will sort ([`Port::sort_and_rearm`]), the plan task its own
//!   ([`rearm_route_receive`]).
//! * **Faults and the end of a run** ([`Port::take_over`], [`exit`]): interrupts off,
//!   the bytes still queued sent by polling, then the caller's frame by polling,
//!   every wait bounded; no semihosting, nothing that can trap; then the core
//!   parks.
//!
//! On a car the same frames would go over CAN-FD (docs/board.md, "Over CAN-FD on
//! a car").

use core::sync::atomic::{AtomicPtr, Ordering};

use cortex_m::peripheral::NVIC;
use firmware::clock_tree;
use firmware::link::demux::{Channel, Sorter};
use firmware::link::usart::{RxBudgets, BAUD, LINK_INTERRUPT_PRIORITY, RX_BUDGET_BYTES};
use firmware::link::{MAX_DOWN_FRAME_BYTES, MAX_UP_FRAME_BYTES};
use heapless::spsc::{Consumer, Producer, Queue};
use stm32f4::stm32f405 as pac;
use stm32f4::stm32f405::interrupt;

/// USART1's kernel clock (APB2) after the clock tree's set-up, Hz: 84 MHz.
pub const APB2_HZ: u32 = clock_tree::SYSCLK_HZ / clock_tree::AHB_DIV / clock_tree::APB2_DIV;

/// The baud-rate register for [`BAUD`] at an APB2 clock of `apb2_hz` Hz with 16×
/// oversampling: `USARTDIV` in 1/16ths (mantissa in bits 15:4, fraction in bits
/// 3:0), rounded to the nearest.
pub const fn brr(apb2_hz: u32) -> u32 {
    (apb2_hz + BAUD / 2) / BAUD
}

/// [`brr`] at [`APB2_HZ`]: 91, `USARTDIV` 5 + 11/16, 923,077 baud (0.16 % fast).
pub const BRR: u32 = brr(APB2_HZ);
const _: () = assert!(BRR == 91);

/// The received bytes the interrupt queues for the control task to sort, bytes
/// (it holds one less): both receive budgets, what arrives between two of the
/// control task's releases from a host that sends as it should. The control
/// task sorts, at its release, the bytes it counted when it renewed its budget
/// ([`Port::sort_and_rearm`]); a byte that finds the queue full is dropped and
/// counted.
pub const RAW_RX_BYTES: usize = RX_BUDGET_BYTES as usize + 1;

/// The plan task's receive queue, bytes (it holds one less): one route frame (the
/// host sends at most one per plan period) and its delimiter.
pub const ROUTE_RX_BYTES: usize = MAX_DOWN_FRAME_BYTES + 2;

/// The transmit queue, bytes (it holds one less): one actuation frame.
pub const TX_BYTES: usize = MAX_UP_FRAME_BYTES + 1;

/// USART1's NVIC priority, the hardware's encoding (upper 4 bits, lower is
/// more urgent): RTIC's logical priority [`LINK_INTERRUPT_PRIORITY`] (4), above
/// SysTick ([`SYSTICK_PRIORITY`]), the control task (2), the plan task (1) and
/// every lock's ceiling (2), so neither a lock nor the monotonic's tick delays a
/// received byte. The handler shares no resource with the tasks but its
/// lock-free queues.
pub const USART1_PRIORITY: u8 = (16 - LINK_INTERRUPT_PRIORITY) << 4;

/// SysTick's priority, the hardware's encoding: RTIC's logical
/// [`firmware::link::usart::SYSTICK_PRIORITY`] (3), above both tasks, below the
/// link (the monotonic leaves it at the most urgent level, 0, where its 3.6 k
/// cycles would outlast a byte's time).
pub const SYSTICK_PRIORITY: u8 = (16 - firmware::link::usart::SYSTICK_PRIORITY) << 4;

/// Polls of a status flag per byte written by polling at most: a byte's time at
/// 168 MHz is about 1,820 cycles and a poll a few, so the wait is ample on
/// silicon; QEMU's transmitter is always ready.
const POLLS_PER_BYTE: u32 = 100_000;

/// The receive budgets left, bytes: the control period's, then the plan
/// period's.
static RX_BUDGETS: RxBudgets = RxBudgets::new();

/// The interrupt handler's state (null until [`open`] stored it).
static ISR: AtomicPtr<UsartIsr> = AtomicPtr::new(core::ptr::null_mut());

/// USART1's registers.
fn usart() -> &'static pac::usart1::RegisterBlock {
    // SAFETY: the peripheral's fixed address; its registers are read and written
    // with volatile accesses by the PAC.
    unsafe { &*pac::USART1::ptr() }
}

/// Control register 1's bits the tasks and the interrupt set apart: receive and
/// transmit-empty interrupt enables.
#[derive(Clone, Copy)]
enum Cr1Bit {
    RxneIe = 5,
    TxeIe = 7,
}

/// Sets or clears one bit of USART1's CR1 through the peripheral bit-band alias:
/// one store, no read-modify-write that the interrupt could undo between a
/// task's read and its write (checked to take in QEMU's `netduinoplus2` too).
fn cr1_bit(bit: Cr1Bit, on: bool) {
    const USART1_CR1: usize = 0x4001_100C;
    const PERIPH_BASE: usize = 0x4000_0000;
    const BITBAND_BASE: usize = 0x4200_0000;
    let alias = BITBAND_BASE + (USART1_CR1 - PERIPH_BASE) * 32 + bit as usize * 4;
    // SAFETY: the bit-band alias word of an existing register bit.
    unsafe { core::ptr::write_volatile(alias as *mut u32, u32::from(on)) };
}

/// The queues and the handler's state, in one static ([`open`]).
struct Storage {
    raw: Queue<u8, RAW_RX_BYTES>,
    route: Queue<u8, ROUTE_RX_BYTES>,
    tx: Queue<u8, TX_BYTES>,
    isr: Option<UsartIsr>,
}

/// The control task's end of the link: the received bytes, their sorter into
/// its own frames and the plan task's, and the transmit queue.
pub struct Port {
    raw: Consumer<'static, u8, RAW_RX_BYTES>,
    sorter: Sorter,
    route: Producer<'static, u8, ROUTE_RX_BYTES>,
    tx: Producer<'static, u8, TX_BYTES>,
    /// Bytes of the road dropped because the plan task's queue was full, bytes.
    pub dropped: u32,
}

/// The plan task's end of the link: its receive queue (the windows of the road).
pub struct RoutePort {
    rx: Consumer<'static, u8, ROUTE_RX_BYTES>,
}

/// Enables USART1 at [`BAUD`] on PA9/PA10 (clocks, pins, baud rate for the APB2
/// clock that `RCC_CFGR` says, receiver and transmitter), its interrupts off, and
/// sets up the queues and the handler's state; the two ends (the set-up polls,
/// [`Port::next_byte_polled`], [`Port::write_polled`], until [`Port::start`]).
/// `None` if called twice (the queues are taken once).
pub fn open(
    rcc: &pac::RCC,
    gpioa: &pac::GPIOA,
    usart1: &pac::USART1,
    clock_ok: bool,
) -> Option<(Port, RoutePort)> {
    let storage: &'static mut Storage = cortex_m::singleton!(: Storage = Storage {
        raw: Queue::new(),
        route: Queue::new(),
        tx: Queue::new(),
        isr: None,
    })?;
    let Storage {
        raw,
        route,
        tx,
        isr,
    } = storage;
    let (raw_in, raw_out) = raw.split();
    let (route_in, route_out) = route.split();
    let (tx_in, tx_out) = tx.split();
    let isr = isr.insert(UsartIsr {
        raw: raw_in,
        tx: tx_out,
        dropped: 0,
    });
    ISR.store(isr, Ordering::Relaxed);

    rcc.ahb1enr.modify(|_, w| w.gpioaen().enabled());
    rcc.apb2enr.modify(|_, w| w.usart1en().enabled());
    // PA9, PA10: alternate function 7 (USART1).
    gpioa
        .moder
        .modify(|_, w| w.moder9().alternate().moder10().alternate());
    gpioa.afrh.modify(|_, w| w.afrh9().af7().afrh10().af7());
    // The clock the core runs on: after a failed set-up (the HSI, whatever
    // prescalers the sequence had set) the ClockFailed answer still goes out at
    // BAUD. With no RCC (QEMU: reads 0, and the core at its fixed 168 MHz) the
    // tree's nominal APB2 clock.
    let apb2_hz = if clock_ok {
        APB2_HZ
    } else {
        clock_tree::apb2_hz(rcc.cfgr.read().bits())
    };
    // SAFETY: any value is a valid baud-rate divisor.
    usart1.brr.write(|w| unsafe { w.bits(brr(apb2_hz)) });
    usart1
        .cr1
        .write(|w| w.ue().enabled().te().enabled().re().enabled());
    // One delimiter, an empty frame that every frame reader skips: it tells the
    // other end that the receiver is on. A host that writes before it may lose
    // bytes (QEMU's USART drops what arrives while it is disabled; silicon too).
    write_polled(&[0]);
    Some((
        Port {
            raw: raw_out,
            sorter: Sorter::new(),
            route: route_in,
            tx: tx_in,
            dropped: 0,
        },
        RoutePort { rx: route_out },
    ))
}

/// The next received byte, polled: `None` when none arrived yet.
fn poll_byte() -> Option<u8> {
    let u = usart();
    let sr = u.sr.read();
    (sr.rxne().bit_is_set() || sr.ore().bit_is_set()).then(|| u.dr.read().bits() as u8)
}

/// Writes `bytes` by polling, each byte's wait bounded ([`POLLS_PER_BYTE`]):
/// nothing here can trap. False if the transmitter never became ready.
fn write_polled(bytes: &[u8]) -> bool {
    let u = usart();
    // wcet-bound: MAX_UP_FRAME_BYTES
    for &b in bytes {
        let mut ready = false;
        // wcet-bound: 100_000
        for _ in 0..POLLS_PER_BYTE {
            if u.sr.read().txe().bit_is_set() {
                ready = true;
                break;
            }
        }
        if !ready {
            return false;
        }
        // SAFETY: any byte is a valid data register value.
        u.dr.write(|w| unsafe { w.bits(u32::from(b)) });
    }
    true
}

impl Port {
    /// The start of a control period: the bytes the interrupt received since
    /// the last call are counted and the control task's receive budget renewed
    /// together, with interrupts off for those few instructions (no byte is
    /// received between the two), the line unmasked, and then exactly the
    /// counted bytes sorted ([`firmware::link::demux::Sorter`], a byte handed
    /// over per byte received, the head of a frame held over at most two
    /// bytes and handed over at the end): sensor, stop and set-up
    /// frames to `control` (the control task's frame reader), the windows
    /// of the road into the plan task's queue ([`RoutePort::next_byte`]). Bytes
    /// received while it sorts wait for the next period. So the bytes sorted at
    /// a release are those received between the last release's count and this
    /// one's: at most the sensor budget renewed with the last count (a renewal
    /// stores, never adds) and what the plan budget gave meanwhile, never more
    /// than the queue holds (`RAW_RX_BYTES` − 1 = `RX_BUDGET_BYTES`), whatever
    /// the host sends and whenever. The timing analysis charges the route bytes
    /// apart on that premise (`host-sim`'s `EcuBuild::light_activations`). Here
    /// rather than in the interrupt, so that an entry of the interrupt costs
    /// little and the sorting runs in a loop that stays in the cache.
    pub fn sort_and_rearm(&mut self, mut control: impl FnMut(u8)) {
        let count = cortex_m::interrupt::free(|_| {
            let count = self.raw.len();
            RX_BUDGETS.renew_control();
            count
        });
        receive_on();
        // At most what the queue holds.
        // wcet-bound: RX_BUDGET_BYTES
        for _ in 0..count.min(RAW_RX_BYTES - 1) {
            let Some(byte) = self.raw.dequeue() else {
                break;
            };
            if let Some((channel, b)) = self.sorter.push(byte) {
                self.hand_over(channel, b, &mut control);
            }
        }
        // The bytes told and still held (a frame's head handed over one per
        // byte): at most two.
        // wcet-bound: 2
        for _ in 0..Sorter::MAX_HELD_AFTER_PUSH {
            let Some((channel, b)) = self.sorter.take_held() else {
                break;
            };
            self.hand_over(channel, b, &mut control);
        }
    }

    /// One sorted byte to its channel: the control task's to `control` (its
    /// frame reader), the plan task's into its queue (a byte that finds it full
    /// is dropped and counted).
    #[inline(always)]
    fn hand_over(&mut self, channel: Channel, b: u8, control: &mut impl FnMut(u8)) {
        match channel {
            Channel::Control => control(b),
            Channel::Route => {
                let full = self.route.enqueue(b).is_err();
                self.dropped = self.dropped.wrapping_add(u32::from(full));
            }
        }
    }

    /// The next byte on the line, polled, waiting for the host as long as it
    /// takes (as the lock-step build's blocking read): the set-up's path, before
    /// the interrupt takes over ([`Port::start`]).
    pub fn next_byte_polled(&mut self) -> u8 {
        loop {
            if let Some(b) = poll_byte() {
                return b;
            }
        }
    }

    /// Queues a frame's `bytes` for the interrupt to send: the tasks' path, it
    /// never waits. False (nothing queued) when they do not all fit (the previous
    /// frame has not left yet).
    pub fn write(&mut self, bytes: &[u8]) -> bool {
        if self.tx.capacity() - self.tx.len() < bytes.len() {
            return false;
        }
        // wcet-bound: MAX_UP_FRAME_BYTES
        for &b in bytes {
            let _ = self.tx.enqueue(b);
        }
        cr1_bit(Cr1Bit::TxeIe, true);
        // The handler starts the transmission at once (QEMU 7.2 raises no
        // transmit-empty interrupt; on silicon TXEIE alone would).
        NVIC::pend(pac::Interrupt::USART1);
        true
    }

    /// Writes a frame's `bytes` by polling ([`write_polled`], each byte's wait
    /// bounded): the set-up's path and, after [`Port::take_over`], the end of
    /// the run's and the fault paths'. False if the transmitter never became
    /// ready.
    pub fn write_polled(&mut self, bytes: &[u8]) -> bool {
        write_polled(bytes)
    }

    /// The end of the set-up, interrupts still off (in `init`): the interrupt
    /// takes over, at [`USART1_PRIORITY`], with a first period's receive budget;
    /// SysTick below it, at [`SYSTICK_PRIORITY`].
    pub fn start(&mut self, nvic: &mut NVIC, scb: &mut cortex_m::peripheral::SCB) {
        // SAFETY: the priority is above every RTIC ceiling and the handler
        // touches no RTIC resource.
        unsafe { nvic.set_priority(pac::Interrupt::USART1, USART1_PRIORITY) };
        // SAFETY: SysTick's handler (the release clock) takes no RTIC
        // lock; it stays above both tasks.
        unsafe {
            scb.set_priority(
                cortex_m::peripheral::scb::SystemHandler::SysTick,
                SYSTICK_PRIORITY,
            );
        }
        // The line unmasked with the first periods' budgets.
        RX_BUDGETS.renew_plan();
        rearm_receive();
    }

    /// A fault, or the end of the run: interrupts off (the caller's, or this
    /// call's), the bytes still queued sent by polling ([`flush`]): the caller's
    /// next frame, written with [`Port::write_polled`], goes out after them,
    /// whole.
    pub fn take_over(&mut self) {
        flush();
    }
}

impl RoutePort {
    /// The next byte the interrupt queued for the plan task, `None` when none is.
    pub fn next_byte(&mut self) -> Option<u8> {
        self.rx.dequeue()
    }
}

/// What the interrupt handler owns: its ends of the queues.
pub struct UsartIsr {
    raw: Producer<'static, u8, RAW_RX_BYTES>,
    tx: Consumer<'static, u8, TX_BYTES>,
    /// Bytes dropped because the received bytes' queue was full, bytes.
    pub dropped: u32,
}

impl UsartIsr {
    /// One interrupt, one byte: a received byte (queued for the control task to
    /// sort, within the control period's budget, else the plan period's), or
    /// else one byte sent; the transmit interrupt off when the queue is empty,
    /// the receive one off (and the line masked until a task renews a budget)
    /// when both budgets are spent. A byte's work per entry keeps an entry's
    /// bound that of one byte's path, as the timing analysis counts an entry per
    /// byte received or sent: with both pending, the transmit-empty request is
    /// still raised on silicon and the handler runs again at once.
    fn on_interrupt(&mut self) {
        let u = usart();
        let sr = u.sr.read();
        if sr.rxne().bit_is_set() || sr.ore().bit_is_set() {
            // The control period's budget first, then the plan period's.
            if !RX_BUDGETS.spend() {
                // Spent: leave the byte (QEMU holds the rest back; silicon drops
                // what comes meanwhile) until the next release re-arms it. The
                // line is masked too: QEMU 7.2's USART lowers its request only
                // when the data register is read, so the handler would run
                // again and again. The transmission waits with it.
                cr1_bit(Cr1Bit::RxneIe, false);
                NVIC::mask(pac::Interrupt::USART1);
                return;
            }
            let byte = u.dr.read().bits() as u8;
            let full = self.raw.enqueue(byte).is_err();
            self.dropped = self.dropped.wrapping_add(u32::from(full));
        } else if sr.txe().bit_is_set() {
            match self.tx.dequeue() {
                // SAFETY: any byte is a valid data register value.
                Some(b) => u.dr.write(|w| unsafe { w.bits(u32::from(b)) }),
                None => {
                    cr1_bit(Cr1Bit::TxeIe, false);
                    return;
                }
            }
        }
        // QEMU 7.2's USART raises no transmit-empty interrupt (its transmitter
        // is always empty): while bytes wait and the transmitter takes them, the
        // handler is pended again, to run after whatever is more urgent. On
        // silicon the transmit-empty interrupt does it and this pend is at most
        // one entry more.
        if self.tx.ready() && u.sr.read().txe().bit_is_set() {
            NVIC::pend(pac::Interrupt::USART1);
        }
    }
}

/// USART1's interrupt: one received byte queued, or one queued byte sent.
#[interrupt]
fn USART1() {
    // SAFETY: set once by `open`, before the interrupt is unmasked, to a static
    // that lives for the rest of the run; this handler is its only user while
    // the tasks run (the fault and exit paths take it over with interrupts off,
    // and never return).
    if let Some(isr) = unsafe { ISR.load(Ordering::Relaxed).as_mut() } {
        isr.on_interrupt();
    }
}

/// The control task's receive budget renewed and the receive interrupt on: the
/// first period's, at [`Port::start`] (each later one comes with
/// [`Port::sort_and_rearm`]).
fn rearm_receive() {
    RX_BUDGETS.renew_control();
    receive_on();
}

/// The start of a plan period: the plan task's receive budget renewed and the
/// receive interrupt on.
pub fn rearm_route_receive() {
    RX_BUDGETS.renew_plan();
    receive_on();
}

/// The receive interrupt on, and the line unmasked (after the handler masked it
/// with both budgets spent).
fn receive_on() {
    cr1_bit(Cr1Bit::RxneIe, true);
    // SAFETY: the handler's state is in place (`Port::start` comes first) and it
    // touches no RTIC resource.
    unsafe { NVIC::unmask(pac::Interrupt::USART1) };
}

/// Interrupts off, the link's interrupts off, and the bytes the interrupt had
/// not sent yet sent by polling (at most [`TX_BYTES`], each wait bounded): a
/// frame in flight ends whole.
fn flush() {
    cortex_m::interrupt::disable();
    cr1_bit(Cr1Bit::RxneIe, false);
    cr1_bit(Cr1Bit::TxeIe, false);
    NVIC::mask(pac::Interrupt::USART1);
    // SAFETY: interrupts are off, so the handler cannot run again; its state is
    // a static (or null before `open`). A fault inside the handler leaves at
    // most its last byte half taken (sent twice: the host refuses that frame).
    if let Some(isr) = unsafe { ISR.load(Ordering::Relaxed).as_mut() } {
        // wcet-bound: MAX_UP_FRAME_BYTES + 1
        while let Some(b) = isr.tx.dequeue() {
            if !write_polled(&[b]) {
                break;
            }
        }
    }
}

/// The end of the run on the board (the host's `Stop`, a refused set-up, a
/// second fault): the frames queued sent ([`flush`]), then the core parks with
/// interrupts off. There is no host to tell the outcome (`_ok`) to: the frames
/// said it.
pub fn exit(_ok: bool) -> ! {
    flush();
    loop {
        cortex_m::asm::wfi();
    }
}
