//! The ECU application (RTIC v2, Cortex-M4F): binds the library's two tasks to
//! priorities and the release clock (SysTick, `support/release_clock.rs`), and
//! talks to the simulator.
//!
//! | task | priority | released | does |
//! |---|---|---|---|
//! | `control` | 2 (high) | every 10 ms by the monotonic | reads the sensor frame, [`ControlTask::run`] on the shared plan, sends the actuator frame |
//! | `plan` | 1 (low) | every 100 ms by the monotonic | [`PlanTask::run`] outside any lock, then [`PlanTask::publish`] (a buffer swap) inside a short lock on the shared plan, or, when a window of the road was received, its adoption instead; then receives the frames of a new window, if one was sent |
//!
//! No maths here: the app calls the same library functions the simulator calls.
//!
//! **Deadline policy** (`firmware::tasks`, the same in the simulator): a plan that
//! finishes after its 100 ms deadline but within 200 ms of its release is still
//! published when it finishes (it is the newest plan, stamped at its release, and
//! `control` follows it at the current time, i.e. shifted); an older one is
//! dropped. Until a plan is published `control` keeps following the previous one
//! shifted in time, then brings the car to a controlled stop when it runs out.
//! Releases that fall while the plan task is still running are skipped, not
//! queued, so the next activation plans from a fresh state.
//!
//! **The ECU watches its own deadlines** ([`firmware::deadline`]): each task's
//! releases (release `k` at `k` periods on the timeline, whose start is the
//! first `control` release), completions (`control`: its actuation frame
//! written, reported by the next frame; `plan`: the plan published, stamped
//! under the lock), response times, deadline misses, budget
//! overruns (its own core clock cycles, preemption excluded, over 6,000 /
//! 15.96 M) and skipped releases are counted on its own clock and sent in every
//! actuation frame (`plan`'s with its plan event). A `control` overrun is not
//! absorbed: the releases that fell during it are skipped and counted, and after
//! [`firmware::deadline::CONTROL_MISS_LIMIT`] consecutive misses the control task
//! latches the safe actuation (zero torque, steering held, as the panic path; fault
//! [`link::FAULT_DEADLINE`]). Its watchdog counts the times no new plan came for
//! more than [`firmware::deadline::PLAN_WATCHDOG_PERIODS`] plan periods (the
//! late-plan policy stops the car).
//!
//! **Link.** In the processor-in-the-loop run (`host-sim pil`) the simulator
//! starts QEMU in a folder holding two FIFOs, `ecu.down` (host → ECU) and
//! `ecu.up` (ECU → host), which the ECU opens through semihosting. Semihosting
//! calls are synchronous: QEMU's virtual clock (`-icount`) does not advance while
//! the host answers, so the run is deterministic. On a vehicle these frames would
//! come from the sensor fusion and go to the actuators over CAN; the frames
//! ([`firmware::link`]) are the same.
//!
//! **Two builds, one application** (docs/board.md). The board layer (the link's
//! transport, the log's, the end of a run and the fault paths' output) is
//! chosen by the cargo feature `board-usart`; the tasks, the library calls and
//! the frames are the same in both:
//! * without it (`cargo ecu-lockstep`), the lock-step build above: semihosting, `defmt`
//!   over semihosting, RTIC's dispatchers `USART1` and `USART2` (the processor
//!   in the loop runs this build; the timing analysis reads either);
//! * with it (`cargo ecu`, profile `board`), the binary you flash:
//!   USART1 (`support/usart_link.rs`), polled during the set-up, then
//!   interrupt-driven into bounded queues that [`firmware::link::demux`] sorts
//!   for the two tasks; `defmt` over RTT; no semihosting instruction anywhere;
//!   the dispatchers `SPI1` and `SPI2`. A release with no whole sensor frame yet
//!   runs as a dropout ([`link::SENSOR_MISSING`]).
//!
//! **Authenticated frames** ([`firmware::link::secoc`]): every frame, both ways,
//! carries a freshness value and a truncated AES-128-CMAC under the build's link
//! key. The control task verifies the sensor frame of its release before it acts
//! and authenticates its actuation frame; the plan task verifies the route
//! frames it reads. A frame refused (forged, replayed, corrupt) is counted by
//! reason and never acted on. A refused sensor frame is this release's: the
//! period runs on no estimate
//! ([`firmware::state_estimate::StateEstimate::unavailable`]: the dropout policy,
//! the control task's safe actuation, the plan task does not plan) and its
//! actuation frame says so ([`link::ActuationFrame::sensor`]); a run of them is a
//! run of dropout periods (the car brakes to a stop under the safe actuation, the
//! watchdog counts the plans missed) until a frame is accepted again. The counts
//! go in every actuation frame and the `Done` frame. A refused set-up frame
//! refuses the set-up ([`link::SetupError::FrameRefused`]).
//!
//! **Route**: the next window of the road comes on a channel of its own
//! (`ecu.route`), announced by the sensor frames (the host's total of route
//! frames: a refused sensor frame loses no announcement); the plan task
//! receives it after it publishes (it is the planner's input), so a window never
//! delays an actuation, and the next activation adopts it instead of planning
//! (the control task follows the last plan 100 ms longer): an activation plans
//! or adopts, never both, so the plan task's worst case is the larger of the
//! two, not their sum.
//!
//! **Clock**: `init` first sets the clock tree ([`firmware::clock_tree`]: the
//! crystal, the PLL, 168 MHz, the flash latency before the switch, the clock
//! security system on). Under QEMU's `netduinoplus2`, which has no RCC (its
//! registers read 0) and a fixed 168 MHz clock, the sequence writes nothing and
//! says so. A failed sequence on silicon (no crystal, no PLL lock, no switch)
//! leaves the core on its internal oscillator: the ECU answers the set-up with a
//! `Ready` frame of status [`link::SetupError::ClockFailed`] and stops, so the
//! control loop never runs at the wrong clock.
//!
//! **Panic and faults**: the panic handler, the HardFault handler (MemManage,
//! BusFault and UsageFault are left disabled in SHCSR, so they escalate to
//! HardFault) and the NMI handler (the clock security system's: the crystal
//! failed and the hardware switched the core to its internal oscillator) command
//! zero torque with the steering held, send it as an actuator frame with the
//! fault code ([`link::FAULT_PANIC`], [`link::FAULT_HARDFAULT`],
//! [`link::FAULT_NMI`]), write a fixed line to the semihosting stderr and stop
//! (the flashed build: the queued bytes and the fault frame written by polling
//! USART1, every wait bounded, then the core parks).
//! Nothing on that path formats (no `defmt`, no `core::fmt`) or can panic, and a
//! static guard sends a second entry straight to the exit: the handlers cannot
//! re-enter themselves.
//!
//! Build: `cargo ecu-lockstep` (lock-step), `cargo ecu` (flashed); run in the loop
//! with the simulator: `host-sim pil` (the lock-step build).
#![no_std]
#![no_main]
// Semihosting calls, painting the stack and the panic handler's actuator frame.
#![allow(unsafe_code)]

#[cfg(not(feature = "board-usart"))]
#[path = "support/qemu_exit.rs"]
mod qemu_exit;
#[path = "support/release_clock.rs"]
mod release_clock;
#[cfg(feature = "board-usart")]
#[path = "support/usart_link.rs"]
mod usart_link;

#[cfg(not(feature = "board-usart"))]
use core::sync::atomic::AtomicUsize;
use core::sync::atomic::{AtomicBool, AtomicPtr, AtomicU32, Ordering};

#[cfg(not(feature = "board-usart"))]
use cortex_m_semihosting::syscall;
#[cfg(feature = "board-usart")]
use defmt_rtt as _;
#[cfg(not(feature = "board-usart"))]
use defmt_semihosting as _;
use firmware::clock_tree::{self, ClockError, ClockRegisters, ClockSource, Register};
use firmware::deadline::{self, DeadlineMonitor, PlanWatchdog};
#[cfg(feature = "board-usart")]
use firmware::link::NewestFrameReader;
use firmware::link::{
    self, ActuationFrame, Authenticator, Down, FrameReader, LinkMac, Refusal, RefusalCounts,
    Stream, UpRef, Verifier, LINK_KEY, MAX_DOWN_FRAME_BYTES, MAX_DRIVING_DOWN_FRAME_BYTES,
    MAX_UP_FRAME_BYTES,
};
use firmware::low_level::Actuation;
use firmware::tasks::{ControlTask, PlanTask};
use firmware::timing;
#[cfg(not(feature = "board-usart"))]
use qemu_exit::exit;
#[cfg(feature = "board-usart")]
use usart_link::exit;

/// Rows of the window of the road the ECU holds (not the whole circuit: its RAM
/// does not grow with the track; the simulator sends the next window as the car
/// moves on).
pub const PATH_CAP: usize = firmware::tasks::ECU_PATH_ROWS;
/// Core clock, Hz (STM32F405 at 168 MHz; QEMU's SysTick counts at this rate of
/// virtual time).
pub const SYSCLK_HZ: u32 = firmware::timing::ECU_CLOCK_HZ;
/// The plan task's caps this binary was built with, for the timing report
/// (`host-sim wcet` reads them from the ELF): `QP_MAX_ITER` iterations,
/// `COLD_START_PASSES` passes, `QP_MAX_REFACTORIZATIONS` refactorizations, a
/// working set of `WS` rows, four little-endian `u32`. In the `.ecu_caps`
/// section, which `memory.x` keeps out of flash and RAM.
#[used]
#[link_section = ".ecu_caps"]
static ECU_CAPS: [u32; 4] = [
    firmware::mpc::QP_MAX_ITER,
    firmware::mpc::COLD_START_PASSES as u32,
    firmware::mpc::QP_MAX_REFACTORIZATIONS,
    firmware::mpc::WS as u32,
];

