//! The real-time hardware in the loop over the emulated USART (`host-sim pil
//! --link usart`): the binary you flash (`cargo ecu`) in QEMU with its
//! USART1 on QEMU's stdio character device, piped to this process, and the plant
//! stepped on the host's clock, as on a bench. Not lock-step: the lock-step PIL
//! over the semihosting build ([`super::qemu`]) stays the deterministic check.
//!
//! # Time
//!
//! Three clocks:
//!
//! * **The host's** ([`std::time::Instant`]): the simulation is paced to it, one
//!   10 ms control period of simulated time per 10 ms of wall time; the plant is
//!   stepped on it.
//! * **QEMU's virtual clock (the ECU's SysTick).** With [`HilClock::Host`] (the
//!   default) QEMU runs without `-icount`: its virtual clock *is* the host's
//!   monotonic clock, and an instruction takes whatever the host takes to
//!   emulate it (the ECU's response times and its budget counts are then the
//!   emulator's, not an STM32F405's). With [`HilClock::Icount`] QEMU runs with
//!   `-icount shift=N,align=on,sleep=on` (QEMU 7.2 accepts it; `align` works
//!   with a fixed shift only and not with `sleep=off`): an instruction takes
//!   `2^N` ns of virtual time as in the lock-step PIL, `sleep=on` lets the
//!   virtual clock follow the host's while the ECU sleeps, `align=on` holds it
//!   back when it runs more than 3 ms ahead of the host's. Either way the ECU's
//!   clock *loses* time against the host's when QEMU is late: its timeline is
//!   its count of SysTick interrupts (one a control period), and ticks that fall due while QEMU's
//!   vCPU is not running seem to be delivered as one (a pending interrupt is
//!   pended once, however many times it falls due). On
//!   a loaded two-core machine (builds beside it, load average 3–4) we
//!   measured 9–15 % of the host's time lost without `-icount` (20 s runs, full
//!   laps) and about 24 % with it (a 30 s run); the default is the host's
//!   clock. We have not measured an idle host. The loss is reported
//!   (`clock_offset_drift_us`), never corrected on the ECU.
//! * **The ECU's timeline** (µs since its first release, right after `Ready`):
//!   its releases are the multiples of 10 ms (control) and 100 ms (plan) on it,
//!   and every actuation frame carries its release and send instants on it.
//!
//! The host does not know the phase of the ECU's releases: it estimates the
//! offset `host − ECU` as the smallest `arrival − sent_us` over the last
//! [`OFFSET_WINDOW`] actuation frames (a frame's transfer time is never
//! negative; its smallest value is the link's latency), first over
//! [`WARMUP_PERIODS`] dropout answers before the run (the ECU answers every
//! release, a sensor frame or not). The run's time 0 is placed `--hil-lead-us`
//! ([`DEFAULT_LEAD_US`], 8 ms) before an ECU plan release: each period's sample
//! is sent at the period's start on the host's clock, that long ahead of the
//! ECU's release while the two clocks agree. The lead is most of a period
//! because QEMU's USART moves one byte per pass of its main loop, and the next
//! only once the ECU has read the last: a sensor frame took up to 5 ms to
//! cross on a loaded host, and one that is not whole at the release is a
//! dropout. Each sensor frame is stamped with its sample's instant: the ECU's clock
//! at the run's start plus the host's time since. The control task follows its
//! plans at the estimates' stamps, and the MPC's nodes are physical time: a
//! stamp on the ECU's own (losing) clock made the plans run slow against the
//! plant (a 15 % slower reference through the obstacles). So the stamps run
//! ahead of the ECU's clock by what it lost; the plan task's age check
//! (`MAX_PLAN_AGE_US`, on the ECU's clock) then finds plans younger than they
//! are, never older.
//!
//! At most one sensor frame waits at the ECU: a period sends its sample once
//! the last one has been answered (the ECU's USART queue holds two frames; a
//! backlog would overflow it and make every later frame older). When the ECU's
//! clock has fallen behind, that answer comes after the period's start, and
//! the sample is sent as soon as it comes (still most of a period ahead of the
//! ECU's next release); a period in which it does not come at all (no ECU
//! release in it) sends none (`periods_not_fed`). A frame that was not whole
//! at a release waits for the next one, and that release answers as a dropout
//! (`sensor_missing_at_ecu`).
//!
//! # The loop
//!
//! The closed loop's driver ([`crate::closed_loop::timeline::run_with`]) is
//! reused as it is: [`UsartEcu`] is an [`Ecu`] whose [`Ecu::control`] at `t`
//! waits for the wall-clock instant of `t`, sends the sensor frame, and waits for
//! the ECU's answer to it until the end of the period on the host's clock (less
//! [`GUARD_US`], in which the driver steps the plant 10 ms ahead: microseconds
//! of wall time). A reader thread receives the ECU's frames as they come and
//! stamps their arrival. The actuation received acts from its arrival (the
//! driver applies it from the plant step containing that instant); when no
//! frame arrived in a period the last one is held. Every actuation frame the
//! ECU sends is applied, dropout answers (`sensor == SENSOR_MISSING`: no whole
//! sensor frame at the release) and answers that arrive after their period
//! included; when two arrive in one period the later one acts from its arrival
//! and the earlier one only until then. Route frames (the next window of the
//! road) go on the route channel's stream of the same USART (the ECU's
//! interrupt sorts them), each right before a sensor frame, which announces it,
//! and the next only once the ECU's plan task has read the last (a plan event
//! released at or after the control release that accepted the announcement:
//! its queue holds one frame, and its activations, on the ECU's clock, are
//! fewer than the host's plan periods when that clock falls behind).
//!
//! # What is counted
//!
//! The ECU counts its own deadline misses, skipped releases, budget overruns and
//! refused frames, and sends them in every actuation frame (the summary's `ecu_*`
//! fields, as in lock-step). The host recounts the misses from the ECU's stamps
//! (the summary's `control_deadline_misses`, `plan_deadline_misses`, ...), but
//! does not fail on a difference: in real time the ECU's frames before the run
//! and after its end count on the ECU only. The [`HilSummary`] in `summary.json`
//! adds the frames sent and received, the dropout answers, and the spread of the
//! ECU's control and plan response times, of the host's round trip sensor frame
//! → actuation frame and of the lead. Instructions are not measured: a control
//! or plan activation's cycles are its ECU clock ticks (168 MHz), its
//! instructions those over the CPI bound.

