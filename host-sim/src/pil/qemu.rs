//! The ECU application running in QEMU: the emulator's process, the link on three
//! FIFOs (down, up and the route channel), the set-up, the exchange of one sensor
//! frame for one actuation frame per control period, and [`QemuEcu`] as the closed
//! loop's [`Ecu`].

use std::fs::{self, File};
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::thread;
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};
use firmware::deadline::{CONTROL_BUDGET_CYCLES, PLAN_BUDGET_CYCLES};
use firmware::link::{
    self, Authenticator, ConfigFrame, DoneFrame, Down, FrameError, FrameReader, LinkKey, LinkMac,
    ObstacleFrame, PlanEventFrame, Refusal, RefusalCounts, SensorFrame, Stream, Up, Verifier,
    MAX_FRAME_BYTES,
};
use firmware::obstacles::MAX_VERTICES;
use firmware::plan::Plan;
use firmware::state_estimate::StateEstimate;
use firmware::tasks::{CONTROL_PERIOD_US, PLAN_PERIOD_US};

use crate::closed_loop::ecu::{
    ControlCompletion, ControlOutput, Ecu, EcuCounts, EcuTaskCounts, SimulatedEcu,
};
use crate::closed_loop::plan_activation::{plan_status_name, PlanActivation};
use crate::closed_loop::SimOptions;
use crate::model::vehicle::VehicleParams;
use crate::pil::deadlines::{skipped_between, TickOverruns};
use crate::pil::frames::{actuation_of, path_chunks, plan_of, setup_refusal};
use crate::pil::link_fault::{flip_bit, noise_run, LinkChannel, LinkFault, LinkFaultKind};
use crate::world::route::{RouteFeeder, Window};
use crate::world::scenario::Scenario;

/// ECU core clock, Hz: QEMU's SysTick counts at this rate of virtual time.
pub const ECU_CLOCK_HZ: f64 = firmware::timing::ECU_CLOCK_HZ as f64;

/// How the ECU is run.
#[derive(Clone, Debug)]
pub struct PilOptions {
    /// The ECU application (ELF for `thumbv7em-none-eabihf`).
    pub elf: PathBuf,
    /// QEMU executable.
    pub qemu: PathBuf,
    /// `-icount shift`: virtual ns per instruction = 2^shift.
    pub icount_shift: u32,
    /// Folder for the FIFOs, the ECU's defmt log and QEMU's messages.
    pub work_dir: PathBuf,
    /// Longest wall time to wait for one frame, s (a hung ECU is an error).
    pub frame_timeout_s: f64,
    /// Cycles per instruction that turn measured instructions into cycles (the
    /// timing report's bound).
    pub cycles_per_instruction: f64,
    /// Write QEMU's execution trace (`-d in_asm,exec,nochain`) to this file, for the
    /// cycles-per-instruction analysis (large: about 14 bytes per instruction).
    pub trace: Option<PathBuf>,
    /// The link key the frames are authenticated with: the ECU application's
    /// (`firmware::link::LINK_KEY` of the build, unless it was built with another
    /// `ECU_LINK_KEY`).
    pub link_key: LinkKey,
    /// Sensor frames to replace by forged, replayed or corrupted ones, if any.
    pub link_fault: Option<LinkFault>,
}

impl PilOptions {
    /// Virtual time per instruction, ns.
    pub fn ns_per_instruction(&self) -> f64 {
        f64::from(1u32 << self.icount_shift)
    }

    /// Instructions executed in `ticks` of the ECU's 168 MHz clock.
    pub fn instructions(&self, ticks: u32) -> f64 {
        f64::from(ticks) / ECU_CLOCK_HZ * 1e9 / self.ns_per_instruction()
    }
}

/// Counters of the link, host side.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct LinkCounters {
    /// Frames the host refused (garbled, short, wrong version, forged, replayed,
    /// unexpected).
    pub rejected: u64,
    /// Of those, the ones refused by reason (the ECU's frames), frames.
    pub refused: RefusalCounts,
    /// Actuation frames answering another sensor frame than the one sent.
    pub stale: u64,
}

