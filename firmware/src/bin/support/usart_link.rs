// The flashed ECU's link: USART1 (PA9 TX, PA10 RX, alternate function 7) at
// `BAUD`, 8 data bits, no parity, one stop bit, interrupt-driven both ways into
// bounded buffers. Its interrupt sorts the received frames into the control
// task's and the plan task's queues (`firmware::link::demux`) and drains the
// transmit queue the control task fills. It takes at most `RX_BUDGET_BYTES` per
// control period: past them it stops reading (on silicon the peripheral then
// drops bytes; QEMU holds them back), so its interference is bounded whatever
// the other end sends; the control task re-arms it at each release.
//
// On a car the same frames would go over CAN-FD (docs/pil-and-hil.md, "The ECU application"):
// a 64-byte data field per CAN-FD frame, the link's COBS frames cut into
// segments by ISO 15765-2 (ISO-TP) on two identifiers (control, route), the
// FDCAN's receive FIFOs standing for the two queues here.

use core::sync::atomic::{AtomicU16, Ordering};

use firmware::link::demux::{Channel, Demux};
use firmware::link::{MAX_DOWN_FRAME_BYTES, MAX_DRIVING_DOWN_FRAME_BYTES, MAX_UP_FRAME_BYTES};
use heapless::spsc::{Consumer, Producer};
use stm32f4::stm32f405 as pac;

/// Baud rate of the link, bits/s.
pub const BAUD: u32 = 921_600;

/// USART1's kernel clock (APB2), Hz.
pub const APB2_HZ: u32 = 84_000_000;

/// The baud-rate register for [`BAUD`] at [`APB2_HZ`] with 16× oversampling:
/// `USARTDIV` in 1/16ths, rounded (`APB2_HZ / (16 · BAUD)` = 5.6966: mantissa 5,
/// fraction 11/16: 923,077 baud, 0.16 % off).
pub const BRR: u32 = (APB2_HZ + BAUD / 2) / BAUD;

/// Time of one byte on the line (a start bit, 8 data bits, a stop bit), µs: the
/// receive interrupt's minimum inter-arrival.
pub const BYTE_TIME_US: f64 = 10.0 * 1e6 / BAUD as f64;

/// The control task's receive queue, bytes (capacity one less): a sensor frame
/// and the start of the next.
pub const CONTROL_RX_BYTES: usize = 2 * MAX_DRIVING_DOWN_FRAME_BYTES;

/// The plan task's receive queue, bytes: one route frame (the host sends at most
/// one per plan period) and a delimiter.
pub const ROUTE_RX_BYTES: usize = MAX_DOWN_FRAME_BYTES + 2;

/// The transmit queue, bytes: one actuation frame.
pub const TX_BYTES: usize = MAX_UP_FRAME_BYTES + 1;

/// Bytes received per control period at most: a sensor frame and a route frame.
pub const RX_BUDGET_BYTES: u16 = (MAX_DRIVING_DOWN_FRAME_BYTES + MAX_DOWN_FRAME_BYTES) as u16;

/// Bytes transmitted per control period at most: one actuation frame.
pub const TX_BUDGET_BYTES: u16 = MAX_UP_FRAME_BYTES as u16;

/// Receive budget left in this control period, bytes.
static RX_LEFT: AtomicU16 = AtomicU16::new(0);

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

/// Sets or clears one bit of USART1's CR1 through the peripheral bit-band alias
/// (one store: no read-modify-write a preemption could undo).
fn cr1_bit(bit: Cr1Bit, on: bool) {
    const USART1_CR1: usize = 0x4001_100C;
    const PERIPH_BASE: usize = 0x4000_0000;
    const BITBAND_BASE: usize = 0x4200_0000;
    let alias = BITBAND_BASE + (USART1_CR1 - PERIPH_BASE) * 32 + bit as usize * 4;
    // SAFETY: the bit-band alias word of an existing register bit.
    unsafe { core::ptr::write_volatile(alias as *mut u32, u32::from(on)) };
}

