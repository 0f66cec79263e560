//! The ECU application (RTIC v2, Cortex-M4F): binds the library's two tasks to
//! priorities and the monotonic timer, and talks to the simulator.
//!
//! | task | priority | released | does |
//! |---|---|---|---|
//! | `control` | 2 (high) | every 10 ms by the monotonic | reads the sensor frame, [`ControlTask::run`] on the shared plan, sends the actuator frame |
//! | `plan` | 1 (low) | every 100 ms by the monotonic | [`PlanTask::run`] outside any lock, then [`PlanTask::publish`] (a buffer swap) inside a short lock on the shared plan |
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
//! **Link.** In the processor-in-the-loop run (`host-sim pil`) the simulator
//! starts QEMU in a folder holding two FIFOs, `ecu.down` (host → ECU) and
//! `ecu.up` (ECU → host), which the ECU opens through semihosting. Semihosting
//! calls are synchronous: QEMU's virtual clock (`-icount`) does not advance while
//! the host answers, so the run is deterministic. On a vehicle these frames would
//! come from the sensor fusion and go to the actuators over CAN; the frames
//! ([`firmware::link`]) are the same.
//!
//! **Panic**: the handler commands zero torque with the steering held, sends it as
//! an actuator frame and stops.
//!
//! Build: `cargo ecu`; run in the loop with the simulator: `host-sim pil`.
#![no_std]
#![no_main]
// Semihosting calls, painting the stack and the panic handler's actuator frame.
#![allow(unsafe_code)]

use core::sync::atomic::{AtomicU32, AtomicUsize, Ordering};

use cortex_m_semihosting::{debug, syscall};
use defmt_semihosting as _;
use firmware::link::{self, ActuationFrame, Down, FrameReader, Up, MAX_FRAME_BYTES};
use firmware::low_level::Actuation;
use firmware::tasks::{ControlTask, PlanTask};
use rtic_monotonics::systick::prelude::*;

/// Rows of the window of the road the ECU holds (not the whole circuit: its RAM
/// does not grow with the track; the simulator sends the next window as the car
/// moves on).
pub const PATH_CAP: usize = 320;
/// Core clock, Hz (STM32F405 at 168 MHz; QEMU's SysTick counts at this rate of
/// virtual time).
pub const SYSCLK_HZ: u32 = 168_000_000;
/// Monotonic tick rate, Hz (1 ms ticks).
const MONO_HZ: u32 = 1_000;
/// SysTick reload: core clock ticks per monotonic tick.
const TICKS_PER_MONO: u32 = SYSCLK_HZ / MONO_HZ;

systick_monotonic!(Mono, MONO_HZ);

/// Host file descriptor of the up-link (0: not open), for the panic handler.
static UP_FD: AtomicUsize = AtomicUsize::new(0);
/// Last steering command, `f32` bits (the panic handler holds it).
static LAST_DELTA_BITS: AtomicU32 = AtomicU32::new(0);
/// The control task's friction estimate `μ̂` (`firmware::friction`), `f32` bits,
/// written by `control` each period and read by `plan` with the estimate at its
/// release (a word: no lock; 0 before the first period, which `plan` takes as no
/// estimate).
static FRICTION_MU_BITS: AtomicU32 = AtomicU32::new(0);
/// Core clock ticks spent in `control` so far, link included (the plan task
/// subtracts them from its elapsed time).
static CONTROL_TICKS: AtomicU32 = AtomicU32::new(0);
/// Core clock tick count at the start of the timeline (t = 0).
static EPOCH_TICKS: AtomicU32 = AtomicU32::new(0);
/// High bits of the epoch (the 64-bit tick count's upper half).
static EPOCH_TICKS_HI: AtomicU32 = AtomicU32::new(0);

/// Core clock ticks since the monotonic started (168 MHz; 64 bits never wrap).
fn core_ticks() -> u64 {
    loop {
        let a = Mono::now().ticks();
        let cvr = cortex_m::peripheral::SYST::get_current();
        let b = Mono::now().ticks();
        if a == b {
            let within = (TICKS_PER_MONO - 1).saturating_sub(cvr);
            return a as u64 * TICKS_PER_MONO as u64 + within as u64;
        }
    }
}

fn epoch_ticks() -> u64 {
    ((EPOCH_TICKS_HI.load(Ordering::Relaxed) as u64) << 32)
        | EPOCH_TICKS.load(Ordering::Relaxed) as u64
}

defmt::timestamp!("{=u64:us}", now_us());

/// µs since the timeline's start.
fn now_us() -> u64 {
    core_ticks().saturating_sub(epoch_ticks()) * 1_000_000 / SYSCLK_HZ as u64
}