/// The link fault's frames, host side: what was injected and what the ECU did
/// with it.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InjectedFrames {
    /// Sensor frames replaced by forged, replayed or corrupted ones, by the reason
    /// the ECU must refuse them for, frames.
    pub injected: RefusalCounts,
    /// Of those, the ones the ECU answered as refused for that reason
    /// (`ActuationFrame::sensor`), frames.
    pub refused_as_expected: u64,
    /// Of those, the ones the ECU answered as accepted: acted on (must be 0),
    /// frames.
    pub acted_on: u64,
    /// Legitimate sensor frames the ECU answered as refused (must be 0), frames.
    pub legitimate_refused: u64,
}

impl InjectedFrames {
    /// The route channel's injected frames judged on the ECU's refusal counts
    /// at the end (`ecu`, its Done frame's): that channel has no answer per
    /// frame. Of each reason, the frames refused up to the count injected are
    /// refused as expected, the rest of the injected ones acted on, and refusals
    /// beyond it legitimate frames refused.
    pub fn judge_by_counts(&mut self, ecu: &RefusalCounts) {
        let (mut expected, mut beyond) = (0u64, 0u64);
        for r in Refusal::ALL {
            let (injected, refused) = (self.injected.of(r), ecu.of(r));
            expected += u64::from(injected.min(refused));
            beyond += u64::from(refused.saturating_sub(injected));
        }
        self.refused_as_expected = expected;
        self.acted_on = u64::from(self.injected.total()) - expected;
        self.legitimate_refused = beyond;
    }
}

/// `msg` encoded as a frame of `tx`'s stream, its tag under `mac`'s key.
fn encode_frame(msg: &Down, mac: &mut LinkMac, tx: &mut Authenticator) -> Result<Vec<u8>> {
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let n = link::encode(msg, mac, tx, &mut buf).map_err(|e| anyhow!("encoding a frame: {e:?}"))?;
    Ok(buf[..n].to_vec())
}

enum Incoming {
    Frame(Box<Up>),
    Bad(FrameError),
    Closed,
}

/// Bytes of the legitimate sensor frames sent in the last second, kept for the
/// `replay` link fault: at most this many frames.
const REPLAY_HISTORY_FRAMES: usize = 100;

/// The ECU application running in QEMU, in the loop.
pub struct QemuEcu {
    child: Child,
    down: BufWriter<File>,
    up: Receiver<Incoming>,
    opts: PilOptions,
    seq: u32,
    /// Counters of the link, host side.
    pub counters: LinkCounters,
    /// The plan the ECU's control task follows (positions only), as reported.
    pub active: Plan<f32>,
    /// The route channel (`ecu.route`): the next window of the road.
    route: BufWriter<File>,
    /// Route frames written since the start, in all (announced in each sensor
    /// frame: a refused one loses no announcement).
    route_frames: u32,
    /// Frames of the road not yet sent: one goes before the sensor frame of each
    /// plan release (the ECU's plan task reads one per activation).
    route_queue: std::collections::VecDeque<Down>,
    /// The plan releases (µs) before whose sensor frame a frame of the road went:
    /// the activations that received one (the records' `route_frames`).
    route_releases: std::collections::BTreeSet<u64>,
    /// The last control release the ECU reported, µs.
    last_release_us: Option<u64>,
    /// That activation's own ticks: its budget overrun is counted with its
    /// completion, which the next frame reports (as the ECU counts it).
    last_control_ticks: Option<u32>,
    /// The plan task's counts as of the last plan event.
    plan_counts: EcuTaskCounts,
    /// The plan events' activations so far: one each, in order.
    event_order: super::deadlines::EventOrder,
    /// Budget overruns on the ECU's clock, counted by the host from the ticks.
    pub tick_overruns: TickOverruns,
    /// The ECU's own counts in the last actuation frame (response times included).
    pub ecu_counts: Option<EcuCounts>,
    /// Keyed BLAKE2s under the link key, for the frames the host sends.
    mac: LinkMac,
    /// The control channel's down stream (the set-up, the sensor frames, `Stop`).
    down_tx: Authenticator,
    /// The route channel's stream.
    route_tx: Authenticator,
    /// A forger's MAC: under a key that is not the link's (`forge`).
    forger: LinkMac,
    /// The legitimate sensor frames of the last second, oldest first (`replay`).
    history: std::collections::VecDeque<Vec<u8>>,
    /// The legitimate route frames of the last windows, oldest first (`replay`
    /// on the route channel).
    route_history: std::collections::VecDeque<Vec<u8>>,
    /// Frames replaced so far by the link fault.
    faulted: u32,
    /// The link fault's frames and what the ECU did with them.
    pub injected: InjectedFrames,
    /// The ECU accepted the set-up (its `Ready` arrived).
    ready: bool,
}