use std::collections::{BTreeMap, VecDeque};
use std::fs::{self, File};
use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use firmware::link::{
    self, ActuationFrame, Authenticator, ConfigFrame, DoneFrame, Down, FrameError, FrameReader,
    LinkKey, LinkMac, ObstacleFrame, PlanEventFrame, RefusalCounts, SensorFrame, Stream, Up,
    Verifier, MAX_FRAME_BYTES,
};
use firmware::low_level::Actuation;
use firmware::obstacles::MAX_VERTICES;
use firmware::plan::Plan;
use firmware::state_estimate::StateEstimate;
use firmware::tasks::{CONTROL_PERIOD_US, PLAN_PERIOD_US};

use crate::closed_loop::ecu::{ControlOutput, Ecu, EcuCounts, EcuTaskCounts, SimulatedEcu};
use crate::closed_loop::plan_activation::{plan_status_name, PlanActivation};
use crate::closed_loop::summary::{HilSummary, Spread};
use crate::closed_loop::SimOptions;
use crate::model::vehicle::VehicleParams;
use crate::pil::deadlines::skipped_between;
use crate::pil::frames::{actuation_of, path_chunks, plan_of, setup_refusal};
use crate::world::route::{RouteFeeder, Window};
use crate::world::scenario::Scenario;

/// How far ahead of the ECU's release the run's first sensor frame is sent, µs.
/// QEMU's USART takes a byte from its character device per pass of its main
/// loop, and the next only once the ECU's interrupt has read the last: a sensor
/// frame's ~70 bytes took up to 5 ms to cross on a loaded two-core host. So the
/// frames go most of a period ahead.
pub const DEFAULT_LEAD_US: u64 = 8_000;
/// Dropout answers the host reads before the run to find the ECU's phase.
pub const WARMUP_PERIODS: u32 = 20;
/// Actuation frames over which the clock offset is the smallest transfer.
pub const OFFSET_WINDOW: usize = 4;
/// Periods after which an unanswered sensor frame is given up.
pub const STALE_FRAMES: u32 = 10;
/// Wall time left at the end of a period for the driver to step the plant, µs.
pub const GUARD_US: u64 = 1_000;

/// What keeps QEMU's virtual clock with the host's (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum HilClock {
    /// No `-icount`: the virtual clock is the host's; instructions take the
    /// emulator's time.
    #[default]
    Host,
    /// `-icount shift=N,align=on,sleep=on`: 2^N ns per instruction, the virtual
    /// clock held back to the host's and following it while the ECU sleeps.
    Icount,
}

/// How the flashed ECU is run.
#[derive(Clone, Debug)]
pub struct UsartOptions {
    /// The binary you flash (`cargo ecu`).
    pub elf: PathBuf,
    /// QEMU executable.
    pub qemu: PathBuf,
    /// What keeps QEMU's clock with the host's.
    pub clock: HilClock,
    /// `-icount shift` with [`HilClock::Icount`].
    pub icount_shift: u32,
    /// Folder for QEMU's messages (`qemu.log`).
    pub work_dir: PathBuf,
    /// Longest wall time to wait for the ECU at the set-up and the stop, s.
    pub frame_timeout_s: f64,
    /// Cycles per instruction (instructions = ticks / this).
    pub cycles_per_instruction: f64,
    /// The link key.
    pub link_key: LinkKey,
    /// The first sensor frame's lead over the ECU's release, µs.
    pub lead_us: u64,
}

impl UsartOptions {
    /// QEMU's clock options, as given to it (for the summary).
    pub fn qemu_clock(&self) -> String {
        match self.clock {
            HilClock::Icount => format!("-icount shift={},align=on,sleep=on", self.icount_shift),
            HilClock::Host => "host clock (no -icount)".into(),
        }
    }
}