/// Monotonic tick rate, Hz (one tick a control period).
const MONO_HZ: u32 = (1_000_000 / firmware::timing::MONO_TICK_US) as u32;
/// Core clock ticks per monotonic tick (SysTick's reload plus one).
const TICKS_PER_MONO: u32 = SYSCLK_HZ / MONO_HZ;
// A whole number of core clock ticks per monotonic tick, within SysTick's
// 24-bit reload register.
const _: () = assert!(TICKS_PER_MONO * MONO_HZ == SYSCLK_HZ);
const _: () = assert!(TICKS_PER_MONO > 1 && TICKS_PER_MONO - 1 <= 0x00FF_FFFF);

/// The control channel (null: not open yet), for the panic handler's frame:
/// its up stream's CMAC and freshness counter authenticate it as any other.
/// Taken only on the path that never returns (see [`safe_stop_work`]).
static PANIC_LINK: AtomicPtr<Link> = AtomicPtr::new(core::ptr::null_mut());
/// Host file descriptor of the semihosting stderr (0: not open), for the panic
/// handler's fixed line.
#[cfg(not(feature = "board-usart"))]
static ERR_FD: AtomicUsize = AtomicUsize::new(0);
/// Set by the first entry into [`safe_stop`]: a second entry (a fault inside the
/// handler) goes straight to the exit.
static STOPPING: AtomicBool = AtomicBool::new(false);
/// Frames the host wrote on the route channel that the plan task has not read
/// yet (announced by `control` from the sensor frames), frames.
static ROUTE_PENDING: AtomicU32 = AtomicU32::new(0);
/// Route frames the plan task refused, frames (the plan task alone writes it).
static ROUTE_REJECTED: AtomicU32 = AtomicU32::new(0);
/// Monotonic tick (`MONO_TICK_US`) of the timeline's start: the first `control` release.
static START_MONO_TICKS: AtomicU32 = AtomicU32::new(0);
/// Last steering command, `f32` bits (the panic handler holds it).
static LAST_DELTA_BITS: AtomicU32 = AtomicU32::new(0);
/// The control task's friction estimate `μ̂` (`firmware::friction`), `f32` bits,
/// written by `control` each period and read by `plan` with the estimate at its
/// release (a word: no lock; 0 before the first period, which `plan` takes as no
/// estimate).
static FRICTION_MU_BITS: AtomicU32 = AtomicU32::new(0);
/// The control task's [`ControlTask::tyres_linear`](firmware::tasks::ControlTask::tyres_linear),
/// written by `control` each period and read by `plan` with the estimate at its
/// release, as [`FRICTION_MU_BITS`] (false before the first period).
static TYRES_LINEAR: AtomicBool = AtomicBool::new(false);
/// Core clock ticks spent in `control` so far, link included (the plan task
/// subtracts them from its elapsed time; the control task alone writes it).
static CONTROL_TICKS: AtomicU32 = AtomicU32::new(0);
/// Core clock tick count at the start of the timeline (t = 0): the start of the
/// monotonic tick of the first release.
static EPOCH_TICKS: AtomicU32 = AtomicU32::new(0);
/// High bits of the epoch (the 64-bit tick count's upper half).
static EPOCH_TICKS_HI: AtomicU32 = AtomicU32::new(0);

/// Core clock ticks since the monotonic started (168 MHz; 64 bits never wrap).
/// Not inlined: one copy of the monotonic's read (which counts the tick whose
/// SysTick exception is pending) instead of one per call site.
///
/// The tick count read on both sides of the SysTick counter: equal, the counter
/// lies in that tick. Different, a SysTick came between the reads, and the
/// counter read again after the second lies in its tick: another needs a whole
/// tick period (10 ms) of preemption within the next few instructions, which the
/// response-time analysis excludes. No retry loop.
#[inline(never)]
fn core_ticks() -> u64 {
    let a = mono_ticks();
    let cvr = cortex_m::peripheral::SYST::get_current();
    let b = mono_ticks();
    let cvr = if a == b {
        cvr
    } else {
        cortex_m::peripheral::SYST::get_current()
    };
    let within = (TICKS_PER_MONO - 1).saturating_sub(cvr);
    b as u64 * TICKS_PER_MONO as u64 + within as u64
}

/// The monotonic's tick count ([`release_clock::now_ticks`]). Not inlined: one
/// copy for both of [`core_ticks`]'s reads.
#[inline(never)]
fn mono_ticks() -> u32 {
    release_clock::now_ticks()
}

fn epoch_ticks() -> u64 {
    ((EPOCH_TICKS_HI.load(Ordering::Relaxed) as u64) << 32)
        | EPOCH_TICKS.load(Ordering::Relaxed) as u64
}

defmt::timestamp!("{=u64:us}", now_us());

/// µs since the timeline's start.
fn now_us() -> u64 {
    timeline_us(core_ticks())
}

/// The instant of a core clock tick count `ticks` ([`core_ticks`]) on the
/// timeline, µs since its start.
fn timeline_us(ticks: u64) -> u64 {
    // A small division (the clock is whole MHz): no 64-bit library division.
    timing::div_u64_small(ticks.saturating_sub(epoch_ticks()), timing::TICKS_PER_US)
        .unwrap_or(u64::MAX)
}

/// The monotonic tick of a time on the timeline, `t_us` µs (whole ticks), ticks.
fn tick_at(t_us: u64) -> u32 {
    let start = START_MONO_TICKS.load(Ordering::Relaxed);
    start.wrapping_add(timing::div_u64_small(t_us, timing::MONO_TICK_US as u32).unwrap_or(0) as u32)
}

/// Byte runs the control task reads from the down-link per release at most: the
/// sensor frame, and, before it, the part of a frame longer than a sensor frame
/// (refused). The first whole frame ends the release's receiving, accepted or
/// refused: the host writes one frame per release.
#[cfg(not(feature = "board-usart"))]
const RECEIVE_FRAMES: usize = 2;

/// Route frames the plan task reads per activation at most: one (the host sends
/// at most one per plan period, before the sensor frame of the plan's release),
/// so a window of the road arrives over `link::route_frames(PATH_CAP)` plan
/// periods and no activation verifies a whole window.
const ROUTE_FRAMES: u32 = 1;

/// Why the control task got no sensor frame to act on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkEnd {
    /// The host asked to stop.
    Stop,
    /// The host closed the link.
    Closed,
    /// [`RECEIVE_FRAMES`] runs of bytes without a whole frame: the byte stream is
    /// out of step with the host's frames.
    Garbled,
    /// This release's frame was refused (counted): the period runs as a dropout.
    Refused {
        /// [`link::ActuationFrame::sensor`]: the [`Refusal::code`], or
        /// [`link::SENSOR_UNEXPECTED`].
        code: u8,
        /// The sequence number the ECU expected of it: the answer's.
        seq: u32,
    },
    /// No whole frame had arrived at this release (the flashed build's USART
    /// link, not in lock-step with the host): the period runs as a dropout,
    /// answered with [`link::SENSOR_MISSING`].
    #[cfg(feature = "board-usart")]
    Missing {
        /// The sequence number the ECU expected: the answer's.
        seq: u32,
    },
}

/// The control channel to the simulator (`ecu.down`, `ecu.up`), through
/// semihosting, and the authentication of its frames: one CMAC engine for both
/// directions (the control task is the only one that uses it), the freshness of
/// the down stream and the counter of the up stream.
pub struct Link {
    #[cfg(not(feature = "board-usart"))]
    down: usize,
    #[cfg(not(feature = "board-usart"))]
    up: usize,
    /// The USART: the control task's receive queue and the transmit queue.
    #[cfg(feature = "board-usart")]
    port: usart_link::Port,
    /// The frame being received while driving: a sensor frame fits
    /// (`MAX_DRIVING_DOWN_FRAME_BYTES`); a longer one is dropped and counted as
    /// refused. The set-up's larger frames go through a reader of their own, on
    /// the stack of `init` ([`Link::receive`]), not in static RAM for the run.
    #[cfg(not(feature = "board-usart"))]
    reader: FrameReader<MAX_DRIVING_DOWN_FRAME_BYTES>,
    /// The frames being received while driving, the newest whole one kept for
    /// the release ([`Link::receive_sensor`]): a sensor frame fits
    /// (`MAX_DRIVING_DOWN_FRAME_BYTES`); a longer one is dropped and counted as
    /// refused. The set-up's larger frames go through a reader of their own.
    #[cfg(feature = "board-usart")]
    reader: NewestFrameReader<MAX_DRIVING_DOWN_FRAME_BYTES>,
    #[cfg(not(feature = "board-usart"))]
    rx: [u8; 64],
    #[cfg(not(feature = "board-usart"))]
    rx_len: usize,
    #[cfg(not(feature = "board-usart"))]
    rx_pos: usize,
    /// AES-128-CMAC under the link key (its key schedule built once, at
    /// [`Link::open`]).
    mac: LinkMac,
    /// The down stream's last accepted freshness.
    down_rx: Verifier,
    /// The up stream's freshness counter.
    up_tx: Authenticator,
    /// The frame being sent: the largest `Up` frame fits (`MAX_UP_FRAME_BYTES`).
    /// In the link's static storage, not on the stack: the control task's
    /// frames and the safe stop's (which takes the link over) are sent one at a
    /// time, and the stack bound counts a buffer on the stack once for the
    /// control task and once more for the safe stop on top of it.
    tx: [u8; MAX_UP_FRAME_BYTES],
    /// The `seq` the next sensor frame should carry (the last accepted + 1; the
    /// answer to a refused one carries it).
    next_seq: u32,
    /// Route frames announced so far (the sensor frames carry the host's total).
    route_announced: u32,
    /// Frames refused (garbled, short, wrong version, forged, replayed,
    /// unexpected), frames.
    pub rejected: u32,
    /// The refused frames by reason, frames.
    pub refused: RefusalCounts,
}