impl Drop for QemuEcu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn mkfifo(path: &Path) -> Result<()> {
    if path.exists() {
        fs::remove_file(path).with_context(|| format!("removing the old {}", path.display()))?;
    }
    let status = Command::new("mkfifo")
        .arg(path)
        .status()
        .context("running mkfifo (coreutils) to create the ECU link")?;
    if !status.success() {
        bail!("mkfifo {} failed", path.display());
    }
    Ok(())
}

/// Reads frames from the up-link FIFO on a thread of its own, verifying them
/// with `key` on the up stream.
fn spawn_reader(mut file: File, key: LinkKey) -> Receiver<Incoming> {
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        let mut mac = LinkMac::new(&key);
        let mut up = Verifier::new(Stream::Up);
        let mut reader: FrameReader<MAX_FRAME_BYTES> = FrameReader::new();
        let mut buf = [0u8; 4096];
        loop {
            let n = match file.read(&mut buf) {
                Ok(0) | Err(_) => {
                    let _ = tx.send(Incoming::Closed);
                    return;
                }
                Ok(n) => n,
            };
            for &b in &buf[..n] {
                let msg = match reader.push(b) {
                    None => continue,
                    Some(Ok(frame)) => match link::decode::<Up>(frame, &mut mac, &mut up) {
                        Ok(m) => Incoming::Frame(Box::new(m)),
                        Err(e) => Incoming::Bad(e),
                    },
                    Some(Err(e)) => Incoming::Bad(e),
                };
                if tx.send(msg).is_err() {
                    return;
                }
            }
        }
    });
    rx
}