/// What the reader thread passes on, with the instant it read the bytes.
enum FromEcu {
    /// The ECU's first byte: it booted and turned its receiver on.
    Listening,
    Frame(Box<Up>),
    Refused(FrameError),
    Closed,
}

/// Reads the ECU's frames from QEMU's stdout (USART1) on a thread of its own.
fn spawn_reader(mut out: std::process::ChildStdout, key: LinkKey) -> Receiver<(Instant, FromEcu)> {
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        let mut mac = LinkMac::new(&key);
        let mut up = Verifier::new(Stream::Up);
        let mut reader: FrameReader<MAX_FRAME_BYTES> = FrameReader::new();
        let mut buf = [0u8; 4096];
        let mut first = true;
        loop {
            let n = match out.read(&mut buf) {
                Ok(0) | Err(_) => {
                    let _ = tx.send((Instant::now(), FromEcu::Closed));
                    return;
                }
                Ok(n) => n,
            };
            let at = Instant::now();
            if std::mem::take(&mut first) && tx.send((at, FromEcu::Listening)).is_err() {
                return;
            }
            for &b in &buf[..n] {
                let got = match reader.push(b) {
                    None => continue,
                    Some(Ok(frame)) => match link::decode::<Up>(frame, &mut mac, &mut up) {
                        Ok(m) => FromEcu::Frame(Box::new(m)),
                        Err(e) => FromEcu::Refused(e),
                    },
                    Some(Err(e)) => FromEcu::Refused(e),
                };
                if tx.send((at, got)).is_err() {
                    return;
                }
            }
        }
    });
    rx
}

/// The smallest of the last [`OFFSET_WINDOW`] values `host − ECU` (µs).
#[derive(Debug, Default)]
struct Offset {
    window: VecDeque<i64>,
    first: Option<i64>,
}

impl Offset {
    fn push(&mut self, v: i64) {
        if self.window.len() == OFFSET_WINDOW {
            self.window.pop_front();
        }
        self.window.push_back(v);
        if self.first.is_none() && self.window.len() >= WARMUP_PERIODS as usize / 2 {
            self.first = self.get();
        }
    }

    fn get(&self) -> Option<i64> {
        self.window.iter().copied().min()
    }
}

/// A route frame on its way: announced by the sensor frame `seq` (or a later
/// one, which carries the same total), read by the ECU's plan task at its first
/// activation released at or after the control release that accepted the
/// announcement (`release_us`, once its answer came: control runs first).
#[derive(Clone, Copy, Debug)]
struct RouteWait {
    seq: u32,
    release_us: Option<u64>,
}

/// The ECU's answer as the host saw it: its frame, and its arrival on the
/// host's clock (µs since the ECU's start).
struct Answer {
    frame: ActuationFrame,
    arrival_us: i64,
}

/// The flashed ECU in QEMU, its USART1 piped to the host, in the real-time loop.
pub struct UsartEcu {
    child: Child,
    stdin: ChildStdin,
    rx: Receiver<(Instant, FromEcu)>,
    opts: UsartOptions,
    /// The host's reference instant: host µs are counted from it.
    epoch: Instant,
    mac: LinkMac,
    down_tx: Authenticator,
    route_tx: Authenticator,
    seq: u32,
    offset: Offset,
    /// The run's time 0 on the host's clock, µs since `epoch`.
    w0_us: i64,
    /// The ECU's clock at the run's time 0, µs (the sensor frames' stamps
    /// count from it on the host's clock).
    stamp0_us: u64,
    /// The sensor frames sent and not yet answered: seq → host µs sent.
    in_flight: BTreeMap<u32, i64>,
    /// The actuation the plant holds.
    held: Actuation<f32>,
    /// The plan the ECU's control task follows (positions only; its stamp on the
    /// simulated timeline).
    active: Plan<f32>,
    route_frames: u32,
    route_queue: VecDeque<Down>,
    /// The route frame last sent, until the ECU's plan task has read it.
    route_wait: Option<RouteWait>,
    last_release_us: Option<u64>,
    plan_counts: EcuTaskCounts,
    /// The plan events' activations so far: one each, in order; the first
    /// breach, reported at the next period.
    event_order: super::deadlines::EventOrder,
    event_error: Option<String>,
    /// The ECU's own counts in the last actuation frame.
    pub ecu_counts: Option<EcuCounts>,
    /// The run's link figures.
    pub hil: HilTally,
    /// Every frame sent and received, one CSV line each (`ecu/frames.csv`).
    pub events: Vec<String>,
    /// The ECU's frames the host refused, by reason.
    pub host_refused: RefusalCounts,
    /// The ECU's frames the host refused or did not expect.
    pub host_rejected: u64,
}