#[cfg(not(feature = "board-usart"))]
fn sh_open(name: &[u8], mode: usize) -> Option<usize> {
    // `name` ends with a NUL; the length excludes it.
    let fd = unsafe { syscall!(OPEN, name.as_ptr(), mode, name.len() - 1) };
    if fd as isize == -1 {
        None
    } else {
        Some(fd)
    }
}

/// Writes `bytes` to the host file `fd` in at most four writes (a host takes a
/// frame in one; a short write is retried for the rest); false when the host
/// took none of a write or the bytes are not all written after four. No slicing
/// that can panic: the panic path uses it.
#[cfg(not(feature = "board-usart"))]
fn sh_write(fd: usize, mut bytes: &[u8]) -> bool {
    // A host that has not taken the frame in four writes is not keeping up: the
    // frame is given up (the caller counts it) rather than retried byte by byte.
    // wcet-bound: 4
    for _ in 0..4 {
        if bytes.is_empty() {
            return true;
        }
        let left = unsafe { syscall!(WRITE, fd, bytes.as_ptr(), bytes.len()) };
        if left >= bytes.len() {
            return false;
        }
        bytes = match bytes.get(bytes.len() - left..) {
            Some(rest) => rest,
            None => return false,
        };
    }
    bytes.is_empty()
}

/// Reads up to `buf.len()` bytes of the host file `fd`; the count, 0 at its end.
#[cfg(not(feature = "board-usart"))]
fn sh_read(fd: usize, buf: &mut [u8]) -> usize {
    let n = buf.len();
    let left = unsafe { syscall!(READ, fd, buf.as_mut_ptr(), n) };
    n.saturating_sub(left)
}

/// Counts a refused frame in `rejected` and, with its reason (`Some`; `None`:
/// an authentic frame not expected here), in `refused`.
fn count_refused(rejected: &mut u32, refused: &mut RefusalCounts, reason: Option<Refusal>) {
    *rejected = rejected.wrapping_add(1);
    if let Some(r) = reason {
        refused.count(r);
    }
}

impl Link {
    /// Opens `ecu.down` for reading, `ecu.up` for writing and `ecu.route` for
    /// reading, in that order (the simulator opens them in the same order), and
    /// the semihosting stderr (`:tt`, append) for the panic handler's line;
    /// builds the CMAC's key schedule from the build's link key.
    #[cfg(not(feature = "board-usart"))]
    pub fn open() -> Option<(Self, RouteLink)> {
        const R_BINARY: usize = 1;
        const W_TRUNC_BINARY: usize = 5;
        const APPEND: usize = 8;
        let down = sh_open(b"ecu.down\0", R_BINARY)?;
        let up = sh_open(b"ecu.up\0", W_TRUNC_BINARY)?;
        let route = sh_open(b"ecu.route\0", R_BINARY)?;
        if let Some(err) = sh_open(b":tt\0", APPEND) {
            ERR_FD.store(err, Ordering::Relaxed);
        }
        Some((
            Self {
                down,
                up,
                reader: FrameReader::new(),
                rx: [0; 64],
                rx_len: 0,
                rx_pos: 0,
                mac: LinkMac::new(&LINK_KEY),
                down_rx: Verifier::new(Stream::Down),
                up_tx: Authenticator::new(Stream::Up),
                tx: [0; MAX_UP_FRAME_BYTES],
                next_seq: 0,
                route_announced: 0,
                rejected: 0,
                refused: RefusalCounts::new(),
            },
            RouteLink {
                fd: route,
                rx: Verifier::new(Stream::Route),
            },
        ))
    }

    /// The link over the USART's two ends (`port`: the control task's, `route`:
    /// the plan task's; [`usart_link::open`]); builds the CMAC's key schedule
    /// from the build's link key.
    #[cfg(feature = "board-usart")]
    pub fn over(port: usart_link::Port, route: usart_link::RoutePort) -> (Self, RouteLink) {
        (
            Self {
                port,
                reader: NewestFrameReader::new(),
                mac: LinkMac::new(&LINK_KEY),
                down_rx: Verifier::new(Stream::Down),
                up_tx: Authenticator::new(Stream::Up),
                tx: [0; MAX_UP_FRAME_BYTES],
                next_seq: 0,
                route_announced: 0,
                rejected: 0,
                refused: RefusalCounts::new(),
            },
            RouteLink {
                port: route,
                rx: Verifier::new(Stream::Route),
            },
        )
    }

    /// Counts a refused frame (`Some(reason)`; `None`: an authentic frame not
    /// expected here).
    fn count_refused(&mut self, reason: Option<Refusal>) {
        count_refused(&mut self.rejected, &mut self.refused, reason);
    }

    /// The next host frame of the set-up, read with `reader` (every `Down`
    /// frame fits); `Err(Some(reason))` for a frame refused (counted), `Err(None)`
    /// when the host closed the link. Before the tasks run.
    pub fn receive(
        &mut self,
        reader: &mut FrameReader<MAX_DOWN_FRAME_BYTES>,
    ) -> Result<Down, Option<Refusal>> {
        loop {
            let byte = self.next_setup_byte().ok_or(None)?;
            let decoded = match reader.push(byte) {
                None => continue,
                Some(Ok(frame)) => link::decode::<Down>(frame, &mut self.mac, &mut self.down_rx),
                Some(Err(e)) => Err(e),
            };
            return decoded.map_err(|e| {
                self.count_refused(Some(e.refusal()));
                Some(e.refusal())
            });
        }
    }

    /// The sensor frame of this release: the first whole frame within at most
    /// [`RECEIVE_FRAMES`] runs of at most [`MAX_DRIVING_DOWN_FRAME_BYTES`] bytes
    /// each (a `Sensor` frame; `Stop` is shorter). The host writes one frame per
    /// release, so a refused frame (forged, replayed, corrupt, or an authentic
    /// frame of another kind) is this release's: it is counted and answered as a
    /// dropout ([`LinkEnd::Refused`]), never acted on. Bytes that run past that
    /// length without a delimiter are counted as refused and the next run read;
    /// no whole frame in [`RECEIVE_FRAMES`] runs is a broken link
    /// ([`LinkEnd::Garbled`]). A frame is decoded (CRC, CMAC) at most once per
    /// release.
    #[cfg(not(feature = "board-usart"))]
    pub fn receive_sensor(&mut self) -> Result<link::SensorFrame, LinkEnd> {
        // WCET: RECEIVE_FRAMES (2; an ECU constant, not the library's).
        // wcet-bound: 2
        for _ in 0..RECEIVE_FRAMES {
            // One frame's bytes up to its delimiter; decoded after the loop, once
            // per frame.
            let mut ended = false;
            // wcet-bound: MAX_DRIVING_DOWN_FRAME_BYTES
            for _ in 0..MAX_DRIVING_DOWN_FRAME_BYTES {
                let byte = self.next_byte().ok_or(LinkEnd::Closed)?;
                if byte == 0 {
                    ended = true;
                    break;
                }
                // A byte inside a frame: the reader only stores it.
                let _ = self.reader.push(byte);
            }
            if !ended {
                self.reader.reset();
                // The compiler makes this path, which skips the loop's head, a binary
                // loop of its own nested in the loop: their back edges together are
                // the loop's iterations.
                // wcet-bound: same loop
                self.count_refused(Some(Refusal::Corrupt));
                continue;
            }
            let reason = match self.reader.push(0) {
                // Two delimiters in a row: idle, no frame.
                None => continue,
                Some(Ok(frame)) => {
                    match link::decode::<Down>(frame, &mut self.mac, &mut self.down_rx) {
                        Ok(Down::Sensor(f)) => {
                            self.next_seq = f.seq.wrapping_add(1);
                            return Ok(f);
                        }
                        Ok(Down::Stop) => return Err(LinkEnd::Stop),
                        Ok(_) => None,
                        Err(e) => Some(e.refusal()),
                    }
                }
                Some(Err(e)) => Some(e.refusal()),
            };
            self.count_refused(reason);
            let seq = self.next_seq;
            self.next_seq = seq.wrapping_add(1);
            return Err(LinkEnd::Refused {
                code: reason.map_or(link::SENSOR_UNEXPECTED, Refusal::code),
                seq,
            });
        }
        Err(LinkEnd::Garbled)
    }