/// The two FIFOs to the simulator, through semihosting.
pub struct Link {
    down: usize,
    up: usize,
    reader: FrameReader<MAX_FRAME_BYTES>,
    rx: [u8; 64],
    rx_len: usize,
    rx_pos: usize,
    /// Frames refused (garbled, short, wrong version, unexpected).
    pub rejected: u32,
}

fn sh_open(name: &[u8], mode: usize) -> Option<usize> {
    // `name` ends with a NUL; the length excludes it.
    let fd = unsafe { syscall!(OPEN, name.as_ptr(), mode, name.len() - 1) };
    if fd as isize == -1 {
        None
    } else {
        Some(fd)
    }
}

fn sh_write(fd: usize, mut bytes: &[u8]) -> bool {
    while !bytes.is_empty() {
        let left = unsafe { syscall!(WRITE, fd, bytes.as_ptr(), bytes.len()) };
        if left >= bytes.len() {
            return false;
        }
        bytes = &bytes[bytes.len() - left..];
    }
    true
}

impl Link {
    /// Opens `ecu.down` for reading and `ecu.up` for writing, in that order (the
    /// simulator opens them in the same order).
    pub fn open() -> Option<Self> {
        const R_BINARY: usize = 1;
        const W_TRUNC_BINARY: usize = 5;
        let down = sh_open(b"ecu.down\0", R_BINARY)?;
        let up = sh_open(b"ecu.up\0", W_TRUNC_BINARY)?;
        UP_FD.store(up, Ordering::Relaxed);
        Some(Self {
            down,
            up,
            reader: FrameReader::new(),
            rx: [0; 64],
            rx_len: 0,
            rx_pos: 0,
            rejected: 0,
        })
    }

    /// The next well-formed host frame (refused frames are counted and skipped);
    /// `None` when the host closed the link.
    pub fn receive(&mut self) -> Option<Down> {
        loop {
            if self.rx_pos == self.rx_len {
                let n = self.rx.len();
                let left = unsafe { syscall!(READ, self.down, self.rx.as_mut_ptr(), n) };
                if left >= n {
                    return None; // end of file: the host is gone
                }
                self.rx_len = n - left;
                self.rx_pos = 0;
            }
            let byte = self.rx[self.rx_pos];
            self.rx_pos += 1;
            match self.reader.push(byte) {
                None => {}
                Some(Ok(frame)) => match link::decode::<Down>(frame) {
                    Ok(msg) => return Some(msg),
                    Err(_) => self.rejected = self.rejected.wrapping_add(1),
                },
                Some(Err(_)) => self.rejected = self.rejected.wrapping_add(1),
            }
        }
    }

    /// Sends one frame to the host. Not inlined: its frame buffer then lives on the
    /// stack only while a frame is sent, not for the whole of the caller's activation.
    #[inline(never)]
    pub fn send(&mut self, msg: &Up) -> bool {
        let mut buf = [0u8; MAX_FRAME_BYTES];
        match link::encode(msg, &mut buf) {
            Ok(n) => sh_write(self.up, &buf[..n]),
            Err(_) => false,
        }
    }
}

/// Ends the QEMU run.
fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::wfi();
    }
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
    while p < top && unsafe { core::ptr::read_volatile(p as *const u32) } == PAINT {
        p += 4;
    }
    ((top - p) as u32, (top - bottom) as u32)
}

/// The next window of the road, received by `control` row by row.
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
        for (i, r) in self.rows.iter().take(w.rows as usize).enumerate() {
            planner.path.stage_row(i, *r);
        }
        self.received = 0;
        Some(w)
    }
}

/// Adds the control task's ticks since `t0` (everything it did, the link's frames
/// included) to [`CONTROL_TICKS`], which the plan task subtracts from its own time.
fn add_control_ticks(t0: u64) {
    let whole = core_ticks().saturating_sub(t0).min(u32::MAX as u64) as u32;
    CONTROL_TICKS.fetch_add(whole, Ordering::Relaxed);
}

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
        plan: None,
    }
}