/// Enables USART1 at [`BAUD`] on PA9/PA10 (clocks, pins, baud rate, receiver and
/// transmitter), interrupts off: the set-up polls it before the tasks run.
pub fn init(rcc: &pac::RCC, gpioa: &pac::GPIOA, usart1: &pac::USART1) {
    rcc.ahb1enr.modify(|_, w| w.gpioaen().enabled());
    rcc.apb2enr.modify(|_, w| w.usart1en().enabled());
    // PA9, PA10: alternate function 7 (USART1).
    gpioa
        .moder
        .modify(|_, w| w.moder9().alternate().moder10().alternate());
    gpioa.afrh.modify(|_, w| w.afrh9().af7().afrh10().af7());
    // SAFETY: any value is a valid baud-rate divisor; BRR is computed above.
    usart1.brr.write(|w| unsafe { w.bits(BRR) });
    usart1.cr1.write(|w| w.ue().enabled().te().enabled().re().enabled());
}

/// The next received byte, polled (the set-up, interrupts off): `None` when none
/// arrived yet.
pub fn poll_byte() -> Option<u8> {
    let u = usart();
    let sr = u.sr.read();
    (sr.rxne().bit_is_set() || sr.ore().bit_is_set()).then(|| u.dr.read().bits() as u8)
}

/// Writes `bytes` by polling, each byte's wait bounded (the set-up's answer and
/// the fault paths, interrupts off: nothing here can trap). False if the
/// transmitter never became ready.
pub fn write_polled(bytes: &[u8]) -> bool {
    // A byte's time at 168 MHz is ~1,820 cycles; a poll is a few: ample.
    const POLLS_PER_BYTE: u32 = 100_000;
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

/// What the interrupt handler owns: the sorter and its ends of the queues.
pub struct UsartIsr {
    demux: Demux,
    control: Producer<'static, u8, CONTROL_RX_BYTES>,
    route: Producer<'static, u8, ROUTE_RX_BYTES>,
    tx: Consumer<'static, u8, TX_BYTES>,
    /// Bytes dropped because their queue was full, bytes.
    pub dropped: u32,
}

impl UsartIsr {
    /// The handler's state over its ends of the queues.
    pub fn new(
        control: Producer<'static, u8, CONTROL_RX_BYTES>,
        route: Producer<'static, u8, ROUTE_RX_BYTES>,
        tx: Consumer<'static, u8, TX_BYTES>,
    ) -> Self {
        Self {
            demux: Demux::new(),
            control,
            route,
            tx,
            dropped: 0,
        }
    }

    /// One interrupt: at most one byte received (sorted into its queue, within
    /// the period's budget) and one byte sent; the transmit interrupt off when
    /// the queue is empty, the receive one off when the budget is spent.
    pub fn on_interrupt(&mut self) {
        let u = usart();
        let sr = u.sr.read();
        if sr.rxne().bit_is_set() || sr.ore().bit_is_set() {
            let left = RX_LEFT.load(Ordering::Relaxed);
            if left == 0 {
                // Spent: leave the byte (QEMU holds the rest back; silicon drops
                // what comes meanwhile) until the next release re-arms it.
                cr1_bit(Cr1Bit::RxneIe, false);
            } else {
                RX_LEFT.store(left - 1, Ordering::Relaxed);
                let byte = u.dr.read().bits() as u8;
                if let Some(e) = self.demux.push(byte) {
                    // At most 4 bytes.
                    for &b in e.bytes() {
                        let full = match e.channel {
                            Channel::Control => self.control.enqueue(b).is_err(),
                            Channel::Route => self.route.enqueue(b).is_err(),
                        };
                        self.dropped = self.dropped.wrapping_add(u32::from(full));
                    }
                }
            }
        }
        if sr.txe().bit_is_set() {
            match self.tx.dequeue() {
                // SAFETY: any byte is a valid data register value.
                Some(b) => u.dr.write(|w| unsafe { w.bits(u32::from(b)) }),
                None => cr1_bit(Cr1Bit::TxeIe, false),
            }
        }
    }
}

/// The start of a control period: the receive budget renewed and the receive
/// interrupt on.
pub fn rearm_receive() {
    RX_LEFT.store(RX_BUDGET_BYTES, Ordering::Relaxed);
    cr1_bit(Cr1Bit::RxneIe, true);
}

/// Queues `bytes` for transmission and starts the transmit interrupt; false
/// (nothing queued) when they do not all fit.
pub fn send(tx: &mut Producer<'static, u8, TX_BYTES>, bytes: &[u8]) -> bool {
    if tx.capacity() - tx.len() < bytes.len() {
        return false;
    }
    // wcet-bound: MAX_UP_FRAME_BYTES
    for &b in bytes {
        let _ = tx.enqueue(b);
    }
    cr1_bit(Cr1Bit::TxeIe, true);
    true
}