    /// The sensor frame of this release, from the bytes the USART interrupt
    /// received since the last release, sorted at this call
    /// ([`usart_link::Port::sort_and_rearm`]: the control task's bytes straight
    /// into its frame reader, the road's into the plan task's queue): the newest
    /// whole frame among them, decoded (CRC, CMAC) once. The link is not in lock-step with the
    /// host: a frame that missed its release is whole at the next one with that
    /// release's own, and the newer one is taken (the older is superseded, not
    /// decoded: the answer's `seq` says which one was used), so the ECU does not
    /// answer a period behind from then on. A refused newest frame (forged,
    /// replayed, corrupt, too long, or an authentic frame of another kind) is
    /// counted and answered as a dropout ([`LinkEnd::Refused`]), never acted on.
    /// No whole frame yet is [`LinkEnd::Missing`], a dropout too; the bytes of a
    /// frame still arriving wait in the reader for the next release.
    #[cfg(feature = "board-usart")]
    pub fn receive_sensor(&mut self) -> Result<link::SensorFrame, LinkEnd> {
        // The newest frame's framing refusal, when the newest that ended was not a
        // frame (counted as it ended).
        let mut malformed = None;
        let (reader, rejected, refused) = (&mut self.reader, &mut self.rejected, &mut self.refused);
        self.port.sort_and_rearm(|byte| match reader.push(byte) {
            None => {}
            Some(Ok(())) => malformed = None,
            Some(Err(e)) => {
                count_refused(rejected, refused, Some(e.refusal()));
                malformed = Some(e.refusal());
            }
        });
        let reason = match self.reader.take_newest() {
            Some(frame) => match link::decode::<Down>(frame, &mut self.mac, &mut self.down_rx) {
                Ok(Down::Sensor(f)) => {
                    self.next_seq = f.seq.wrapping_add(1);
                    return Ok(f);
                }
                Ok(Down::Stop) => return Err(LinkEnd::Stop),
                Ok(_) => None,
                Err(e) => Some(e.refusal()),
            },
            None => match malformed {
                // Refused and counted as it ended.
                Some(r) => {
                    let seq = self.next_seq;
                    self.next_seq = seq.wrapping_add(1);
                    return Err(LinkEnd::Refused {
                        code: r.code(),
                        seq,
                    });
                }
                None => return Err(LinkEnd::Missing { seq: self.next_seq }),
            },
        };
        self.count_refused(reason);
        let seq = self.next_seq;
        self.next_seq = seq.wrapping_add(1);
        Err(LinkEnd::Refused {
            code: reason.map_or(link::SENSOR_UNEXPECTED, Refusal::code),
            seq,
        })
    }

    /// The route frames the host announced in an accepted sensor frame (its
    /// total, `route_frames`) that were not announced before, frames.
    fn newly_announced(&mut self, total: u32) -> u32 {
        let new = total.saturating_sub(self.route_announced);
        self.route_announced = self.route_announced.max(total);
        new
    }

    /// The next byte of the down-link; `None` when the host closed it.
    #[cfg(not(feature = "board-usart"))]
    fn next_byte(&mut self) -> Option<u8> {
        if self.rx_pos == self.rx_len {
            let got = sh_read(self.down, &mut self.rx);
            if got == 0 {
                return None; // end of file: the host is gone
            }
            self.rx_len = got;
            self.rx_pos = 0;
        }
        let byte = *self.rx.get(self.rx_pos)?;
        self.rx_pos += 1;
        Some(byte)
    }

    /// The next byte of the set-up, waiting for it; `None` when the host closed
    /// the link.
    #[cfg(not(feature = "board-usart"))]
    fn next_setup_byte(&mut self) -> Option<u8> {
        self.next_byte()
    }

    /// The next byte of the set-up: polled, waiting for it (the interrupt takes
    /// over only when the tasks start).
    #[cfg(feature = "board-usart")]
    fn next_setup_byte(&mut self) -> Option<u8> {
        Some(self.port.next_byte_polled())
    }

    /// Sends one frame to the host, authenticated on the up stream, through the
    /// link's frame buffer (`tx`: the largest `Up` frame, `MAX_UP_FRAME_BYTES`,
    /// tested on the largest message). Not inlined: the encoder's frames are on
    /// the stack only while a frame is sent. The message comes by reference
    /// ([`UpRef`]): no copy of it in an `Up` on the caller's stack.
    #[inline(never)]
    #[cfg(not(feature = "board-usart"))]
    pub fn send(&mut self, msg: UpRef<'_>) -> bool {
        match link::encode(&msg, &mut self.mac, &mut self.up_tx, &mut self.tx) {
            // No slicing that can panic: the panic path sends through it.
            Ok(n) => self
                .tx
                .get(..n)
                .is_some_and(|bytes| sh_write(self.up, bytes)),
            Err(_) => false,
        }
    }

    /// [`Link::send`] outside the tasks (the set-up's answers, the end of the
    /// run, the fault paths): the same in this build.
    #[cfg(not(feature = "board-usart"))]
    pub fn send_polled(&mut self, msg: UpRef<'_>) -> bool {
        self.send(msg)
    }

    /// The end of the run or a fault, interrupts off: nothing to hand over in
    /// this build (semihosting writes are synchronous).
    #[cfg(not(feature = "board-usart"))]
    fn take_over(&mut self) {}

    /// [`Link::send`] over the USART, the tasks' path: the frame queued for the
    /// interrupt (false, nothing queued, when the previous frame has not left
    /// yet); it never waits.
    #[inline(never)]
    #[cfg(feature = "board-usart")]
    pub fn send(&mut self, msg: UpRef<'_>) -> bool {
        match link::encode(&msg, &mut self.mac, &mut self.up_tx, &mut self.tx) {
            // No slicing that can panic: the panic path sends through it.
            Ok(n) => match self.tx.get(..n) {
                Some(bytes) => self.port.write(bytes),
                None => false,
            },
            Err(_) => false,
        }
    }

    /// [`Link::send`] outside the tasks, written by polling, every wait bounded:
    /// the set-up's answers (before the interrupt takes over) and, after
    /// [`Link::take_over`], the end of the run's and the fault paths' frames.
    /// Apart from [`Link::send`], so that no task's path holds a polled wait.
    #[inline(never)]
    #[cfg(feature = "board-usart")]
    pub fn send_polled(&mut self, msg: UpRef<'_>) -> bool {
        match link::encode(&msg, &mut self.mac, &mut self.up_tx, &mut self.tx) {
            // No slicing that can panic: the panic path sends through it.
            Ok(n) => match self.tx.get(..n) {
                Some(bytes) => self.port.write_polled(bytes),
                None => false,
            },
            Err(_) => false,
        }
    }

    /// The end of the run or a fault: interrupts off, the frame in flight sent
    /// whole by polling ([`usart_link::Port::take_over`]); then
    /// [`Link::send_polled`].
    #[cfg(feature = "board-usart")]
    fn take_over(&mut self) {
        self.port.take_over();
    }
}

/// The route channel (`ecu.route`): the frames of the next window of the road,
/// read by the plan task (one byte at a time: they are few), and the route
/// stream's last accepted freshness.
pub struct RouteLink {
    #[cfg(not(feature = "board-usart"))]
    fd: usize,
    /// The USART's queue of the road's frames (sorted by the control task).
    #[cfg(feature = "board-usart")]
    port: usart_link::RoutePort,
    rx: Verifier,
}

/// Route frames the plan task refused, by reason (the control task reports them
/// with its own; the plan task alone writes them), frames.
static ROUTE_REFUSED_AUTH: AtomicU32 = AtomicU32::new(0);
/// See [`ROUTE_REFUSED_AUTH`].
static ROUTE_REFUSED_REPLAY: AtomicU32 = AtomicU32::new(0);
/// See [`ROUTE_REFUSED_AUTH`].
static ROUTE_REFUSED_CORRUPT: AtomicU32 = AtomicU32::new(0);

/// The route channel's refusals by reason so far.
fn route_refused() -> RefusalCounts {
    RefusalCounts {
        auth: ROUTE_REFUSED_AUTH.load(Ordering::Relaxed),
        replay: ROUTE_REFUSED_REPLAY.load(Ordering::Relaxed),
        corrupt: ROUTE_REFUSED_CORRUPT.load(Ordering::Relaxed),
    }
}

impl RouteLink {
    /// Reads `frames` frames of the road into `staging` (at most [`ROUTE_FRAMES`],
    /// each at most [`MAX_DOWN_FRAME_BYTES`] bytes; refused ones are counted in
    /// [`ROUTE_REJECTED`] and by reason); stops early when the host closed the
    /// channel. Not inlined: its decoded frame and its CMAC engine live on the
    /// stack only while it runs, not beside the MPC step's frames in the plan
    /// task's. Its frame buffer is on the stack too (no static RAM): the host
    /// writes whole frames and announces them, so no frame is left half read
    /// between two calls. The CMAC's key schedule is built here, once per window
    /// (the control task's engine is its own, in its link: no lock between the
    /// tasks).
    #[inline(never)]
    fn receive(&mut self, frames: u32, staging: &mut Staging) {
        let mut reader: FrameReader<MAX_DOWN_FRAME_BYTES> = FrameReader::new();
        let mut mac = LinkMac::new(&LINK_KEY);
        let mut byte = [0u8; 1];
        // WCET: ROUTE_FRAMES, this application's one frame per activation.
        // wcet-bound: 1
        for _ in 0..frames.min(ROUTE_FRAMES) {
            // One frame's bytes up to its delimiter; decoded after the loop, once
            // per frame.
            let mut ended = false;
            // wcet-bound: MAX_DOWN_FRAME_BYTES
            for _ in 0..MAX_DOWN_FRAME_BYTES {
                #[cfg(not(feature = "board-usart"))]
                if sh_read(self.fd, &mut byte) == 0 {
                    return;
                }
                // The host writes a route frame whole before the sensor frame that
                // announces it, and the interrupt queues bytes in order: an
                // announced frame is in the queue whole.
                #[cfg(feature = "board-usart")]
                match self.port.next_byte() {
                    Some(b) => byte[0] = b,
                    None => return,
                }
                if byte[0] == 0 {
                    ended = true;
                    break;
                }
                // A byte inside a frame: the reader only stores it.
                let _ = reader.push(byte[0]);
            }
            let outcome = if ended {
                match reader.push(0) {
                    Some(Ok(frame)) => match link::decode::<Down>(frame, &mut mac, &mut self.rx) {
                        Ok(Down::PathChunk(c)) => Ok(staging.chunk(&c)),
                        Ok(Down::Window(w)) => {
                            staging.complete(&w);
                            Ok(true)
                        }
                        Ok(_) => Ok(false),
                        Err(e) => Err(e.refusal()),
                    },
                    Some(Err(e)) => Err(e.refusal()),
                    None => Ok(false),
                }
            } else {
                Err(Refusal::Corrupt)
            };
            if outcome != Ok(true) {
                reader.reset();
                add_own(&ROUTE_REJECTED, 1);
            }
            if let Err(reason) = outcome {
                let count = match reason {
                    Refusal::Auth => &ROUTE_REFUSED_AUTH,
                    Refusal::Replay => &ROUTE_REFUSED_REPLAY,
                    Refusal::Corrupt => &ROUTE_REFUSED_CORRUPT,
                };
                add_own(count, 1);
            }
        }
    }
}