/// The link figures, gathered over the run (made [`HilSummary`] at its end).
#[derive(Debug, Default)]
pub struct HilTally {
    /// Sensor frames sent.
    pub sensor_frames_sent: u64,
    /// Route frames sent.
    pub route_frames_sent: u64,
    /// Actuation frames received during the run.
    pub actuation_frames_received: u64,
    /// Of those, answers to a sensor frame (accepted by the ECU).
    pub answers: u64,
    /// Dropout answers: no sensor frame had arrived at the release.
    pub sensor_missing: u64,
    /// Answers saying the ECU refused the sensor frame.
    pub sensor_refused: u64,
    /// Answers received after the end of their sensor frame's period.
    pub late_answers: u64,
    /// Periods in which no actuation frame arrived (the last one held).
    pub periods_without_frame: u64,
    /// Periods in which no sensor frame was sent: no ECU release fell in them
    /// (the ECU's clock had fallen a period behind the host's).
    pub periods_not_fed: u64,
    /// Plan events received.
    pub plan_events: u64,
    /// Control response times the ECU reported, µs.
    pub control_response_us: Vec<f64>,
    /// Plan response times (release → plan published), µs.
    pub plan_response_us: Vec<f64>,
    /// Host round trips, sensor frame sent → its answer received, µs.
    pub round_trip_us: Vec<f64>,
    /// The ECU's release less the host's send instant of the frame it answered, µs.
    pub lead_us: Vec<f64>,
    /// The host's recount of control deadline misses (late completions and
    /// skipped releases) from the ECU's stamps.
    pub control_deadline_misses: u64,
    /// The host's recount of skipped control releases.
    pub control_skipped_releases: u64,
    /// Dropout answers during the warm-up.
    pub warmup_missing: u64,
    /// The offset estimate at the start and at the end, µs.
    pub offset_first_us: Option<i64>,
}

impl Drop for UsartEcu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl UsartEcu {
    /// Starts QEMU on the flashed binary, sends it the car, the road and the
    /// obstacles of `scenario`, waits for `Ready`, and finds the ECU's phase.
    pub fn start(
        scenario: &Scenario,
        vehicle: &VehicleParams,
        sim: &SimOptions,
        opts: &UsartOptions,
    ) -> Result<Self> {
        if !opts.elf.exists() {
            bail!(
                "the flashed ECU binary {} does not exist: build it with `cargo ecu` (or give --elf)",
                opts.elf.display()
            );
        }
        // The same checks as `run` first (their messages say what is wrong).
        SimulatedEcu::<f32>::new(scenario, vehicle, sim)?;
        if scenario.obstacles.len() > u8::MAX as usize {
            bail!(
                "{} obstacles: the link carries at most 255",
                scenario.obstacles.len()
            );
        }
        fs::create_dir_all(&opts.work_dir)
            .with_context(|| format!("cannot create {}", opts.work_dir.display()))?;
        let qemu_log = File::create(opts.work_dir.join("qemu.log"))?;
        let mut cmd = Command::new(&opts.qemu);
        cmd.args(["-cpu", "cortex-m4", "-machine", "netduinoplus2"])
            // No semihosting: the flashed binary holds no `bkpt`. The first serial
            // port is the SoC's USART1, the link's, on QEMU's stdin/stdout.
            .args(["-display", "none", "-monitor", "none", "-serial", "stdio"]);
        if opts.clock == HilClock::Icount {
            cmd.arg("-icount")
                .arg(format!("shift={},align=on,sleep=on", opts.icount_shift));
        }
        let mut child = cmd
            .arg("-kernel")
            .arg(&opts.elf)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(qemu_log)
            .spawn()
            .with_context(|| {
                format!(
                    "cannot start {} (install it: apt-get install qemu-system-arm)",
                    opts.qemu.display()
                )
            })?;
        let stdin = child.stdin.take().ok_or_else(|| anyhow!("QEMU's stdin"))?;
        let stdout = child
            .stdout
            .take()
            .ok_or_else(|| anyhow!("QEMU's stdout"))?;
        let rx = spawn_reader(stdout, opts.link_key);
        let mut ecu = Self {
            child,
            stdin,
            rx,
            opts: opts.clone(),
            epoch: Instant::now(),
            mac: LinkMac::new(&opts.link_key),
            down_tx: Authenticator::new(Stream::Down),
            route_tx: Authenticator::new(Stream::Route),
            seq: 0,
            offset: Offset::default(),
            w0_us: 0,
            stamp0_us: 0,
            in_flight: BTreeMap::new(),
            held: Actuation::safe(0.0, 0.0),
            active: Plan::zeroed(),
            route_frames: 0,
            route_queue: VecDeque::new(),
            route_wait: None,
            last_release_us: None,
            plan_counts: EcuTaskCounts::default(),
            event_order: Default::default(),
            event_error: None,
            ecu_counts: None,
            hil: HilTally::default(),
            events: Vec::new(),
            host_refused: RefusalCounts::new(),
            host_rejected: 0,
        };
        ecu.set_up(scenario, vehicle, sim)?;
        ecu.warm_up()?;
        Ok(ecu)
    }

    fn host_us(&self, at: Instant) -> i64 {
        at.saturating_duration_since(self.epoch).as_micros() as i64
    }