impl QemuEcu {
    /// Starts QEMU on the ECU application and sends it the car, the track and the
    /// obstacles of `scenario`; returns once the ECU has accepted them.
    pub fn start(
        scenario: &Scenario,
        vehicle: &VehicleParams,
        sim: &SimOptions,
        opts: &PilOptions,
    ) -> Result<Self> {
        if !opts.elf.exists() {
            bail!(
                "the ECU application {} does not exist: build it with `cargo ecu-lockstep`",
                opts.elf.display()
            );
        }
        fs::create_dir_all(&opts.work_dir)
            .with_context(|| format!("cannot create {}", opts.work_dir.display()))?;
        let dir = fs::canonicalize(&opts.work_dir)?;
        let down_path = dir.join("ecu.down");
        let up_path = dir.join("ecu.up");
        let route_path = dir.join("ecu.route");
        mkfifo(&down_path)?;
        mkfifo(&up_path)?;
        mkfifo(&route_path)?;
        // The ECU's defmt log goes to the semihosting console, QEMU's stdout.
        let defmt_log = File::create(dir.join("ecu.defmt"))?;
        let qemu_log = File::create(dir.join("qemu.log"))?;
        let child = Command::new(&opts.qemu)
            .current_dir(&dir)
            .args(["-cpu", "cortex-m4", "-machine", "netduinoplus2"])
            .args(["-display", "none", "-serial", "null", "-monitor", "none"])
            .args(["-semihosting-config", "enable=on,target=native"])
            .arg("-icount")
            .arg(format!("shift={},sleep=off", opts.icount_shift))
            .args(opts.trace.iter().flat_map(|t| {
                [
                    "-d".into(),
                    "in_asm,exec,nochain".into(),
                    "-D".into(),
                    t.display().to_string(),
                ]
            }))
            .arg("-kernel")
            .arg(fs::canonicalize(&opts.elf)?)
            .stdin(Stdio::null())
            .stdout(defmt_log)
            .stderr(qemu_log)
            .spawn()
            .with_context(|| {
                format!(
                    "cannot start {} (install it: apt-get install qemu-system-arm)",
                    opts.qemu.display()
                )
            })?;
        // Open the FIFOs in the ECU's order (down, up, route), on a thread: an open
        // blocks until QEMU opens the other end.
        let (tx, rx) = mpsc::channel();
        {
            let (d, u, r) = (down_path.clone(), up_path.clone(), route_path.clone());
            thread::spawn(move || {
                let opened = File::options().write(true).open(&d).and_then(|down| {
                    let up = File::open(&u)?;
                    let route = File::options().write(true).open(&r)?;
                    Ok((down, up, route))
                });
                let _ = tx.send(opened);
            });
        }
        let mut ecu = None;
        let mut child = child;
        for _ in 0..(opts.frame_timeout_s * 20.0).ceil() as u64 {
            match rx.recv_timeout(Duration::from_millis(50)) {
                Ok(r) => {
                    ecu = Some(r.context("opening the ECU link FIFOs")?);
                    break;
                }
                Err(RecvTimeoutError::Timeout) => {
                    if let Some(status) = child.try_wait()? {
                        let log = fs::read_to_string(dir.join("qemu.log")).unwrap_or_default();
                        bail!("QEMU exited ({status}) before opening the link: {log}");
                    }
                }
                Err(RecvTimeoutError::Disconnected) => bail!("the link opener stopped"),
            }
        }
        let Some((down, up, route)) = ecu else {
            let _ = child.kill();
            bail!(
                "the ECU did not open its link within {} s (is {} the ECU application?)",
                opts.frame_timeout_s,
                opts.elf.display()
            );
        };
        let mut forger_key = opts.link_key;
        for b in &mut forger_key {
            *b ^= 0x5a;
        }
        let mut ecu = Self {
            child,
            down: BufWriter::new(down),
            up: spawn_reader(up, opts.link_key),
            opts: opts.clone(),
            seq: 0,
            counters: LinkCounters::default(),
            active: Plan::zeroed(),
            route: BufWriter::new(route),
            route_frames: 0,
            route_queue: Default::default(),
            route_releases: Default::default(),
            last_release_us: None,
            last_control_ticks: None,
            plan_counts: Default::default(),
            event_order: Default::default(),
            tick_overruns: TickOverruns::default(),
            ecu_counts: None,
            mac: LinkMac::new(&opts.link_key),
            down_tx: Authenticator::new(Stream::Down),
            route_tx: Authenticator::new(Stream::Route),
            forger: LinkMac::new(&forger_key),
            history: std::collections::VecDeque::new(),
            route_history: std::collections::VecDeque::new(),
            faulted: 0,
            injected: InjectedFrames::default(),
            ready: false,
        };
        ecu.set_up(scenario, vehicle, sim)?;
        Ok(ecu)
    }

    /// A frame of the control channel's down stream, encoded and authenticated.
    fn frame(&mut self, msg: &Down) -> Result<Vec<u8>> {
        encode_frame(msg, &mut self.mac, &mut self.down_tx)
    }

    fn send(&mut self, msg: &Down) -> Result<()> {
        let frame = self.frame(msg)?;
        self.write_down(&frame)
    }

    fn write_down(&mut self, frame: &[u8]) -> Result<()> {
        self.down
            .write_all(frame)
            .context("the ECU closed its link")
    }