/// The end of the run, from the control task: the stack's high-water mark and the
/// refused frames in a Done frame, then QEMU's exit (`ok` when the host asked to
/// stop). Not inlined, and it never returns: the timing analysis leaves it out of
/// the control task's activations.
#[inline(never)]
fn stop(link: &mut Link, ok: bool) -> ! {
    let (used, size) = stack_high_water();
    defmt::info!("ecu: stop; stack high-water {} of {} bytes", used, size);
    let rejected = link
        .rejected
        .wrapping_add(ROUTE_REJECTED.load(Ordering::Relaxed));
    let refused = link.refused.plus(route_refused());
    link.take_over();
    link.send_polled(UpRef::Done(&link::DoneFrame {
        stack_high_water_bytes: used,
        stack_size_bytes: size,
        rejected_frames: rejected,
        refused,
    }));
    exit(ok)
}

/// Stack painting: the untouched part of the stack keeps this word.
const PAINT: u32 = 0xCCCC_CCCC;

extern "C" {
    static _stack_start: u32;
    static _stack_end: u32;
}

/// Lowest address the stack may reach (with flip-link the stack sits below the
/// statics, from the start of RAM; without it, above `.bss`).
fn stack_bottom() -> usize {
    let start = core::ptr::addr_of!(_stack_start) as usize;
    let end = core::ptr::addr_of!(_stack_end) as usize;
    if end < start {
        end
    } else {
        0x2000_0000
    }
}

/// Fills the unused stack below the current stack pointer (less a margin).
fn paint_stack() {
    let sp = cortex_m::register::msp::read() as usize;
    let mut p = (stack_bottom() + 3) & !3;
    while p + 64 < sp {
        unsafe { core::ptr::write_volatile(p as *mut u32, PAINT) };
        p += 4;
    }
}

/// Bytes of stack ever used: from the top down to the lowest overwritten word.
fn stack_high_water() -> (u32, u32) {
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let bottom = (stack_bottom() + 3) & !3;
    let mut p = bottom;
    // WCET: one word per pass from `bottom` up to `top`, both in the 128 KiB of RAM
    // (memory.x): at most 128 KiB / 4 passes (reached only from the stop path).
    // wcet-bound: 128 * 1024 / 4
    while p < top && unsafe { core::ptr::read_volatile(p as *const u32) } == PAINT {
        p += 4;
    }
    ((top - p) as u32, (top - bottom) as u32)
}

/// The next window of the road, received by the plan task chunk by chunk.
pub struct Staging {
    rows: [[f32; 4]; PATH_CAP],
    received: usize,
    ready: Option<link::WindowFrame>,
}

impl Default for Staging {
    fn default() -> Self {
        Self::new()
    }
}

impl Staging {
    /// Empty (`const`, for the app's shared resources).
    pub const fn new() -> Self {
        Self {
            rows: [[0.0; 4]; PATH_CAP],
            received: 0,
            ready: None,
        }
    }

    /// Rows of a chunk (the first chunk of a window starts at row 0); false when
    /// out of order or past the capacity.
    fn chunk(&mut self, c: &link::PathChunkFrame) -> bool {
        if c.first == 0 {
            self.received = 0;
            self.ready = None;
        }
        let (first, n) = (c.first as usize, c.count as usize);
        if first != self.received || first + n > PATH_CAP || n > c.rows.len() {
            return false;
        }
        // WCET: n <= PATH_CHUNK_ROWS rows of four f32.
        // wcet-bound: PATH_CHUNK_ROWS * 16 bytes
        self.rows[first..first + n].copy_from_slice(&c.rows[..n]);
        self.received = first + n;
        true
    }

    /// The window is complete when all its rows arrived.
    fn complete(&mut self, w: &link::WindowFrame) {
        if w.rows as usize == self.received {
            self.ready = Some(*w);
        }
    }

    /// Copies a complete window into the planner's path storage.
    fn take_into(&mut self, planner: &mut PlanTask<f32, PATH_CAP>) -> Option<link::WindowFrame> {
        let w = self.ready.take()?;
        // WCET: `rows` holds PATH_CAP = ECU_PATH_ROWS rows.
        // wcet-bound: ECU_PATH_ROWS
        for (i, r) in self.rows.iter().take(w.rows as usize).enumerate() {
            planner.path.stage_row(i, *r);
        }
        self.received = 0;
        Some(w)
    }
}

/// The control task's own work, [`ControlTask::run`] on the estimate and the plan
/// (inside the `plan` lock). Not inlined: the timing analysis bounds it alone,
/// against [`deadline::CONTROL_BUDGET_CYCLES`]. Its symbol has a fixed name, which
/// the firmware's build script lists first in the linker's symbol ordering: it
/// starts `.text` right after `Reset`, so its flash lines (and its bound) do not
/// move when other code changes size.
#[inline(never)]
#[export_name = "ecu_control_job"]
fn control_job(
    control: &mut ControlTask<f32>,
    e: &firmware::state_estimate::StateEstimate<f32>,
    plan: &firmware::plan::Plan<f32>,
) -> Actuation<f32> {
    control.run(e, plan, e.stamp_us)
}

/// The plan task's own work: [`PlanTask::run`] on the estimate, planning with
/// `friction_mu` (the control task's `μ̂`, 0 for none), its sideslip lag learning
/// when `tyres_linear` (the control task's). Not inlined: the timing analysis
/// bounds it alone, against [`deadline::PLAN_BUDGET_CYCLES`].
#[inline(never)]
fn plan_job(
    planner: &mut PlanTask<f32, PATH_CAP>,
    est: &firmware::state_estimate::StateEstimate<f32>,
    friction_mu: f32,
    tyres_linear: bool,
) -> Result<firmware::mpc::MpcReport<f32>, firmware::mpc::MpcError> {
    planner.set_friction_limit(friction_mu);
    planner.set_tyres_linear(tyres_linear);
    planner.run(est)
}

/// The plan task's reception of the frames of the road announced since its last
/// activation: at most [`ROUTE_FRAMES`], verified and staged. True when the
/// staged window is complete: this activation adopts it ([`window_job`]) instead
/// of planning. Not inlined: the timing analysis bounds it alone; an activation
/// runs it, then one of the two jobs.
#[inline(never)]
fn route_job(route: &mut RouteLink, frames: u32, staging: &mut Staging) -> bool {
    route.receive(frames.min(ROUTE_FRAMES), staging);
    staging.ready.is_some()
}

/// The plan task's adoption of a window of the road, in place of [`plan_job`]:
/// the staged window ([`route_job`]) copied into the path's storage, the path
/// computed, the MPC's warm start moved, the obstacles' parabolas rebuilt
/// ([`PlanTask::adopt_window`]). False when the planner refused it (then without
/// a path); true when adopted or when no window was complete. Not inlined: the
/// timing analysis bounds it alone, against [`deadline::PLAN_BUDGET_CYCLES`]
/// with [`route_job`] before it.
#[inline(never)]
fn window_job(planner: &mut PlanTask<f32, PATH_CAP>, staging: &mut Staging) -> bool {
    staging.take_into(planner).is_none_or(|w| {
        planner
            .adopt_window(w.rows as usize, w.origin_m, w.closed)
            .is_ok()
    })
}

/// The plan swap, inside the `plan` lock: the critical section that blocks the
/// control task. Not inlined: the timing analysis bounds it alone. Publishes the
/// plan under the late-plan policy, its age judged at `now_us` (µs, taken just
/// before the lock: one clock read fewer in the critical section), and sets
/// `swapped_ticks` to the plan task's completion, the core clock tick count
/// ([`core_ticks`]) when the swap is done: nothing else runs under the lock, so
/// `control` first sees the plan just after (its conversion to µs, a 64-bit
/// division, is left outside). Returns whether the plan was published.
#[inline(never)]
fn publish_plan(
    planner: &mut PlanTask<f32, PATH_CAP>,
    shared: &mut firmware::plan::Plan<f32>,
    now_us: u64,
    swapped_ticks: &mut u64,
) -> bool {
    let published = planner.publish_at(shared, now_us);
    *swapped_ticks = core_ticks();
    published
}

/// The plan task's own core clock ticks since `t0`: the ticks elapsed less the
/// control task's since `c0` (its [`CONTROL_TICKS`] then).
fn own_ticks(t0: u64, c0: u32) -> u64 {
    let c1 = CONTROL_TICKS.load(Ordering::Relaxed);
    core_ticks()
        .saturating_sub(t0)
        .saturating_sub(c1.wrapping_sub(c0) as u64)
}