    /// The host instant `host_us` µs after `epoch`.
    fn instant(&self, host_us: i64) -> Instant {
        self.epoch + Duration::from_micros(host_us.max(0) as u64)
    }

    /// An instant on the ECU's timeline on the simulated one (through the
    /// offset as now estimated).
    fn sim_of_ecu(&self, ecu_us: u64) -> u64 {
        let off = self.offset.get().unwrap_or(0);
        (ecu_us as i64 + off - self.w0_us).max(0) as u64
    }

    /// A host instant (µs) on the simulated timeline.
    fn sim_of_host(&self, host_us: i64) -> u64 {
        (host_us - self.w0_us).max(0) as u64
    }

    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.stdin
            .write_all(bytes)
            .and_then(|()| self.stdin.flush())
            .context("QEMU closed the ECU's USART (it exited: see qemu.log)")
    }

    fn send(&mut self, msg: &Down) -> Result<()> {
        let mut buf = [0u8; MAX_FRAME_BYTES];
        let n = link::encode(msg, &mut self.mac, &mut self.down_tx, &mut buf)
            .map_err(|e| anyhow!("encoding a frame: {e:?}"))?;
        self.write(&buf[..n])
    }

    fn send_route(&mut self, msg: &Down) -> Result<()> {
        let mut buf = [0u8; MAX_FRAME_BYTES];
        let n = link::encode(msg, &mut self.mac, &mut self.route_tx, &mut buf)
            .map_err(|e| anyhow!("encoding a frame: {e:?}"))?;
        self.write(&buf[..n])?;
        self.route_frames = self.route_frames.saturating_add(1);
        self.hil.route_frames_sent += 1;
        Ok(())
    }

    /// The next thing from the ECU within `timeout`; an error if QEMU exited.
    fn next(&mut self, timeout: Duration) -> Result<Option<(Instant, FromEcu)>> {
        match self.rx.recv_timeout(timeout) {
            Ok((_, FromEcu::Closed)) | Err(RecvTimeoutError::Disconnected) => {
                let log =
                    fs::read_to_string(self.opts.work_dir.join("qemu.log")).unwrap_or_default();
                bail!(
                    "the ECU's USART closed (QEMU exited: {}){}",
                    self.child
                        .try_wait()
                        .ok()
                        .flatten()
                        .map_or("still running".into(), |s| s.to_string()),
                    if log.is_empty() {
                        String::new()
                    } else {
                        format!("; qemu.log: {}", log.trim())
                    }
                )
            }
            Ok(x) => Ok(Some(x)),
            Err(RecvTimeoutError::Timeout) => Ok(None),
        }
    }

    fn set_up(
        &mut self,
        scenario: &Scenario,
        vehicle: &VehicleParams,
        sim: &SimOptions,
    ) -> Result<()> {
        let wait = Duration::from_secs_f64(self.opts.frame_timeout_s);
        // QEMU's USART drops what arrives before the ECU turns its receiver on:
        // its first byte says it did.
        match self.next(wait)? {
            Some((_, FromEcu::Listening)) => {}
            Some(_) => bail!("the ECU's first bytes were not its link's"),
            None => bail!(
                "no byte from the ECU within {} s: is {} the flashed binary (`cargo ecu`)?",
                self.opts.frame_timeout_s,
                self.opts.elf.display()
            ),
        }
        let first = RouteFeeder::new(&scenario.track)?.first();
        self.send(&Down::Config(ConfigFrame {
            vehicle: crate::model::vehicle::vehicle_config::<f32>(vehicle),
            mu_planner: sim.mu_planner as f32,
            closed: first.closed,
            path_rows: first.rows.len() as u16,
            obstacles: scenario.obstacles.len() as u8,
        }))?;
        for f in path_chunks(&first.rows) {
            self.send(&f)?;
        }
        let total = scenario.obstacles.len() as u8;
        for (k, o) in scenario.obstacles.iter().enumerate() {
            if o.vertices.len() > MAX_VERTICES {
                bail!(
                    "obstacle {:?} has {} vertices: the ECU takes at most {MAX_VERTICES}",
                    o.id,
                    o.vertices.len()
                );
            }
            let mut f = ObstacleFrame {
                index: k as u8,
                total,
                id: k as u32,
                count: o.vertices.len() as u8,
                vertices: [[0.0; 2]; MAX_VERTICES],
            };
            for (dst, src) in f.vertices.iter_mut().zip(&o.vertices) {
                *dst = src.map(|x| x as f32);
            }
            self.send(&Down::Obstacle(f))?;
        }
        self.send(&Down::Start)?;
        loop {
            match self.next(wait)? {
                Some((_, FromEcu::Frame(m))) => match *m {
                    Up::Ready(r) if r.status == 0 => return Ok(()),
                    Up::Ready(r) => bail!(
                        "the ECU refused the set-up: {}",
                        setup_refusal(r.status, r.detail)
                    ),
                    _ => self.host_rejected += 1,
                },
                Some((_, FromEcu::Refused(e))) => {
                    self.host_rejected += 1;
                    self.host_refused.count(e.refusal());
                    if e.refusal() == link::Refusal::Auth {
                        bail!("the ECU's frames fail authentication: the ECU binary was built with another link key than the simulator's (build both with the same ECU_LINK_KEY, or give the ECU's key with --link-key)");
                    }
                }
                Some((_, FromEcu::Listening)) => {}
                Some((_, FromEcu::Closed)) => unreachable!("next() fails on Closed"),
                None => bail!(
                    "no Ready from the ECU within {} s of the set-up",
                    self.opts.frame_timeout_s
                ),
            }
        }
    }

    /// Reads the ECU's dropout answers for [`WARMUP_PERIODS`] periods: the
    /// offset between its clock and the host's, and the run's base release.
    fn warm_up(&mut self) -> Result<()> {
        let mut last_release = 0u64;
        let mut n = 0;
        while n < WARMUP_PERIODS {
            let Some((at, m)) = self.next(Duration::from_secs_f64(self.opts.frame_timeout_s))?
            else {
                bail!(
                    "no actuation frame from the ECU within {} s after Ready: its control task does not run",
                    self.opts.frame_timeout_s
                );
            };
            match m {
                FromEcu::Frame(m) => match *m {
                    Up::Actuation(a) => {
                        let host = self.host_us(at);
                        self.offset.push(host - a.sent_us as i64);
                        last_release = last_release.max(a.release_us);
                        if a.sensor == link::SENSOR_MISSING {
                            self.hil.warmup_missing += 1;
                        }
                        n += 1;
                    }
                    _ => self.host_rejected += 1,
                },
                FromEcu::Refused(e) => {
                    self.host_rejected += 1;
                    self.host_refused.count(e.refusal());
                }
                _ => {}
            }
        }
        self.hil.offset_first_us = self.offset.get();
        // The run's time 0 `lead` before an ECU plan release, far enough ahead
        // for its frame.
        let earliest = last_release + 3 * CONTROL_PERIOD_US + self.opts.lead_us;
        let first = earliest.div_ceil(PLAN_PERIOD_US) * PLAN_PERIOD_US;
        let off = self.offset.get().unwrap_or(0);
        self.w0_us = first as i64 - self.opts.lead_us as i64 + off;
        self.stamp0_us = first - self.opts.lead_us;
        Ok(())
    }

    /// One actuation frame of the ECU, received at host `arrival_us`: counted,
    /// timed, and its plan event recorded; `Some` when it is an actuation.
    fn take(
        &mut self,
        at: Instant,
        m: FromEcu,
        plans: &mut Vec<PlanActivation>,
        skipped: &mut u32,
    ) -> Option<Answer> {
        let a = match m {
            FromEcu::Frame(m) => match *m {
                Up::Actuation(a) => a,
                _ => {
                    self.host_rejected += 1;
                    return None;
                }
            },
            FromEcu::Refused(e) => {
                self.host_rejected += 1;
                self.host_refused.count(e.refusal());
                return None;
            }
            FromEcu::Listening | FromEcu::Closed => return None,
        };
        let arrival_us = self.host_us(at);
        self.offset.push(arrival_us - a.sent_us as i64);
        self.events.push(format!(
            "recv,{arrival_us},{},{},{},{},{}",
            a.seq,
            a.sensor,
            a.release_us,
            a.sent_us,
            self.offset.get().unwrap_or(0)
        ));
        let h = &mut self.hil;
        h.actuation_frames_received += 1;
        match a.sensor {
            0 => {
                h.answers += 1;
                if let Some(w) = self.route_wait.as_mut() {
                    if w.release_us.is_none() && a.seq.wrapping_sub(w.seq) < u32::MAX / 2 {
                        w.release_us = Some(a.release_us);
                    }
                }
                if let Some(sent) = self.in_flight.remove(&a.seq) {
                    h.round_trip_us.push((arrival_us - sent) as f64);
                    let off = self.offset.get().unwrap_or(0);
                    h.lead_us.push((a.release_us as i64 + off - sent) as f64);
                }
            }
            link::SENSOR_MISSING => h.sensor_missing += 1,
            _ => h.sensor_refused += 1,
        }
        // Frames answered or overtaken: no answer will come for them (a
        // dropout answer carries the seq the ECU expects next).
        let missing = a.sensor == link::SENSOR_MISSING;
        self.in_flight
            .retain(|&s, _| s > a.seq || (missing && s == a.seq));
        // The previous activation's completion, and the releases skipped since.
        if let Some(last) = self.last_release_us {
            h.control_response_us
                .push(f64::from(a.previous_response_us));
            if u64::from(a.previous_response_us) > CONTROL_PERIOD_US {
                h.control_deadline_misses += 1;
            }
            let gap = (a.release_us.saturating_sub(last) / CONTROL_PERIOD_US).saturating_sub(1);
            h.control_skipped_releases += gap;
            h.control_deadline_misses += gap;
        }
        self.last_release_us = Some(a.release_us);
        if let Some(p) = &a.plan {
            if let Err(e) = self.event_order.check(p.activation) {
                self.event_error.get_or_insert(e);
            }
            let h = &mut self.hil;
            h.plan_events += 1;
            if self
                .route_wait
                .is_some_and(|w| w.release_us.is_some_and(|r| p.release_us >= r))
            {
                self.route_wait = None;
            }
            h.plan_response_us
                .push(p.finish_us.saturating_sub(p.release_us) as f64);
            *skipped += skipped_between(p.release_us, p.end_us, PLAN_PERIOD_US);
            self.plan_counts = p.timing.into();
            if p.published {
                let mut plan = plan_of(p);
                plan.stamp_us = self.sim_of_ecu(plan.stamp_us);
                self.active = plan;
            }
            plans.push(self.activation_of(p));
        }
        self.ecu_counts = Some(EcuCounts {
            plan: self.plan_counts,
            control: a.control.into(),
            watchdog_trips: a.watchdog_trips.into(),
            frames_refused: a.refused,
        });
        Some(Answer {
            frame: a,
            arrival_us,
        })
    }

    /// The record of a plan event on the simulated timeline; cycles are its
    /// ECU clock ticks.
    fn activation_of(&self, p: &PlanEventFrame) -> PlanActivation {
        let cycles = f64::from(p.ticks);
        PlanActivation {
            activation: p.activation,
            release_us: self.sim_of_ecu(p.release_us),
            finish_us: self.sim_of_ecu(p.finish_us),
            instructions: cycles / self.opts.cycles_per_instruction,
            cycles,
            status: plan_status_name(p.status),
            published: p.published,
            deadline_miss: p.finish_us > p.release_us + PLAN_PERIOD_US,
            passes: u32::from(p.passes),
            warm: p.warm,
            qp_iterations: u32::from(p.qp_iterations),
            qp_added: u32::from(p.qp_added),
            qp_removed: u32::from(p.qp_removed),
            qp_refactorizations: u32::from(p.qp_refactorizations),
            rows: u32::from(p.rows),
            active_constraints: u32::from(p.active),
            window: p.window_ticks > 0,
            window_instructions: f64::from(p.window_ticks) / self.opts.cycles_per_instruction,
            route_frames: 0,
            max_validity_slack_rad: None,
        }
    }

    /// Writes `frames.csv` into the work folder: every sensor frame sent
    /// (`send`, host µs, seq, the period's start in host µs, its stamp) and
    /// every actuation frame received (`recv`, host µs, seq, sensor code, release
    /// and send instants on the ECU's timeline, the offset estimate).
    pub fn write_frames(&self) -> Result<()> {
        let path = self.opts.work_dir.join("frames.csv");
        let mut text = String::from("event,host_us,seq,a,b,c,offset_us\n");
        for e in &self.events {
            text.push_str(e);
            text.push('\n');
        }
        fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))
    }

    /// Ends the run: `Stop`, the ECU's `Done` (its stack and refused frames).
    pub fn stop(mut self) -> Result<(DoneFrame, Self)> {
        self.send(&Down::Stop)?;
        let wait = Duration::from_secs_f64(self.opts.frame_timeout_s);
        let done = loop {
            match self.next(wait)? {
                Some((_, FromEcu::Frame(m))) => match *m {
                    Up::Done(d) => break d,
                    Up::Actuation(_) => {}
                    _ => self.host_rejected += 1,
                },
                Some((_, FromEcu::Refused(e))) => {
                    self.host_rejected += 1;
                    self.host_refused.count(e.refusal());
                }
                Some(_) => {}
                None => bail!(
                    "no Done from the ECU within {} s of Stop",
                    self.opts.frame_timeout_s
                ),
            }
        };
        for _ in 0..50 {
            if self.child.try_wait()?.is_some() {
                break;
            }
            thread::sleep(Duration::from_millis(20));
        }
        Ok((done, self))
    }

    /// The run's link figures.
    pub fn summary(&self, wall_s: f64) -> HilSummary {
        let h = &self.hil;
        let drift = match (h.offset_first_us, self.offset.get()) {
            (Some(a), Some(b)) => Some((b - a) as f64),
            _ => None,
        };
        HilSummary {
            qemu_clock: self.opts.qemu_clock(),
            lead_us: self.opts.lead_us,
            warmup_periods: u64::from(WARMUP_PERIODS),
            warmup_missing: h.warmup_missing,
            sensor_frames_sent: h.sensor_frames_sent,
            route_frames_sent: h.route_frames_sent,
            actuation_frames_received: h.actuation_frames_received,
            answers: h.answers,
            sensor_missing_at_ecu: h.sensor_missing,
            sensor_refused_at_ecu: h.sensor_refused,
            late_answers: h.late_answers,
            periods_without_frame: h.periods_without_frame,
            periods_not_fed: h.periods_not_fed,
            plan_events: h.plan_events,
            control_response_us: Spread::of(&h.control_response_us),
            plan_response_us: Spread::of(&h.plan_response_us),
            round_trip_us: Spread::of(&h.round_trip_us),
            lead_at_release_us: Spread::of(&h.lead_us),
            clock_offset_drift_us: drift,
            wall_s,
        }
    }
}