    /// What the ECU's frames the host refused say, if anything: refused as
    /// forged, they were sent under another key than the host's.
    fn refusal_hint(&self) -> String {
        if self.counters.refused.auth > 0 {
            format!(
                "; the host refused {} of the ECU's frames as forged: the ECU application was built with another link key than the simulator's (build both with the same ECU_LINK_KEY, or give the ECU's key with --link-key)",
                self.counters.refused.auth
            )
        } else {
            String::new()
        }
    }

    fn receive(&mut self) -> Result<Up> {
        loop {
            self.down.flush().context("the ECU closed its link")?;
            match self
                .up
                .recv_timeout(Duration::from_secs_f64(self.opts.frame_timeout_s))
            {
                Ok(Incoming::Frame(m)) => return Ok(*m),
                Ok(Incoming::Bad(e)) => {
                    self.counters.rejected += 1;
                    self.counters.refused.count(e.refusal());
                    // Before the set-up is accepted a forged frame is most likely a
                    // key that differs from the ECU's: said at once, not after a
                    // timeout.
                    if !self.ready && e.refusal() == Refusal::Auth {
                        bail!(
                            "the ECU's frames fail authentication{}",
                            self.refusal_hint()
                        );
                    }
                }
                Ok(Incoming::Closed) | Err(RecvTimeoutError::Disconnected) => {
                    let defmt = self.opts.work_dir.join("ecu.defmt");
                    bail!(
                        "the ECU stopped (QEMU exited); its log: {} (decode with `defmt-print -e {}`), QEMU's: {}{}",
                        defmt.display(),
                        self.opts.elf.display(),
                        self.opts.work_dir.join("qemu.log").display(),
                        self.refusal_hint()
                    )
                }
                Err(RecvTimeoutError::Timeout) => bail!(
                    "no frame from the ECU within {} s of wall time: the firmware hangs{}",
                    self.opts.frame_timeout_s,
                    self.refusal_hint()
                ),
            }
        }
    }