/// Adds the control task's ticks since `t0` (everything it did, the link's frames
/// included) to [`CONTROL_TICKS`], which the plan task subtracts from its own time.
fn add_control_ticks(t0: u64) {
    let whole = core_ticks().saturating_sub(t0).min(u32::MAX as u64) as u32;
    add_own(&CONTROL_TICKS, whole);
}

/// Adds `n` to a counter that one task alone writes (the others only read it): a
/// load and a store, with no load/store-exclusive retry loop, since no other
/// writer can come between them (a preempting reader sees the old or the new
/// value, both whole words).
fn add_own(counter: &AtomicU32, n: u32) {
    counter.store(
        counter.load(Ordering::Relaxed).wrapping_add(n),
        Ordering::Relaxed,
    );
}

/// An actuation frame: the actuation, its fault code and the activation's own
/// ticks; the caller fills in the instants and the counts.
fn actuation_frame(seq: u32, a: &Actuation<f32>, fault: u8, ticks: u32) -> ActuationFrame {
    ActuationFrame {
        seq,
        torque_nm: a.wheel_torque_nm,
        delta_rad: a.delta_rad,
        delta_ol_rad: a.delta_ol_rad,
        delta_cl_rad: a.delta_cl_rad,
        v_ref_mps: a.v_ref_mps,
        mode: link::mode_code(a.mode),
        fault,
        control_ticks: ticks,
        release_us: 0,
        sent_us: 0,
        previous_response_us: 0,
        control: link::TaskTimingFrame::default(),
        watchdog_trips: 0,
        sensor: 0,
        refused: RefusalCounts::new(),
        plan: None,
    }
}

/// The clock tree's registers on the device, through the PAC: volatile word
/// accesses at RM0090's addresses.
struct DeviceClockRegisters<'a> {
    rcc: &'a stm32f4::stm32f405::RCC,
    pwr: &'a stm32f4::stm32f405::PWR,
    flash: &'a stm32f4::stm32f405::FLASH,
}

impl ClockRegisters for DeviceClockRegisters<'_> {
    fn read(&mut self, register: Register) -> u32 {
        match register {
            Register::RccCr => self.rcc.cr.read().bits(),
            Register::RccPllcfgr => self.rcc.pllcfgr.read().bits(),
            Register::RccCfgr => self.rcc.cfgr.read().bits(),
            Register::RccApb1enr => self.rcc.apb1enr.read().bits(),
            Register::PwrCr => self.pwr.cr.read().bits(),
            Register::PwrCsr => self.pwr.csr.read().bits(),
            Register::FlashAcr => self.flash.acr.read().bits(),
        }
    }

    fn write(&mut self, register: Register, value: u32) {
        // Whole words: the sequence writes RM0090's fields and keeps every other
        // bit as it read it (the PAC's `bits` is unsafe for that reason).
        unsafe {
            match register {
                Register::RccCr => self.rcc.cr.write(|w| w.bits(value)),
                Register::RccPllcfgr => self.rcc.pllcfgr.write(|w| w.bits(value)),
                Register::RccCfgr => self.rcc.cfgr.write(|w| w.bits(value)),
                Register::RccApb1enr => self.rcc.apb1enr.write(|w| w.bits(value)),
                Register::PwrCr => self.pwr.cr.write(|w| w.bits(value)),
                Register::PwrCsr => self.pwr.csr.write(|w| w.bits(value)),
                Register::FlashAcr => self.flash.acr.write(|w| w.bits(value)),
            }
        }
    }
}

// The lock-step build dispatches its tasks on the USART1 and USART2 vectors
// (the timing analysis maps them so: host-sim/src/wcet/ecu_app.rs); the flashed
// build's link owns USART1's interrupt, so its dispatchers are the unused SPI1
// and SPI2 vectors.
#[cfg_attr(
    not(feature = "board-usart"),
    rtic::app(device = stm32f4::stm32f405, dispatchers = [USART1, USART2])
)]
#[cfg_attr(
    feature = "board-usart",
    rtic::app(device = stm32f4::stm32f405, dispatchers = [SPI1, SPI2])
)]
mod app {
    use super::*;
    use firmware::link::{PlanEventFrame, ReadyFrame};
    use firmware::mpc::MpcSettings;
    use firmware::plan::Plan;
    use firmware::setup::Setup;
    use firmware::state_estimate::StateEstimate;

    #[shared]
    struct Shared {
        /// The latest state estimate (written by `control`, read by `plan`).
        estimate: StateEstimate<f32>,
        /// The plan `control` follows (swapped in by `plan`); in a static, so init
        /// does not build it on its stack.
        plan: &'static mut Plan<f32>,
        /// The last plan activation's record, until `control` reports it; in a
        /// static, as `plan`.
        plan_event: &'static mut Option<PlanEventFrame>,
    }

    #[local]
    struct Local {
        /// The control task's state, in a static, so that init does not build
        /// it on its stack.
        control: &'static mut ControlTask<f32>,
        link: &'static mut Link,
        planner: &'static mut PlanTask<f32, PATH_CAP>,
        /// The route channel and the next window of the road being received
        /// (the plan task's; in statics, as `planner`).
        route: &'static mut RouteLink,
        staging: &'static mut Staging,
    }