#[rtic::app(device = stm32f4::stm32f405, dispatchers = [USART1, USART2])]
mod app {
    use super::*;
    use firmware::link::{DoneFrame, PlanEventFrame, ReadyFrame};
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
        /// The last plan activation's record, until `control` reports it.
        plan_event: Option<PlanEventFrame>,
        /// The next window of the road, as `control` receives it; `plan` adopts it
        /// (in a static, as `plan`).
        staging: &'static mut Staging,
    }

    #[local]
    struct Local {
        control: ControlTask<f32>,
        link: &'static mut Link,
        planner: &'static mut PlanTask<f32, PATH_CAP>,
    }

    #[init(local = [
        planner_storage: PlanTask<f32, PATH_CAP> = PlanTask::new(MpcSettings::unset(), 0.0),
        plan_storage: Plan<f32> = Plan::zeroed(),
        staging_storage: Staging = Staging::new(),
        link_storage: Option<Link> = None,
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        paint_stack();
        Mono::start(cx.core.SYST, SYSCLK_HZ);
        // The set-up's work runs in functions of their own, so their frames are gone
        // when `init` returns and the tasks it spawned run on this stack (RTIC
        // enables interrupts before `init`'s caller returns).
        let link = cx.local.link_storage.insert(open_link());
        let planner = cx.local.planner_storage;
        let control = set_up(link, planner);
        let epoch = core_ticks();
        EPOCH_TICKS.store(epoch as u32, Ordering::Relaxed);
        EPOCH_TICKS_HI.store((epoch >> 32) as u32, Ordering::Relaxed);
        let _ = control::spawn();
        let _ = plan::spawn();
        (
            Shared {
                estimate: StateEstimate::zeroed(),
                plan: cx.local.plan_storage,
                plan_event: None,
                staging: cx.local.staging_storage,
            },
            Local {
                control,
                link,
                planner,
            },
        )
    }

    /// Opens the link to the simulator, or stops the ECU saying why.
    #[inline(never)]
    fn open_link() -> Link {
        defmt::info!("ecu: waiting for the simulator on ecu.down / ecu.up");
        let Some(link) = Link::open() else {
            defmt::error!(
                "ecu: no link: run it from `host-sim pil` (it creates ecu.down and ecu.up)"
            );
            exit(false)
        };
        link
    }

    /// The set-up from the simulator's frames (car, first window, obstacles), then
    /// `Ready`; stops the ECU on a refused set-up.
    #[inline(never)]
    fn set_up(link: &mut Link, planner: &mut PlanTask<f32, PATH_CAP>) -> ControlTask<f32> {
        let mut setup = Setup::new();
        let control = loop {
            match link.receive() {
                Some(Down::Config(c)) => setup.config(&c, planner),
                Some(Down::PathChunk(c)) => setup.path_chunk(&c, planner),
                Some(Down::Obstacle(o)) => setup.obstacle(&o),
                Some(Down::Start) => match setup.finish(planner) {
                    Ok(control) => break control,
                    Err(f) => {
                        defmt::error!("ecu: set-up refused: {} ({})", f.error.name(), f.detail);
                        link.send(&Up::Ready(ReadyFrame {
                            status: f.error.code(),
                            detail: f.detail,
                        }));
                        exit(false)
                    }
                },
                Some(_) => link.rejected = link.rejected.wrapping_add(1),
                None => exit(false),
            }
        };
        defmt::info!("ecu: set-up done, {} path points", planner.path.len());
        link.send(&Up::Ready(ReadyFrame {
            status: 0,
            detail: 0,
        }));
        control
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
    /// frame out. Deadline: its 10 ms period.
    #[task(priority = 2, shared = [estimate, plan, plan_event, staging], local = [control, link])]
    async fn control(mut cx: control::Context) {
        let mut release = Mono::now();
        loop {
            let t0 = core_ticks();
            let msg = cx.local.link.receive();
            let est = match msg {
                Some(Down::Sensor(f)) => f,
                Some(Down::Stop) | None => {
                    let (used, size) = stack_high_water();
                    defmt::info!("ecu: stop; stack high-water {} of {} bytes", used, size);
                    let rejected = cx.local.link.rejected;
                    cx.local.link.send(&Up::Done(DoneFrame {
                        stack_high_water_bytes: used,
                        stack_size_bytes: size,
                        rejected_frames: rejected,
                    }));
                    exit(msg.is_some())
                }
                Some(Down::PathChunk(c)) => {
                    // The next window's rows (a short copy under the staging lock).
                    let ok = cx.shared.staging.lock(|st| st.chunk(&c));
                    if !ok {
                        cx.local.link.rejected = cx.local.link.rejected.wrapping_add(1);
                    }
                    // Receiving is this task's time, not the preempted plan's.
                    add_control_ticks(t0);
                    continue;
                }
                Some(Down::Window(w)) => {
                    cx.shared.staging.lock(|st| st.complete(&w));
                    add_control_ticks(t0);
                    continue;
                }
                Some(_) => {
                    cx.local.link.rejected = cx.local.link.rejected.wrapping_add(1);
                    continue;
                }
            };
            // The task's own work: the PIL link's frame decoding and encoding stand
            // in for the vehicle's bus drivers and are measured apart.
            let t1 = core_ticks();
            let e = est.estimate;
            cx.shared.estimate.lock(|s| *s = e);
            let control = &mut *cx.local.control;
            let act = cx
                .shared
                .plan
                .lock(|plan| control.run(&e, plan, e.stamp_us));
            let fault = link::fault_code(control.last_fault);
            LAST_DELTA_BITS.store(act.delta_rad.to_bits(), Ordering::Relaxed);
            FRICTION_MU_BITS.store(control.friction_mu().to_bits(), Ordering::Relaxed);
            let ticks = core_ticks().saturating_sub(t1).min(u32::MAX as u64) as u32;
            let mut frame = actuation_frame(est.seq, &act, fault, ticks);
            frame.plan = cx.shared.plan_event.lock(|p| p.take());
            cx.local.link.send(&Up::Actuation(frame));
            add_control_ticks(t0);
            release += 10.millis();
            Mono::delay_until(release).await;
        }
    }

    /// The 10 Hz plan task: [`PlanTask::run`] on the estimate at its release, then
    /// the plan published by a swap. Deadline: its 100 ms period (see the
    /// deadline policy above).
    #[task(priority = 1, shared = [estimate, plan, plan_event, staging], local = [planner])]
    async fn plan(mut cx: plan::Context) {
        let start = Mono::now();
        let mut activation: u32 = 0;
        let mut k: u32 = 0; // release index: t = k · 100 ms
        loop {
            Mono::delay_until(start + (k * 100).millis()).await;
            activation = activation.wrapping_add(1);
            let release_us = k as u64 * 100_000;
            let est = cx.shared.estimate.lock(|e| *e);
            let friction_mu = f32::from_bits(FRICTION_MU_BITS.load(Ordering::Relaxed));
            let t0 = core_ticks();
            let c0 = CONTROL_TICKS.load(Ordering::Relaxed);
            let planner = &mut *cx.local.planner;
            planner.set_friction_limit(friction_mu);
            let result = planner.run(&est);
            // The record's copy of the plan, taken before the swap, outside the lock.
            let computed = planner.pending().copied();
            let finish_us = now_us();
            let published = cx.shared.plan.lock(|p| planner.publish_at(p, finish_us));
            let c1 = CONTROL_TICKS.load(Ordering::Relaxed);
            let t1 = core_ticks();
            let own = t1
                .saturating_sub(t0)
                .saturating_sub(c1.wrapping_sub(c0) as u64);
            // After publishing, in the slack before the next release: a complete new
            // window of the road, its rows copied into the path's storage under the
            // lock, the path computed outside it (the next activation plans on it).
            let window = cx.shared.staging.lock(|st| st.take_into(planner));
            if let Some(w) = window {
                if planner
                    .adopt_window(w.rows as usize, w.origin_m, w.closed)
                    .is_err()
                {
                    defmt::error!("ecu: window refused");
                }
            }
            let c2 = CONTROL_TICKS.load(Ordering::Relaxed);
            let window_ticks = match window {
                Some(_) => core_ticks()
                    .saturating_sub(t1)
                    .saturating_sub(c2.wrapping_sub(c1) as u64)
                    .clamp(1, u32::MAX as u64) as u32,
                None => 0,
            };
            let event = PlanEventFrame::new(
                activation,
                release_us,
                finish_us,
                own.min(u32::MAX as u64) as u32,
                &result,
                planner.last_report(),
                published,
                window_ticks,
                computed.as_ref(),
            );
            cx.shared.plan_event.lock(|p| *p = Some(event));
            // The next release: the next multiple of 100 ms not yet past (releases
            // that fell while this one ran are skipped, not queued).
            let end_us = now_us();
            k += 1;
            while (k as u64) * 100_000 < end_us {
                k += 1;
            }
        }
    }
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    // Interrupts off first, in a frame of a few bytes: nothing preempts the
    // handler's work below (the stack bound counts `safe_stop`'s chain once, not
    // at every priority level).
    cortex_m::interrupt::disable();
    safe_stop()
}

/// Safe actuators after a panic, interrupts disabled: zero torque on every wheel,
/// the steering held where it was; then the ECU stops.
#[inline(never)]
fn safe_stop() -> ! {
    let delta = f32::from_bits(LAST_DELTA_BITS.load(Ordering::Relaxed));
    let fd = UP_FD.load(Ordering::Relaxed);
    if fd != 0 {
        let a = Actuation::safe(delta, 0.0);
        let mut frame = actuation_frame(u32::MAX, &a, link::FAULT_PANIC, 0);
        frame.plan = None;
        let mut buf = [0u8; MAX_FRAME_BYTES];
        if let Ok(n) = link::encode(&Up::Actuation(frame), &mut buf) {
            sh_write(fd, &buf[..n]);
        }
    }
    defmt::error!("ecu: panic: zero torque, steering held");
    exit(false)
}