    fn set_up(
        &mut self,
        scenario: &Scenario,
        vehicle: &VehicleParams,
        sim: &SimOptions,
    ) -> Result<()> {
        // The same checks as `run` on the whole track first (their messages say
        // which obstacle blocks the road and by how much).
        SimulatedEcu::<f32>::new(scenario, vehicle, sim)?;
        if scenario.obstacles.len() > u8::MAX as usize {
            bail!(
                "{} obstacles: the link carries at most 255",
                scenario.obstacles.len()
            );
        }
        let first = RouteFeeder::new(&scenario.track)?.first();
        self.send(&Down::Config(ConfigFrame {
            vehicle: crate::model::vehicle::vehicle_config::<f32>(vehicle),
            mu_planner: sim.mu_planner as f32,
            closed: first.closed,
            path_rows: first.rows.len() as u16,
            obstacles: scenario.obstacles.len() as u8,
        }))?;
        self.send_rows(&first.rows)?;
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
            match self.receive()? {
                Up::Ready(r) if r.status == 0 => {
                    self.ready = true;
                    return Ok(());
                }
                Up::Ready(r) => bail!(
                    "the ECU refused the set-up: {}",
                    setup_refusal(r.status, r.detail)
                ),
                _ => self.counters.rejected += 1,
            }
        }
    }

    /// Writes the frame of the road `msg` on the route channel at the plan
    /// release `t_us` (µs), or, while a link fault of the route channel lasts, a
    /// forged, replayed or corrupted one in its place.
    fn send_route(&mut self, msg: &Down, t_us: u64) -> Result<()> {
        let fault = self.opts.link_fault.and_then(|f| {
            f.route_frames()
                .filter(|r| r.replaces(t_us, self.faulted))
                .map(|_| f.spec.kinds.nth(self.faulted))
        });
        let frame = self.faulty_frame(msg, fault, LinkChannel::Route)?;
        self.route
            .write_all(&frame)
            .context("the ECU closed its route channel")?;
        self.route_frames = self.route_frames.saturating_add(1);
        Ok(())
    }

    /// Sends rows of a window in `PathChunk` frames (the first starting at row 0).
    fn send_rows(&mut self, rows: &[[f64; 4]]) -> Result<()> {
        for f in path_chunks(rows) {
            self.send(&f)?;
        }
        Ok(())
    }

    /// The frame the ECU receives for this period's sensor frame `msg`: the
    /// frame itself, or, while a link fault of the sensor frames lasts, a forged,
    /// replayed or corrupted one in its place, or the frame after a run of noise
    /// (`Some(kind)`).
    fn sensor_frame(&mut self, msg: &Down, t_us: u64) -> Result<(Vec<u8>, Option<LinkFaultKind>)> {
        let fault = self
            .opts
            .link_fault
            .filter(|f| f.covers(t_us))
            .map(|f| f.spec.kinds.nth(self.faulted));
        let frame = self.faulty_frame(msg, fault, LinkChannel::Sensor)?;
        Ok((frame, fault))
    }

    /// `msg` encoded on `channel`'s stream as the link fault's `fault` makes it
    /// (module [`crate::pil::link_fault`]); a legitimate frame is kept for
    /// replays, a replaced one counted.
    fn faulty_frame(
        &mut self,
        msg: &Down,
        fault: Option<LinkFaultKind>,
        channel: LinkChannel,
    ) -> Result<Vec<u8>> {
        let (tx, history) = match channel {
            LinkChannel::Sensor => (&mut self.down_tx, &mut self.history),
            LinkChannel::Route => (&mut self.route_tx, &mut self.route_history),
        };
        let frame = match fault {
            // Noise goes before the legitimate frame itself (kept for replays).
            None | Some(LinkFaultKind::Noise) => {
                let frame = encode_frame(msg, &mut self.mac, tx)?;
                if history.len() == REPLAY_HISTORY_FRAMES {
                    history.pop_front();
                }
                history.push_back(frame.clone());
                frame
            }
            Some(LinkFaultKind::Forge) => {
                // Fresh (the next freshness value of the stream, not taken), its
                // tag under the forger's key.
                let mut fresh = *tx;
                encode_frame(msg, &mut self.forger, &mut fresh)?
            }
            Some(LinkFaultKind::Replay) => {
                let k = self.faulted as usize;
                match history.len() {
                    0 => bail!(
                        "--link-fault replay: no {} frame was sent before the fault to replay; start it later (--link-fault-at)",
                        channel.name()
                    ),
                    n => history[k % n].clone(),
                }
            }
            Some(LinkFaultKind::Corrupt) => {
                let mut frame = encode_frame(msg, &mut self.mac, tx)?;
                flip_bit(&mut frame, self.faulted);
                frame
            }
        };
        let frame = if fault == Some(LinkFaultKind::Noise) {
            [noise_run(), frame].concat()
        } else {
            frame
        };
        if let Some(kind) = fault {
            self.faulted += 1;
            self.injected.injected.count(kind.refusal());
        }
        Ok(frame)
    }

    /// One control period: sends the estimate at `t_us` (after a frame of the
    /// road at a plan release, if one waits), returns the ECU's answer.
    pub fn exchange(&mut self, est: &StateEstimate<f32>) -> Result<link::ActuationFrame> {
        if est.stamp_us.is_multiple_of(PLAN_PERIOD_US) {
            if let Some(f) = self.route_queue.pop_front() {
                self.route_releases.insert(est.stamp_us);
                self.send_route(&f, est.stamp_us)?;
                self.route
                    .flush()
                    .context("the ECU closed its route channel")?;
            }
        }
        self.seq = self.seq.wrapping_add(1);
        let msg = Down::Sensor(SensorFrame {
            seq: self.seq,
            estimate: *est,
            route_frames: self.route_frames,
        });
        let (frame, fault) = self.sensor_frame(&msg, est.stamp_us)?;
        self.write_down(&frame)?;
        loop {
            match self.receive()? {
                Up::Actuation(a) if a.seq == self.seq => {
                    self.judge_answer(&a, fault);
                    if let Some(p) = &a.plan {
                        if p.published {
                            self.active = plan_of(p);
                        }
                    }
                    return Ok(a);
                }
                Up::Actuation(a) if a.fault == link::FAULT_PANIC => {
                    bail!(
                        "the ECU panicked (it commanded zero torque, steering held at {:.3} rad, and stopped; its line is in {})",
                        a.delta_rad,
                        self.opts.work_dir.join("qemu.log").display()
                    )
                }
                Up::Actuation(a) if a.fault == link::FAULT_HARDFAULT => {
                    bail!(
                        "the ECU took a HardFault (a MemManage, BusFault or UsageFault escalated, or a HardFault proper: e.g. a stack overflow into flip-link's guard); it commanded zero torque, steering held at {:.3} rad, and stopped",
                        a.delta_rad
                    )
                }
                Up::Actuation(a) if a.fault == link::FAULT_NMI => {
                    bail!(
                        "the ECU took an NMI (the clock security system's: its crystal failed and the core fell back to its internal oscillator); it commanded zero torque, steering held at {:.3} rad, and stopped",
                        a.delta_rad
                    )
                }
                Up::Actuation(_) => self.counters.stale += 1,
                _ => self.counters.rejected += 1,
            }
        }
    }

    /// Counts what the ECU said of this period's sensor frame against what was
    /// sent: a replaced frame must be refused for its reason, a legitimate one
    /// accepted (after noise too: the run refused, the frame taken).
    fn judge_answer(&mut self, a: &link::ActuationFrame, fault: Option<LinkFaultKind>) {
        let refused = Refusal::from_code(a.sensor);
        match fault {
            Some(LinkFaultKind::Noise) if a.sensor == 0 => self.injected.refused_as_expected += 1,
            Some(LinkFaultKind::Noise) => self.injected.legitimate_refused += 1,
            Some(kind) if refused == Some(kind.refusal()) => self.injected.refused_as_expected += 1,
            Some(_) if a.sensor == 0 => self.injected.acted_on += 1,
            Some(_) => {}
            None if a.sensor != 0 => self.injected.legitimate_refused += 1,
            None => {}
        }
    }

    /// Ends the run: the ECU reports its stack high-water mark and its refused
    /// frames and exits; with the link's counters, host side, at the end.
    pub fn stop(mut self) -> Result<(DoneFrame, LinkCounters)> {
        self.send(&Down::Stop)?;
        let done = loop {
            match self.receive()? {
                Up::Done(d) => break d,
                _ => self.counters.rejected += 1,
            }
        };
        for _ in 0..100 {
            if self.child.try_wait()?.is_some() {
                break;
            }
            thread::sleep(Duration::from_millis(20));
        }
        Ok((done, self.counters))
    }

    /// The run's options.
    pub fn options(&self) -> &PilOptions {
        &self.opts
    }
}