    #[init(local = [
        planner_storage: PlanTask<f32, PATH_CAP> = PlanTask::new(MpcSettings::unset(), 0.0),
        plan_storage: Plan<f32> = Plan::zeroed(),
        staging_storage: Staging = Staging::new(),
        link_storage: Option<Link> = None,
        route_storage: Option<RouteLink> = None,
        clock_storage: Option<Result<ClockSource, ClockError>> = None,
        control_storage: Option<ControlTask<f32>> = None,
        plan_event_storage: Option<PlanEventFrame> = None,
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        paint_stack();
        // In a static: the result waits there, not in the frame the tasks first run
        // above, until the set-up answers with it.
        let clock = cx.local.clock_storage.insert(configure_clock(
            &cx.device.RCC,
            &cx.device.PWR,
            &cx.device.FLASH,
        ));
        release_clock::start(cx.core.SYST, TICKS_PER_MONO - 1);
        // The set-up's work runs in functions of their own, so their frames are gone
        // when `init` returns and the tasks it spawned run on this stack (RTIC
        // enables interrupts before `init`'s caller returns).
        #[cfg(not(feature = "board-usart"))]
        let (link, route) = open_link(cx.local.link_storage, cx.local.route_storage);
        #[cfg(feature = "board-usart")]
        let (link, route) = open_usart_link(
            cx.local.link_storage,
            cx.local.route_storage,
            &cx.device,
            clock.is_ok(),
        );
        let planner = cx.local.planner_storage;
        let control = set_up(link, planner, clock, cx.local.control_storage);
        // The set-up was polled; from here the USART's interrupt moves the bytes.
        #[cfg(feature = "board-usart")]
        {
            let mut nvic = cx.core.NVIC;
            let mut scb = cx.core.SCB;
            link.port.start(&mut nvic, &mut scb);
        }
        // The timeline starts at the beginning of the monotonic's next tick: the
        // first release of both tasks, which then run at a tick as every later
        // release does. The set-up ends anywhere within a tick: a timeline started
        // at the beginning of that tick would put the first release up to 1 ms
        // before the tasks first run, and the first actuation would be sent up to
        // 1 ms after its release (and act a plant step later in the loop).
        let start = release_clock::now_ticks().wrapping_add(1);
        START_MONO_TICKS.store(start, Ordering::Relaxed);
        let epoch = u64::from(start) * u64::from(TICKS_PER_MONO);
        EPOCH_TICKS.store(epoch as u32, Ordering::Relaxed);
        EPOCH_TICKS_HI.store((epoch >> 32) as u32, Ordering::Relaxed);
        let _ = control::spawn();
        let _ = plan::spawn();
        (
            Shared {
                estimate: StateEstimate::zeroed(),
                plan: cx.local.plan_storage,
                plan_event: cx.local.plan_event_storage,
            },
            Local {
                control,
                link,
                planner,
                route,
                staging: cx.local.staging_storage,
            },
        )
    }

    /// The clock tree from reset to 168 MHz from the crystal, the flash
    /// interface as the timing analysis models it included
    /// ([`clock_tree::configure`] on the device's registers). Not inlined: it
    /// runs before interrupts are enabled, and its frame is gone when the tasks
    /// first run.
    #[inline(never)]
    fn configure_clock(
        rcc: &stm32f4::stm32f405::RCC,
        pwr: &stm32f4::stm32f405::PWR,
        flash: &stm32f4::stm32f405::FLASH,
    ) -> Result<ClockSource, ClockError> {
        clock_tree::configure(&mut DeviceClockRegisters { rcc, pwr, flash })
    }

    /// Opens the link to the simulator into its storage (so `init`'s own frame
    /// holds no link), or stops the ECU saying why.
    #[inline(never)]
    #[cfg(not(feature = "board-usart"))]
    fn open_link(
        link: &'static mut Option<Link>,
        route: &'static mut Option<RouteLink>,
    ) -> (&'static mut Link, &'static mut RouteLink) {
        defmt::info!("ecu: waiting for the simulator on ecu.down / ecu.up / ecu.route");
        let Some((l, r)) = Link::open() else {
            defmt::error!(
                "ecu: no link: run it from `host-sim pil` (it creates ecu.down, ecu.up and ecu.route)"
            );
            exit(false)
        };
        let link = link.insert(l);
        PANIC_LINK.store(&raw mut *link, Ordering::Relaxed);
        (link, route.insert(r))
    }

    /// Opens the USART link ([`usart_link::open`]: USART1 at its baud rate for
    /// the clock the core runs on, `clock_ok` when the clock tree's set-up did
    /// not fail) into its storage (so `init`'s own frame holds no link). Polled
    /// until the set-up is done.
    #[inline(never)]
    #[cfg(feature = "board-usart")]
    fn open_usart_link(
        link: &'static mut Option<Link>,
        route: &'static mut Option<RouteLink>,
        device: &stm32f4::stm32f405::Peripherals,
        clock_ok: bool,
    ) -> (&'static mut Link, &'static mut RouteLink) {
        defmt::info!("ecu: waiting for the set-up on USART1");
        let Some((port, route_port)) =
            usart_link::open(&device.RCC, &device.GPIOA, &device.USART1, clock_ok)
        else {
            exit(false)
        };
        let (l, r) = Link::over(port, route_port);
        let link = link.insert(l);
        PANIC_LINK.store(&raw mut *link, Ordering::Relaxed);
        (link, route.insert(r))
    }

    /// The set-up from the simulator's frames (car, first window, obstacles), then
    /// `Ready`; stops the ECU on a refused set-up, and when the clock set-up
    /// (`clock`) failed (status [`link::SetupError::ClockFailed`], detail the
    /// [`ClockError`]'s code). The control task's state goes into `storage`, not
    /// through `init`'s frame, which is still on the stack when the tasks first
    /// run (RTIC enables interrupts at the end of the function `init` is inlined
    /// into).
    #[inline(never)]
    fn set_up(
        link: &mut Link,
        planner: &mut PlanTask<f32, PATH_CAP>,
        clock: &Result<ClockSource, ClockError>,
        storage: &'static mut Option<ControlTask<f32>>,
    ) -> &'static mut ControlTask<f32> {
        match *clock {
            Ok(ClockSource::Pll { hse_hz }) => defmt::info!(
                "ecu: clock: HSE {=u32} Hz -> PLL, {=u32} Hz",
                hse_hz,
                SYSCLK_HZ
            ),
            Ok(ClockSource::Fixed) => defmt::info!(
                "ecu: clock: no RCC (RCC_CR reads 0): the machine's fixed clock, taken as {=u32} Hz",
                SYSCLK_HZ
            ),
            // The code, not the name: the names would take static RAM (read-only
            // data is copied to SRAM); the host names the code from the Ready frame.
            Err(e) => defmt::error!(
                "ecu: clock set-up failed (ClockError code {=u16}): on the internal oscillator",
                e.code()
            ),
        }
        let mut setup = Setup::new();
        let mut reader = FrameReader::<MAX_DOWN_FRAME_BYTES>::new();
        let control = loop {
            match link.receive(&mut reader) {
                Ok(Down::Config(c)) => setup.config(&c, planner),
                Ok(Down::PathChunk(c)) => setup.path_chunk(&c, planner),
                Ok(Down::Obstacle(o)) => setup.obstacle(&o),
                Ok(Down::Start) if clock.is_err() => {
                    let detail = clock.err().map_or(0, ClockError::code);
                    link.send_polled(UpRef::Ready(&ReadyFrame {
                        status: link::SetupError::ClockFailed.code(),
                        detail,
                    }));
                    exit(false)
                }
                Ok(Down::Start) => match setup.finish(planner) {
                    Ok(control) => break control,
                    Err(f) => {
                        defmt::error!("ecu: set-up refused: {} ({})", f.error, f.detail);
                        link.send_polled(UpRef::Ready(&ReadyFrame {
                            status: f.error.code(),
                            detail: f.detail,
                        }));
                        exit(false)
                    }
                },
                Ok(_) => link.count_refused(None),
                // A set-up with a frame refused is incomplete: refused at once,
                // saying why (a forged frame: most likely another link key).
                Err(Some(reason)) => {
                    defmt::error!("ecu: set-up frame refused: {}", reason);
                    link.send_polled(UpRef::Ready(&ReadyFrame {
                        status: link::SetupError::FrameRefused.code(),
                        detail: u16::from(reason.code()),
                    }));
                    exit(false)
                }
                Err(None) => exit(false),
            }
        };
        defmt::info!("ecu: set-up done, {} path points", planner.path.len());
        link.send_polled(UpRef::Ready(&ReadyFrame {
            status: 0,
            detail: 0,
        }));
        storage.insert(control)
    }

    /// Between activations the core sleeps until the next interrupt (the
    /// monotonic's tick or a task's release).
    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// The 100 Hz control task: sensor frame in, [`ControlTask::run`], actuator
    /// frame out. Deadline: its 10 ms period. Releases that fall while it runs
    /// are skipped and counted; [`firmware::deadline::CONTROL_MISS_LIMIT`]
    /// consecutive misses latch the safe actuation (module docs).
    #[task(priority = 2, shared = [estimate, plan, plan_event], local = [control, link])]
    async fn control(mut cx: control::Context) {
        let mut monitor = DeadlineMonitor::control();
        let mut watchdog = PlanWatchdog::plan();
        // The previous activation's response time, µs: it completes after its frame
        // is written, so the next frame reports it (0 before the first).
        let mut previous_response_us: u32 = 0;
        loop {
            // WCET: a poll resumes in this loop, so the binary has a cycle with two entry
            // blocks (irreducible): the loop's head (the first poll) and the delay's
            // resumption. Its back edges are the edges into them from inside: a job
            // crosses two, its end into the head and the head into the delay, which
            // suspends (the job ended with `next_release(now)`, the first release not
            // yet past, and the response-time analysis keeps a job within its period, so
            // one job per poll). The first poll enters at the head and crosses one more,
            // the head into the delay of release 0, which is already due: 3.
            // wcet-bound: 3 per activation
            release_clock::wait_until(release_clock::Slot::Control, tick_at(monitor.release_us()))
                .await;
            let release_us = monitor.start();
            let t0 = core_ticks();
            // In the flashed build, the bytes the USART's interrupt received since
            // the last release are counted and a new period's receive budget given
            // together, then those bytes sorted (this task's frames, the plan
            // task's road), as the sensor frame is read.
            // A refused sensor frame is never acted on: the period runs on no
            // estimate (the dropout policy: both tasks refuse it, the control task
            // applies the safe actuation) and still answers, saying so. A run of
            // refused frames is a run of such periods: the car brakes to a stop
            // under the safe actuation, the plan task plans nothing (its watchdog
            // counts the plans missed), and the first accepted frame resumes
            // following; the link is stopped only when no whole frame arrives.
            let (seq, e, sensor) = match cx.local.link.receive_sensor() {
                Ok(f) => {
                    // A window of the road sent on the route channel: the plan task
                    // reads it.
                    let new = cx.local.link.newly_announced(f.route_frames);
                    if new > 0 {
                        ROUTE_PENDING.fetch_add(new, Ordering::Relaxed);
                    }
                    (f.seq, f.estimate, 0)
                }
                Err(LinkEnd::Refused { code, seq }) => {
                    (seq, StateEstimate::unavailable(release_us), code)
                }
                // No frame yet (the flashed build's link is not in lock-step with
                // the host): a dropout, as a refused frame.
                #[cfg(feature = "board-usart")]
                Err(LinkEnd::Missing { seq }) => (
                    seq,
                    StateEstimate::unavailable(release_us),
                    link::SENSOR_MISSING,
                ),
                Err(end) => stop(cx.local.link, end == LinkEnd::Stop),
            };
            // The task's own work: the PIL link's frame decoding and encoding stand
            // in for the vehicle's bus drivers and are measured apart.
            let t1 = core_ticks();
            cx.shared.estimate.lock(|s| *s = e);
            let control = &mut *cx.local.control;
            let act = cx.shared.plan.lock(|plan| control_job(control, &e, plan));
            let mut fault = link::fault_code(control.last_fault);
            watchdog.check(release_us, control.state().plans_seen);
            FRICTION_MU_BITS.store(control.friction_mu().to_bits(), Ordering::Relaxed);
            TYRES_LINEAR.store(control.tyres_linear(), Ordering::Relaxed);
            let ticks = core_ticks().saturating_sub(t1).min(u32::MAX as u64) as u32;
            // K consecutive misses (the previous activations' late completions and
            // skipped releases): zero torque, the steering held where it was.
            let held = f32::from_bits(LAST_DELTA_BITS.load(Ordering::Relaxed));
            let (act, stopped) = deadline::control_output(&monitor, act, held);
            if stopped {
                fault = link::FAULT_DEADLINE;
            } else {
                LAST_DELTA_BITS.store(act.delta_rad.to_bits(), Ordering::Relaxed);
            }
            let mut frame = actuation_frame(seq, &act, fault, ticks);
            frame.sensor = sensor;
            frame.refused = cx.local.link.refused.plus(route_refused());
            frame.release_us = release_us;
            frame.previous_response_us = previous_response_us;
            frame.control = monitor.counts().into();
            frame.watchdog_trips = watchdog.trips();
            frame.plan = cx.shared.plan_event.lock(|p| p.take());
            // Two instants (the host counts from the same two):
            // * sent: the frame carries the instant it is handed to the link, the
            //   last one it can carry: its encoding (the PIL's stand-in for a bus
            //   driver) cannot include an instant taken after it. The plant applies
            //   the actuation from then.
            // * completion: the frame has been written (a semihosting write takes no
            //   virtual time: the host has the bytes at this instant). The response
            //   time runs to here, so the link's encoding counts in it; the next
            //   frame reports it, with the counts that include it.
            frame.sent_us = now_us();
            cx.local.link.send(UpRef::Actuation(&frame));
            let end_us = now_us();
            let done = monitor.complete(end_us, u64::from(ticks));
            previous_response_us = done.response_us.min(u64::from(u32::MAX)) as u32;
            add_control_ticks(t0);
            // The activation ends with its completion. The next release not yet
            // past: the ones that fell during an overrun are skipped and counted,
            // not absorbed.
            monitor.next_release(end_us);
        }
    }

    /// The 10 Hz plan task: [`PlanTask::run`] on the estimate at its release, then
    /// the plan published by a swap, or a received window of the road adopted
    /// instead; then the frames of a window of the road, if one was sent.
    /// Deadline: its 100 ms period (see the deadline policy above).
    #[task(priority = 1, shared = [estimate, plan, plan_event], local = [planner, route, staging])]
    async fn plan(mut cx: plan::Context) {
        let mut monitor = DeadlineMonitor::plan();
        let mut activation: u32 = 0;
        loop {
            // WCET: as in `control`: two back edges per job, one more in the first poll.
            // wcet-bound: 3 per activation
            release_clock::wait_until(release_clock::Slot::Plan, tick_at(monitor.release_us()))
                .await;
            activation = activation.wrapping_add(1);
            let release_us = monitor.start();
            // A new plan period's receive budget (a route frame's bytes).
            #[cfg(feature = "board-usart")]
            usart_link::rearm_route_receive();
            let planner = &mut *cx.local.planner;
            // The frames of the road announced since the last activation (by the
            // control task's sensor frames: at a common release it runs first). At
            // most ROUTE_FRAMES per activation; the rest wait for the next. The
            // control task adds to the count: the frames taken are subtracted,
            // not the count cleared.
            let frames = ROUTE_PENDING.load(Ordering::Relaxed).min(ROUTE_FRAMES);
            ROUTE_PENDING.fetch_sub(frames, Ordering::Relaxed);
            let t0 = core_ticks();
            let c0 = CONTROL_TICKS.load(Ordering::Relaxed);
            // The frame of the road first; when it completes a window, the
            // activation adopts it instead of planning (the control task follows
            // the last plan meanwhile): an activation adopts or plans, never both,
            // on two branches of one test. The two calls share one count (a flow
            // fact the traces check), so the task's static bound takes the larger
            // job, whatever shape the compiler gives the loop: the job ends with
            // `next_release(now)`, a release not yet past, and the response-time
            // analysis keeps a job within its period.
            let complete = frames > 0 && route_job(cx.local.route, frames, cx.local.staging);
            let mut event = if complete {
                // wcet-bound: 1 times per activation, counted in plan_jobs
                if !window_job(planner, cx.local.staging) {
                    // Counted with the refused route frames (the Done frame's
                    // `rejected_frames`); no logging in a task.
                    add_own(&ROUTE_REJECTED, 1);
                }
                let finish_us = now_us();
                let own = own_ticks(t0, c0);
                monitor.complete(finish_us, own);
                let ticks = own.clamp(1, u32::MAX as u64) as u32;
                PlanEventFrame::window(activation, release_us, finish_us, ticks)
            } else {
                let est = cx.shared.estimate.lock(|e| *e);
                let friction_mu = f32::from_bits(FRICTION_MU_BITS.load(Ordering::Relaxed));
                let tyres_linear = TYRES_LINEAR.load(Ordering::Relaxed);
                // wcet-bound: 1 times per activation, counted in plan_jobs
                let result = plan_job(planner, &est, friction_mu, tyres_linear);
                // The record's copy of the plan, taken before the swap, outside the lock.
                let computed = planner.pending().copied();
                // The late-plan policy judges the plan's age now; the completion is
                // the plan published, stamped under the lock.
                let now = now_us();
                let mut swapped_ticks = 0;
                let published = cx
                    .shared
                    .plan
                    .lock(|p| publish_plan(planner, p, now, &mut swapped_ticks));
                let finish_us = timeline_us(swapped_ticks);
                let own = own_ticks(t0, c0);
                monitor.complete(finish_us, own);
                PlanEventFrame::new(
                    activation,
                    release_us,
                    finish_us,
                    own.min(u32::MAX as u64) as u32,
                    &result,
                    planner.last_report(),
                    published,
                    0,
                    computed.as_ref(),
                )
            };
            // The next release: the next multiple of 100 ms not yet past (releases
            // that fell while this one ran are skipped, not queued, and counted).
            let end_us = now_us();
            monitor.next_release(end_us);
            event.end_us = end_us;
            event.timing = monitor.counts().into();
            cx.shared.plan_event.lock(|p| **p = Some(event));
        }
    }
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    // Interrupts off first, in a frame of a few bytes: no interrupt preempts the
    // handler's work below (only NMI and HardFault can), so the stack bound counts
    // its chain (`safe_stop_work`'s) once, not at every priority level.
    cortex_m::interrupt::disable();
    safe_stop(link::FAULT_PANIC)
}