impl Ecu<f32> for UsartEcu {
    fn control(&mut self, t_us: u64, est: &StateEstimate<f32>) -> Result<ControlOutput<f32>> {
        if let Some(e) = self.event_error.take() {
            bail!("{e}");
        }
        let mut plans = Vec::new();
        let mut skipped = 0u32;
        let mut latest: Option<Answer> = None;
        // The period's start on the host's clock: whatever comes until then (late
        // answers of the last period).
        let start = self.w0_us + t_us as i64;
        let send_at = self.instant(start);
        loop {
            let now = Instant::now();
            if now >= send_at {
                break;
            }
            if let Some((at, m)) = self.next(send_at - now)? {
                if let Some(a) = self.take(at, m, &mut plans, &mut skipped) {
                    self.hil.late_answers += u64::from(a.frame.sensor == 0);
                    latest = Some(a);
                }
            }
        }
        // At most one sensor frame waits at the ECU: a new one is sent once the
        // last one was answered (or the ECU said it refused it), i.e. once the
        // ECU has had a release since; when that answer comes within the period
        // (the ECU's clock is behind the host's), the period's sample is sent at
        // once, a period ahead of the ECU's next release; a period without it
        // sends none (module docs). A frame unanswered for 10 periods is given
        // up.
        let seq = self.seq.wrapping_add(1);
        self.in_flight
            .retain(|&s, _| seq.wrapping_sub(s) <= STALE_FRAMES);
        let end = self.instant(start + (CONTROL_PERIOD_US - GUARD_US) as i64);
        let mut send = self.in_flight.is_empty();
        while !send && !self.in_flight.is_empty() {
            let now = Instant::now();
            if now >= end {
                break;
            }
            if let Some((at, m)) = self.next(end - now)? {
                if let Some(a) = self.take(at, m, &mut plans, &mut skipped) {
                    self.hil.late_answers += u64::from(a.frame.sensor == 0);
                    send = self.in_flight.is_empty();
                    latest = Some(a);
                }
            }
        }
        if send {
            self.seq = seq;
            // A frame of the road before it, announced by it, once the ECU's plan
            // task has read the last one (its queue holds one).
            if self.route_wait.is_none() {
                if let Some(f) = self.route_queue.pop_front() {
                    self.send_route(&f)?;
                    self.route_wait = Some(RouteWait {
                        seq,
                        release_us: None,
                    });
                }
            }
            // Stamped with the sample's instant: the ECU's clock at the run's
            // start plus the host's time since (module docs).
            let stamp = self.stamp0_us + t_us;
            let msg = Down::Sensor(SensorFrame {
                seq,
                estimate: StateEstimate {
                    stamp_us: stamp,
                    ..*est
                },
                route_frames: self.route_frames,
            });
            let sent = self.host_us(Instant::now());
            self.events
                .push(format!("send,{sent},{seq},{start},{stamp},,"));
            self.in_flight.insert(seq, sent);
            self.send(&msg)?;
            self.hil.sensor_frames_sent += 1;
        } else {
            self.hil.periods_not_fed += 1;
        }
        // Its answer, until the end of the period.
        loop {
            let now = Instant::now();
            if now >= end {
                break;
            }
            if let Some((at, m)) = self.next(end - now)? {
                if let Some(a) = self.take(at, m, &mut plans, &mut skipped) {
                    let answered = a.frame.seq == seq && a.frame.sensor != link::SENSOR_MISSING;
                    latest = Some(a);
                    if answered {
                        break;
                    }
                }
            }
        }
        let (actuation, release_us, sent_us, ticks) = match latest {
            Some(a) => {
                let act = actuation_of(&a.frame);
                self.held = act;
                (
                    act,
                    self.sim_of_ecu(a.frame.release_us),
                    self.sim_of_host(a.arrival_us).max(t_us),
                    a.frame.control_ticks,
                )
            }
            None => {
                self.hil.periods_without_frame += 1;
                (self.held, t_us, t_us, 0)
            }
        };
        let cycles = f64::from(ticks);
        Ok(ControlOutput {
            actuation,
            release_us,
            sent_us,
            // Counted by the host from every frame (`HilTally`), not per call.
            completion: None,
            control_skipped_releases: 0,
            ecu_counts: self.ecu_counts,
            instructions: cycles / self.opts.cycles_per_instruction,
            cycles,
            plans,
            skipped_releases: skipped,
            friction_mu: None,
            sideslip_lag: None,
            car_estimate: None,
        })
    }

    fn active_plan(&self) -> &Plan<f32> {
        &self.active
    }

    fn reports_plan_states(&self) -> bool {
        false
    }

    fn set_window(&mut self, w: &Window) -> Result<()> {
        // As in lock-step: one frame per plan release on the route channel, each
        // announced by the sensor frame after it.
        self.route_queue = path_chunks(&w.rows).collect();
        self.route_queue.push_back(Down::Window(link::WindowFrame {
            rows: w.rows.len() as u16,
            origin_m: w.origin_m as f32,
            closed: w.closed,
        }));
        Ok(())
    }
}