impl QemuEcu {
    /// The record of a plan event, instructions from the ECU's clock ticks.
    pub fn activation_of(&self, p: &PlanEventFrame) -> PlanActivation {
        let instructions = self.opts.instructions(p.ticks);
        PlanActivation {
            activation: p.activation,
            release_us: p.release_us,
            finish_us: p.finish_us,
            instructions,
            cycles: instructions * self.opts.cycles_per_instruction,
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
            window_instructions: if p.window_ticks > 0 {
                self.opts.instructions(p.window_ticks)
            } else {
                0.0
            },
            route_frames: u32::from(self.route_releases.contains(&p.release_us)),
            max_validity_slack_rad: None,
        }
    }
}

impl Ecu<f32> for QemuEcu {
    fn control(&mut self, t_us: u64, est: &StateEstimate<f32>) -> Result<ControlOutput<f32>> {
        let mut e = *est;
        e.stamp_us = t_us;
        let frame = self.exchange(&e)?;
        let instructions = self.opts.instructions(frame.control_ticks);
        let mut plans = Vec::new();
        let mut skipped_releases = 0;
        if let Some(p) = &frame.plan {
            self.event_order
                .check(p.activation)
                .map_err(|e| anyhow!("{e}"))?;
            // Releases that fell while this activation ran, up to its end (the
            // route frames it received included), were skipped.
            skipped_releases = skipped_between(p.release_us, p.end_us, PLAN_PERIOD_US);
            if u64::from(p.ticks) > PLAN_BUDGET_CYCLES {
                self.tick_overruns.plan += 1;
            }
            self.plan_counts = p.timing.into();
            plans.push(self.activation_of(p));
        }
        // The previous activation's completion (its frame written), which this
        // frame reports (the first frame has no previous activation).
        let completion = self.last_release_us.map(|release_us| ControlCompletion {
            release_us,
            completed_us: release_us + u64::from(frame.previous_response_us),
        });
        if completion.is_some()
            && self
                .last_control_ticks
                .is_some_and(|t| u64::from(t) > CONTROL_BUDGET_CYCLES)
        {
            self.tick_overruns.control += 1;
        }
        self.last_control_ticks = Some(frame.control_ticks);
        // Control releases the ECU skipped: the gap to the last one it reported.
        let control_skipped_releases = match self.last_release_us {
            Some(last) => {
                (frame.release_us.saturating_sub(last) / CONTROL_PERIOD_US).saturating_sub(1) as u32
            }
            None => 0,
        };
        self.last_release_us = Some(frame.release_us);
        self.ecu_counts = Some(EcuCounts {
            plan: self.plan_counts,
            control: frame.control.into(),
            watchdog_trips: frame.watchdog_trips.into(),
            frames_refused: frame.refused,
        });
        Ok(ControlOutput {
            actuation: actuation_of(&frame),
            release_us: frame.release_us,
            sent_us: frame.sent_us,
            completion,
            control_skipped_releases,
            ecu_counts: self.ecu_counts,
            instructions,
            cycles: instructions * self.opts.cycles_per_instruction,
            plans,
            skipped_releases,
            friction_mu: None,
            sideslip_lag: None,
            car_estimate: None,
        })
    }