/// HardFault, and the configurable faults escalated to it: MemManage, BusFault
/// and UsageFault are not enabled in SCB SHCSR, so the core raises HardFault for
/// them (a stack overflow into flip-link's guard, an invalid instruction, a bus
/// error). Safe actuators, a fault frame, stop. Without cortex-m-rt's trampoline
/// (which only passes the exception frame, unused here): the vector points at
/// this function, one frame fewer under the stack bound's HardFault level.
#[cortex_m_rt::exception(trampoline = false)]
unsafe fn HardFault() -> ! {
    cortex_m::interrupt::disable();
    safe_stop(link::FAULT_HARDFAULT)
}

/// NMI: on the STM32F405 the clock security system raises it when the crystal
/// (HSE) fails, after the hardware switched the core to its internal oscillator
/// (16 MHz: every timing is off by a factor 10.5). Safe actuators, a fault frame,
/// stop, as HardFault. It runs at priority −2, so nothing preempts it and there
/// are no interrupts to disable.
///
/// Defined by its symbol, the one cortex-m-rt's vector table names (its linker
/// script makes `NonMaskableInt` the default handler only where the program
/// defines none): `#[exception]` would put a trampoline frame below this one,
/// 8 bytes more under the stack bound's NMI level, which it cannot spare.
///
/// # Safety
///
/// Only the hardware calls it, through the vector table. It touches no data a
/// critical section protects (atomics and the semihosting up-link only), so it
/// may preempt one.
#[no_mangle]
pub unsafe extern "C" fn NonMaskableInt() -> ! {
    safe_stop(link::FAULT_NMI)
}

/// Safe actuators after a panic or a fault (`fault`: [`link::FAULT_PANIC`],
/// [`link::FAULT_HARDFAULT`] or [`link::FAULT_NMI`]), interrupts disabled or
/// from the NMI; the entry the three handlers call.
/// The static guard comes first, in a frame of a few bytes: a second entry (a
/// fault on the path below) exits at once, so [`safe_stop_work`] runs at most once
/// and its frame is on the stack at most once. The stack bound relies on that: it
/// counts the work's chain once, whether a panic or a HardFault entered it, and
/// HardFault (taken at any depth, even during the work) with only this guard.
#[inline(never)]
fn safe_stop(fault: u8) -> ! {
    // WCET: an exclusive store (the swap's LDREX/STREX retry) fails only if an exception
    // is taken between the two; the panic and HardFault handlers disable interrupts first,
    // nothing preempts the NMI handler, and the exceptions that still can (NMI, HardFault)
    // do not return here: no retry.
    // wcet-bound: 1
    if STOPPING.swap(true, Ordering::Relaxed) {
        exit(false)
    }
    safe_stop_work(fault)
}

/// The safe stop's work, reached only through [`safe_stop`]'s guard: zero torque
/// on every wheel, the steering held where it was, sent as an actuator frame
/// (authenticated on the up stream, as every frame); a fixed line on the
/// semihosting stderr; then the ECU stops. It neither formats nor panics. Not
/// inlined: its frame is allocated only past the guard.
///
/// The frame goes through the control task's [`Link`] ([`PANIC_LINK`]): its
/// CMAC and the up stream's next freshness value (a second engine would cost
/// its key schedule in RAM). The control task may hold the link, interrupted
/// (a panic inside it, or a fault at any point): this path never returns and
/// ends the ECU, so that borrow is never used again, and [`Link::send`] starts
/// its tag afresh, whatever an interrupted one left.
#[inline(never)]
fn safe_stop_work(fault: u8) -> ! {
    let delta = f32::from_bits(LAST_DELTA_BITS.load(Ordering::Relaxed));
    let link = PANIC_LINK.load(Ordering::Relaxed);
    // SAFETY: non-null only once `open_link` stored the link, in a static that
    // lives for the rest of the run; interrupts are disabled and this path ends
    // the ECU (above), so this is the only use of the link from here on.
    if let Some(link) = unsafe { link.as_mut() } {
        let a = Actuation::safe(delta, 0.0);
        let frame = actuation_frame(u32::MAX, &a, fault, 0);
        // The USART polled from here: the frame in flight sent whole first, then
        // this one, every wait bounded (no interrupt, no semihosting).
        link.take_over();
        link.send_polled(UpRef::Actuation(&frame));
    }
    #[cfg(not(feature = "board-usart"))]
    {
        let err = ERR_FD.load(Ordering::Relaxed);
        if err != 0 {
            let line: &[u8] = match fault {
                link::FAULT_HARDFAULT => b"ecu: HardFault: safe stop\n",
                link::FAULT_NMI => b"ecu: NMI (clock security): safe stop\n",
                _ => b"ecu: panic: safe stop\n",
            };
            sh_write(err, line);
        }
    }
    exit(false)
}