    fn active_plan(&self) -> &Plan<f32> {
        &self.active
    }

    fn reports_plan_states(&self) -> bool {
        // The plan events carry the nodes' positions only (`plan_of`).
        false
    }

    fn set_window(&mut self, w: &Window) -> Result<()> {
        // On the route channel, one frame per plan release, each announced by the
        // sensor frame after it. A window that comes while another is still on
        // its way replaces the frames not yet sent (its first chunk restarts the
        // ECU's staging).
        self.route_queue = path_chunks(&w.rows).collect();
        self.route_queue.push_back(Down::Window(link::WindowFrame {
            rows: w.rows.len() as u16,
            origin_m: w.origin_m as f32,
            closed: w.closed,
        }));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counts(auth: u32, replay: u32, corrupt: u32) -> RefusalCounts {
        RefusalCounts {
            auth,
            replay,
            corrupt,
        }
    }

    #[test]
    fn route_frames_are_judged_on_the_ecus_counts_by_reason() {
        let injected = InjectedFrames {
            injected: counts(1, 1, 1),
            ..InjectedFrames::default()
        };
        // (refused as expected, acted on, legitimate refused) on the ECU's counts.
        let judged = |ecu: RefusalCounts| {
            let mut j = injected;
            j.judge_by_counts(&ecu);
            (j.refused_as_expected, j.acted_on, j.legitimate_refused)
        };
        // Each refused for its reason.
        assert_eq!(judged(counts(1, 1, 1)), (3, 0, 0));
        // The replayed one not refused (taken), a legitimate frame refused as
        // forged instead.
        assert_eq!(judged(counts(2, 0, 1)), (2, 1, 1));
        // Nothing refused.
        assert_eq!(judged(RefusalCounts::new()), (0, 3, 0));
    }
}
