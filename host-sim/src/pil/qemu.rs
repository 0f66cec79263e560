//! Processor in the loop: the firmware's ECU application runs in QEMU
//! (`netduinoplus2`, an STM32F405 Cortex-M4F) and the simulator's plant closes the
//! loop with it, one sensor frame and one actuator frame per 10 ms control period.
//!
//! # Time
//!
//! QEMU runs with `-icount shift=N,sleep=off`: its virtual clock advances `2^N` ns
//! per executed instruction and jumps straight to the next timer when the CPU
//! sleeps, so the firmware's timers (RTIC's monotonic on SysTick, 168 MHz of
//! virtual time) are driven by what the firmware executes, not by the host. The
//! link is semihosting on two FIFOs (`ecu.down`, `ecu.up`): a semihosting call is
//! synchronous and takes no virtual time, so the host's own speed never shows in
//! the ECU's timeline and the run is deterministic. A UART would deliver bytes at
//! host-dependent virtual instants.
//!
//! The plant advances 10 ms between two sensor frames; the ECU's control task is
//! released by its own timer every 10 ms of virtual time and its plan task every
//! 100 ms; a plan takes effect when the ECU publishes it, so the firmware's real
//! execution time is what delays its plans. With `N = 4` an instruction takes
//! 16 ns of virtual time, i.e. 2.69 cycles at 168 MHz: above the cycles-per-
//! instruction bound of the timing report, so the PIL timeline is no faster than
//! the real ECU.
//!
//! # Frames
//!
//! See [`firmware::link`]: versioned, CRC-32, COBS-delimited postcard frames.
//! Set-up: `Config`, `PathChunk`s, `Obstacle`s, `Start` → `Ready`; then `Sensor`
//! → `Actuation` every period; `Stop` → `Done`. Garbled, short, wrong-version,
//! stale or out-of-order frames are refused and counted on both sides. The next
//! window of the road goes on a third FIFO (`ecu.route`), announced by the count
//! in the next sensor frame: the ECU's plan task reads it after it publishes.
//!
//! # Deadlines, counted twice
//!
//! Each actuation frame carries the control release it answers and its send
//! instant on the ECU's clock, each plan event its release, finish and end; the
//! host counts misses and skipped releases from these stamps, and budget
//! overruns from the measured ticks, as the driver does for any ECU. The ECU
//! counts them itself ([`firmware::deadline`]) and sends its counts in the same
//! frames; [`count_mismatches`] compares the two and `host-sim pil` fails when
//! they differ. The plant applies each actuation from the instant the ECU sent it
//! ([`crate::closed_loop::timeline`]).

use std::fs::{self, File};
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::thread;
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};
use firmware::link::{
    self, ConfigFrame, DoneFrame, Down, FrameReader, ObstacleFrame, PathChunkFrame, PlanEventFrame,
    SensorFrame, Up, MAX_FRAME_BYTES, PATH_CHUNK_ROWS,
};
use firmware::low_level::{Actuation, Mode};
use firmware::obstacles::MAX_VERTICES;
use firmware::plan::{Plan, PlanNode, PLAN_DT_S};
use firmware::state_estimate::StateEstimate;

use crate::closed_loop::ecu::{ControlOutput, Ecu, EcuCounts, EcuTaskCounts, SimulatedEcu};
use crate::closed_loop::plan_activation::{plan_status_name, PlanActivation};
use crate::closed_loop::summary::Summary;
use crate::closed_loop::timeline::{self, RunResult};
use crate::closed_loop::{self, SimOptions};
use crate::model::vehicle::VehicleParams;
use crate::world::route::{RouteFeeder, Window};
use crate::world::scenario::Scenario;
use firmware::deadline::{CONTROL_BUDGET_CYCLES, PLAN_BUDGET_CYCLES};
use firmware::tasks::{CONTROL_PERIOD_US, PLAN_PERIOD_US};

/// Releases of a task of period `period_us` skipped by an activation released at
/// `release_us` that ended at `end_us` (µs): those after its release and before
/// the first not yet past at its end (one exactly at the end is not past).
pub fn skipped_between(release_us: u64, end_us: u64, period_us: u64) -> u32 {
    let next_due = release_us + period_us;
    if end_us <= next_due {
        0
    } else {
        (end_us - next_due).div_ceil(period_us) as u32
    }
}

/// Where the ECU's own deadline counts differ from the host's: the summary's
/// misses and skipped releases (counted by the driver from the frames' stamps)
/// and the host's count of budget overruns on the ECU's clock; one line each,
/// empty when they agree (or when there is no ECU count).
pub fn count_mismatches(s: &Summary, ticks: &TickOverruns) -> Vec<String> {
    let pairs = [
        (
            "plan deadline misses",
            s.ecu_plan_deadline_misses,
            s.plan_deadline_misses,
        ),
        (
            "plan skipped releases",
            s.ecu_skipped_releases,
            s.plan_skipped_releases,
        ),
        (
            "plan budget overruns (ECU clock)",
            s.ecu_plan_budget_overruns,
            ticks.plan,
        ),
        (
            "control deadline misses",
            s.ecu_control_deadline_misses,
            s.control_deadline_misses,
        ),
        (
            "control skipped releases",
            s.ecu_control_skipped_releases,
            s.control_skipped_releases,
        ),
        (
            "control budget overruns (ECU clock)",
            s.ecu_control_budget_overruns,
            ticks.control,
        ),
    ];
    pairs
        .iter()
        .filter_map(|&(name, ecu, host)| match ecu {
            Some(e) if e != host => Some(format!("{name}: ECU {e}, host {host}")),
            _ => None,
        })
        .collect()
}

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
    /// Frames the host refused (garbled, short, wrong version, unexpected).
    pub rejected: u64,
    /// Actuation frames answering another sensor frame than the one sent.
    pub stale: u64,
}

/// The host's own count, from the frames' raw ticks, of the ECU's budget
/// overruns on the ECU's clock (its ticks of a task's own execution over the
/// budget in cycles), to compare with the ECU's (the summary's
/// `*_budget_overruns` are the host's estimate for the real part: instructions ×
/// cycles per instruction).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct TickOverruns {
    /// Plan activations whose ticks exceeded the plan budget.
    pub plan: u64,
    /// Control activations whose ticks exceeded the control budget.
    pub control: u64,
}

enum Incoming {
    Frame(Box<Up>),
    Bad,
    Closed,
}

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
    /// Route frames written since the last sensor frame (announced in the next).
    route_frames: u16,
    /// The last control release the ECU reported, µs.
    last_release_us: Option<u64>,
    /// The plan task's counts as of the last plan event.
    plan_counts: EcuTaskCounts,
    /// Budget overruns on the ECU's clock, counted by the host from the ticks.
    pub tick_overruns: TickOverruns,
    /// The ECU's own counts in the last actuation frame (response times included).
    pub ecu_counts: Option<EcuCounts>,
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

/// Reads frames from the up-link FIFO on a thread of its own.
fn spawn_reader(mut file: File) -> Receiver<Incoming> {
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
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
                    Some(Ok(frame)) => match link::decode::<Up>(frame) {
                        Ok(m) => Incoming::Frame(Box::new(m)),
                        Err(_) => Incoming::Bad,
                    },
                    Some(Err(_)) => Incoming::Bad,
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
                "the ECU application {} does not exist: build it with `cargo ecu`",
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
        let mut ecu = Self {
            child,
            down: BufWriter::new(down),
            up: spawn_reader(up),
            opts: opts.clone(),
            seq: 0,
            counters: LinkCounters::default(),
            active: Plan::zeroed(),
            route: BufWriter::new(route),
            route_frames: 0,
            last_release_us: None,
            plan_counts: Default::default(),
            tick_overruns: TickOverruns::default(),
            ecu_counts: None,
        };
        ecu.set_up(scenario, vehicle, sim)?;
        Ok(ecu)
    }

    fn send(&mut self, msg: &Down) -> Result<()> {
        let mut buf = [0u8; MAX_FRAME_BYTES];
        let n = link::encode(msg, &mut buf).map_err(|e| anyhow!("encoding a frame: {e:?}"))?;
        self.down
            .write_all(&buf[..n])
            .context("the ECU closed its link")?;
        Ok(())
    }

    fn receive(&mut self) -> Result<Up> {
        loop {
            self.down.flush().context("the ECU closed its link")?;
            match self
                .up
                .recv_timeout(Duration::from_secs_f64(self.opts.frame_timeout_s))
            {
                Ok(Incoming::Frame(m)) => return Ok(*m),
                Ok(Incoming::Bad) => self.counters.rejected += 1,
                Ok(Incoming::Closed) | Err(RecvTimeoutError::Disconnected) => {
                    let defmt = self.opts.work_dir.join("ecu.defmt");
                    bail!(
                        "the ECU stopped (QEMU exited); its log: {} (decode with `defmt-print -e {}`), QEMU's: {}",
                        defmt.display(),
                        self.opts.elf.display(),
                        self.opts.work_dir.join("qemu.log").display()
                    )
                }
                Err(RecvTimeoutError::Timeout) => bail!(
                    "no frame from the ECU within {} s of wall time: the firmware hangs",
                    self.opts.frame_timeout_s
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
        crate::closed_loop::ecu::SimulatedEcu::<f32>::new(scenario, vehicle, sim)?;
        if scenario.obstacles.len() > u8::MAX as usize {
            bail!(
                "{} obstacles: the link carries at most 255",
                scenario.obstacles.len()
            );
        }
        let first = RouteFeeder::new(&scenario.track)?.first();
        self.send(&Down::Config(ConfigFrame {
            vehicle: closed_loop::vehicle_config::<f32>(vehicle),
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
                Up::Ready(r) if r.status == 0 => return Ok(()),
                Up::Ready(r) => bail!(
                    "the ECU refused the set-up: {}",
                    setup_refusal(r.status, r.detail)
                ),
                _ => self.counters.rejected += 1,
            }
        }
    }

    /// Writes a frame on the route channel.
    fn send_route(&mut self, msg: &Down) -> Result<()> {
        let mut buf = [0u8; MAX_FRAME_BYTES];
        let n = link::encode(msg, &mut buf).map_err(|e| anyhow!("encoding a frame: {e:?}"))?;
        self.route
            .write_all(&buf[..n])
            .context("the ECU closed its route channel")?;
        self.route_frames = self.route_frames.saturating_add(1);
        Ok(())
    }

    /// The `PathChunk` frames of a window's rows (the first starting at row 0).
    fn chunks(rows: &[[f64; 4]]) -> impl Iterator<Item = Down> + '_ {
        rows.chunks(PATH_CHUNK_ROWS).enumerate().map(|(c, chunk)| {
            let mut f = PathChunkFrame {
                first: (c * PATH_CHUNK_ROWS) as u16,
                count: chunk.len() as u8,
                rows: [[0.0; 4]; PATH_CHUNK_ROWS],
            };
            for (dst, src) in f.rows.iter_mut().zip(chunk) {
                *dst = src.map(|x| x as f32);
            }
            Down::PathChunk(f)
        })
    }

    /// Sends rows of a window in `PathChunk` frames (the first starting at row 0).
    fn send_rows(&mut self, rows: &[[f64; 4]]) -> Result<()> {
        for f in Self::chunks(rows) {
            self.send(&f)?;
        }
        Ok(())
    }

    /// One control period: sends the estimate at `t_us`, returns the ECU's answer.
    pub fn exchange(&mut self, est: &StateEstimate<f32>) -> Result<link::ActuationFrame> {
        self.seq = self.seq.wrapping_add(1);
        let route_frames = std::mem::take(&mut self.route_frames);
        self.send(&Down::Sensor(SensorFrame {
            seq: self.seq,
            estimate: *est,
            route_frames,
        }))?;
        loop {
            match self.receive()? {
                Up::Actuation(a) if a.seq == self.seq => {
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
                Up::Actuation(_) => self.counters.stale += 1,
                _ => self.counters.rejected += 1,
            }
        }
    }

    /// Ends the run: the ECU reports its stack high-water mark and exits.
    pub fn stop(mut self) -> Result<DoneFrame> {
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
        Ok(done)
    }

    /// The run's options.
    pub fn options(&self) -> &PilOptions {
        &self.opts
    }
}

/// The plan of a plan event (positions only: what the consistency measure needs).
pub fn plan_of(p: &PlanEventFrame) -> Plan<f32> {
    let mut plan = Plan::zeroed();
    plan.stamp_us = p.release_us;
    plan.dt_s = PLAN_DT_S;
    for (n, xy) in plan.nodes.iter_mut().zip(p.nodes_xy.iter()) {
        *n = PlanNode {
            x_m: xy[0],
            y_m: xy[1],
            ..PlanNode::default()
        };
    }
    plan.v_heur_mps[0] = p.v_heur0_mps;
    plan
}

/// The actuation of an actuator frame (the fields the simulator uses).
pub fn actuation_of(a: &link::ActuationFrame) -> Actuation<f32> {
    Actuation {
        wheel_torque_nm: a.torque_nm,
        delta_rad: a.delta_rad,
        delta_ol_rad: a.delta_ol_rad,
        delta_cl_rad: a.delta_cl_rad,
        v_ref_mps: a.v_ref_mps,
        v_mps: 0.0,
        psi_ref_rad: 0.0,
        yaw_error_rad: 0.0,
        torque_total_nm: a.torque_nm.iter().sum(),
        torque_ff_nm: 0.0,
        plan_age_s: 0.0,
        mode: link::mode_from_code(a.mode).unwrap_or(Mode::Safe),
        new_plan: false,
    }
}

/// What a refused set-up means, and what to change.
pub fn setup_refusal(status: u8, detail: u16) -> String {
    use firmware::link::SetupError as E;
    match E::from_code(status) {
        Some(E::NoConfig) => "a frame came before the configuration (a simulator bug)".into(),
        Some(E::InvalidConfig) => {
            "the vehicle's numbers or the planner's friction are not finite and positive: check the vehicle file and --mu-planner".into()
        }
        Some(E::PathTooLong) => format!(
            "the track has more rows than the ECU's path holds ({detail}): resample the track to fewer points"
        ),
        Some(E::PathChunkOutOfRange) | Some(E::ObstacleOutOfRange) => {
            format!("a set-up frame arrived out of order (at {detail}): a simulator bug")
        }
        Some(E::MissingPathRow) => format!("track row {detail} never arrived"),
        Some(E::InvalidPathRow) => format!(
            "track row {detail} is not finite or has a negative width: fix the track file"
        ),
        Some(E::PathRejected) => {
            "the reference path refused the track (fewer than 3 distinct points or repeated points): fix the track file".into()
        }
        Some(E::TooManyObstacles) => format!("more obstacles than the ECU holds ({detail})"),
        Some(E::MissingObstacle) => format!("obstacle {detail} never arrived"),
        Some(E::InvalidObstacle) => format!(
            "obstacle {detail} was refused (no vertex, too many, or not finite): fix the obstacle file"
        ),
        Some(E::ObstacleBlocksRoad) => format!(
            "obstacle {detail} leaves no room to pass on either side: move it, make it narrower, or widen the track there"
        ),
        None => format!("unknown status {status} (detail {detail}): is the ECU application of another version?"),
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
            // Releases that fell while this activation ran, up to its end (its
            // window adoption included), were skipped.
            skipped_releases = skipped_between(p.release_us, p.end_us, PLAN_PERIOD_US);
            if u64::from(p.ticks) > PLAN_BUDGET_CYCLES {
                self.tick_overruns.plan += 1;
            }
            self.plan_counts = p.timing.into();
            plans.push(self.activation_of(p));
        }
        if u64::from(frame.control_ticks) > CONTROL_BUDGET_CYCLES {
            self.tick_overruns.control += 1;
        }
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
        });
        Ok(ControlOutput {
            actuation: actuation_of(&frame),
            release_us: frame.release_us,
            sent_us: frame.sent_us,
            control_skipped_releases,
            ecu_counts: self.ecu_counts,
            instructions,
            cycles: instructions * self.opts.cycles_per_instruction,
            plans,
            skipped_releases,
            friction_mu: None,
        })
    }

    fn active_plan(&self) -> &Plan<f32> {
        &self.active
    }

    fn reports_plan_states(&self) -> bool {
        // The plan events carry the nodes' positions only (`plan_of`).
        false
    }

    fn set_window(&mut self, _t_us: u64, w: &Window) -> Result<()> {
        // On the route channel, announced by the next sensor frame.
        for f in Self::chunks(&w.rows) {
            self.send_route(&f)?;
        }
        self.send_route(&Down::Window(link::WindowFrame {
            rows: w.rows.len() as u16,
            origin_m: w.origin_m as f32,
            closed: w.closed,
        }))?;
        self.route
            .flush()
            .context("the ECU closed its route channel")
    }
}

/// `host-sim pil`'s command line: `run`'s ([`crate::commands::run::RunCommand`]: the same
/// scenario options, refused where PIL cannot apply them), and how to run the ECU.
#[derive(Debug, Clone, clap::Args)]
pub struct PilCommand {
    /// The scenario and outputs, as for `run` (`--precision` must stay f32 and
    /// `--ecu-mhz` 168: the ECU's own clock times the run).
    #[command(flatten)]
    pub run: crate::commands::run::RunCommand,
    /// How the ECU runs.
    #[command(flatten)]
    pub ecu: PilEcuArgs,
}

/// How `host-sim pil` runs the ECU.
#[derive(Debug, Clone, clap::Args)]
pub struct PilEcuArgs {
    /// The ECU application (build it with `cargo ecu`).
    #[arg(long, default_value = "target/thumbv7em-none-eabihf/release/ecu")]
    pub elf: PathBuf,
    /// QEMU's `-icount shift`: an instruction takes 2^shift ns of the ECU's virtual
    /// time (4: 16 ns, 2.69 cycles at 168 MHz, above the CPI bound).
    #[arg(long, default_value_t = 4)]
    pub icount_shift: u32,
    /// QEMU executable.
    #[arg(long, default_value = "qemu-system-arm")]
    pub qemu: PathBuf,
    /// Cycles per instruction that turn measured instructions into cycles (the
    /// timing report's bound).
    #[arg(long, default_value_t = closed_loop::DEFAULT_CPI_BOUND)]
    pub cpi: f64,
    /// Also write QEMU's execution trace here (for `host-sim wcet`; large).
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// Skip the comparison with the in-process run.
    #[arg(long)]
    pub no_compare: bool,
    /// Longest wall time to wait for one frame, s.
    #[arg(long, default_value_t = 60.0)]
    pub frame_timeout: f64,
    /// Fail when the simulator's cost model underestimates a measured plan
    /// activation by more than this, % (CI's check that the model stays honest).
    #[arg(long)]
    pub max_model_underestimate_pct: Option<f64>,
}

impl PilCommand {
    /// The PIL run's settings (one value of each scenario option, checked).
    pub fn resolve(&self) -> Result<PilArgs> {
        let e = self.ecu.clone();
        Ok(PilArgs {
            run: self.run.resolve("pil")?,
            elf: e.elf,
            icount_shift: e.icount_shift,
            qemu: e.qemu,
            cpi: e.cpi,
            trace: e.trace,
            no_compare: e.no_compare,
            frame_timeout: e.frame_timeout,
            max_model_underestimate_pct: e.max_model_underestimate_pct,
        })
    }
}

/// A PIL run's settings: the run's ([`crate::commands::run::RunArgs`]) and how to run the ECU
/// ([`PilEcuArgs`] has the meanings); what `pil`'s command line resolves to, or what
/// a program builds (`wcet`).
#[derive(Debug, Clone)]
pub struct PilArgs {
    /// The scenario and outputs.
    pub run: crate::commands::run::RunArgs,
    /// The ECU application.
    pub elf: PathBuf,
    /// QEMU's `-icount shift`.
    pub icount_shift: u32,
    /// QEMU executable.
    pub qemu: PathBuf,
    /// Cycles per instruction.
    pub cpi: f64,
    /// QEMU's execution trace, if wanted.
    pub trace: Option<PathBuf>,
    /// Skip the comparison with the in-process run.
    pub no_compare: bool,
    /// Longest wall time to wait for one frame, s.
    pub frame_timeout: f64,
    /// Largest underestimate of the cost model allowed, %.
    pub max_model_underestimate_pct: Option<f64>,
}

/// The first difference between the PIL trajectory and the in-process one.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Comparison {
    /// Log rows compared (10 ms each).
    pub rows_compared: usize,
    /// The two trajectories are equal bit for bit on every compared row.
    pub identical: bool,
    /// Time of the first differing row, s.
    pub first_divergence_s: Option<f64>,
    /// Why, as far as the activations tell.
    pub cause: String,
}

/// What `host-sim pil` adds to `run`'s outputs (`pil.json`).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PilReport {
    /// QEMU's `-icount shift`.
    pub icount_shift: u32,
    /// Virtual time per instruction, ns.
    pub ns_per_instruction: f64,
    /// The ECU application run.
    pub elf: String,
    /// Deepest stack use seen on the ECU (painted stack), bytes.
    pub stack_high_water_bytes: u32,
    /// The ECU's stack region, bytes.
    pub stack_size_bytes: u32,
    /// Frames the ECU refused.
    pub ecu_rejected_frames: u32,
    /// Frames the host refused.
    pub host_rejected_frames: u64,
    /// Actuation frames answering an older sensor frame.
    pub stale_frames: u64,
    /// Largest control activation, instructions.
    pub control_max_instructions: f64,
    /// Median control activation, instructions.
    pub control_p50_instructions: f64,
    /// Largest plan activation, instructions.
    pub plan_max_instructions: f64,
    /// Largest warm (one-pass) plan activation, instructions.
    pub warm_max_instructions: f64,
    /// Largest cold-start plan activation, instructions.
    pub cold_max_instructions: f64,
    /// The simulator's cost model against the measurements.
    pub model_error: crate::closed_loop::cost_model::ModelError,
    /// The cost model refitted on this run's activations.
    pub refit: Option<crate::closed_loop::cost_model::CostModel>,
    /// Against the in-process run (f32, same inputs).
    pub comparison: Option<Comparison>,
    /// The host's count of budget overruns on the ECU's clock (from the frames'
    /// ticks), beside the ECU's own (`summary.json`'s `ecu_*_budget_overruns`).
    pub tick_overruns: TickOverruns,
    /// Where the ECU's own deadline counts differ from the host's (empty: they
    /// agree; otherwise `host-sim pil` fails).
    pub count_mismatches: Vec<String>,
    /// The ECU's own counts at the end of the run, per task: releases, misses,
    /// skipped releases, budget overruns, largest response time (µs); watchdog
    /// trips.
    pub ecu_counts: Option<EcuCounts>,
    /// Wall time of the PIL run, s.
    pub wall_s: f64,
}

/// Compares the PIL run with the in-process one, row by row.
pub fn compare(pil: &RunResult, host: &RunResult) -> Comparison {
    let n = pil.log.len().min(host.log.len());
    let first = (0..n).find(|&i| {
        let (a, b) = (&pil.log[i], &host.log[i]);
        a.x_m.to_bits() != b.x_m.to_bits()
            || a.y_m.to_bits() != b.y_m.to_bits()
            || a.psi_rad.to_bits() != b.psi_rad.to_bits()
            || a.v_mps.to_bits() != b.v_mps.to_bits()
            || a.delta_rad.to_bits() != b.delta_rad.to_bits()
    });
    let Some(i) = first else {
        return Comparison {
            rows_compared: n,
            identical: pil.log.len() == host.log.len(),
            first_divergence_s: None,
            cause: if pil.log.len() == host.log.len() {
                "none: identical bit for bit".into()
            } else {
                format!("equal on the first {n} rows; the runs ended at different times")
            },
        };
    };
    let t_us = (pil.log[i].t_s * 1e6).round() as u64;
    // Publication slot: the first control instant at or after the finish.
    let slot = |a: &PlanActivation| a.finish_us.div_ceil(10_000) * 10_000;
    let cause = pil
        .plan_activations
        .iter()
        .zip(host.plan_activations.iter())
        .find(|(p, h)| {
            p.release_us != h.release_us
                || p.status != h.status
                || p.published != h.published
                || slot(p) != slot(h)
        })
        .filter(|(p, _)| p.release_us <= t_us)
        .map(|(p, h)| {
            if p.status != h.status {
                format!(
                    "plan released at {:.1} s: the ECU's MPC returned {} and the host's {} (f32 arithmetic differs between the targets)",
                    p.release_us as f64 * 1e-6, p.status, h.status
                )
            } else {
                format!(
                    "plan released at {:.1} s was published at {:.1} ms on the ECU (measured: {:.0} instructions) and at {:.1} ms by the cost model ({:.0} instructions): a different 10 ms control period",
                    p.release_us as f64 * 1e-6,
                    (slot(p) - p.release_us) as f64 * 1e-3,
                    p.instructions,
                    (slot(h) - h.release_us) as f64 * 1e-3,
                    h.instructions
                )
            }
        })
        .unwrap_or_else(|| {
            // Same outcome and same publication period: compare the plans themselves.
            let t_div = pil.log[i].t_s;
            let diff = pil.plans.iter().filter(|p| p.t_publish_s <= t_div).find_map(|p| {
                let h = host
                    .plans
                    .iter()
                    .find(|h| (h.t_release_s - p.t_release_s).abs() < 1e-9)?;
                let d = p
                    .xy
                    .iter()
                    .zip(h.xy.iter())
                    .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
                    .fold(0.0f64, f64::max);
                (d > 0.0).then_some((p.t_release_s, d))
            });
            match diff {
                Some((t, d)) => format!(
                    "the plan released at {t:.1} s has the same QP work counters and publication period on both, but its nodes differ by up to {d:.3} m: the same f32 code gives different results on the Cortex-M4F and on the host (rounding of a step both compute; not a timing difference)"
                ),
                None => "every plan published so far is the same on both (positions bit for bit), so the control task's f32 results differ between the Cortex-M4F and the host (rounding in a step both compute; not a timing difference)".into(),
            }
        });
    Comparison {
        rows_compared: n,
        identical: false,
        first_divergence_s: Some(pil.log[i].t_s),
        cause,
    }
}

use crate::closed_loop::cost_model::percentile;

/// Refuses what a PIL run cannot apply, saying why and where it applies: the
/// in-process ECU's arithmetic and clock, and the disturbances applied around the
/// in-process ECU (noise, delay, and every fault but those [`FaultKind::pil`] allows).
///
/// [`FaultKind::pil`]: crate::world::faults::FaultKind::pil
pub fn check_pil_args(args: &PilArgs) -> Result<()> {
    if args.run.precision != closed_loop::Precision::F32 {
        bail!("--precision: the ECU computes in f32; PIL runs are f32 only");
    }
    if (args.run.ecu_mhz - ECU_CLOCK_HZ / 1e6).abs() > 1e-9 {
        bail!("--ecu-mhz: in PIL the ECU's own (virtual) clock times the run; use --icount-shift to change the time per instruction");
    }
    if !(1..=10).contains(&args.icount_shift) {
        bail!(
            "--icount-shift must be in 1..=10 (2^shift ns per instruction), got {}",
            args.icount_shift
        );
    }
    if !(args.cpi.is_finite() && args.cpi > 0.0) {
        bail!(
            "--cpi must be a positive number of cycles per instruction, got {}",
            args.cpi
        );
    }
    let c = &args.run.conditions;
    if c.noise.0 != 0.0 || c.delay_ms != 0.0 {
        bail!("--noise and --delay-ms disturb the estimate around the in-process ECU; PIL does not apply them: use `host-sim run` or `host-sim sweep`");
    }
    if !c.fault.applies_to_pil() {
        let pil: Vec<String> = crate::world::faults::FAULT_KINDS
            .iter()
            .filter(|k| k.pil)
            .map(|k| k.usage())
            .collect();
        bail!(
            "--fault {}: PIL cannot apply it (dropouts, the steering rate limit and the late obstacle act around the in-process ECU; an overrun changes the modelled ECU's clock, and in PIL the ECU's own clock times the run); PIL takes {}; use `host-sim run` or `host-sim sweep`",
            c.fault,
            pil.join(", ")
        );
    }
    Ok(())
}

/// `host-sim pil` from its command line.
pub fn command(cmd: &PilCommand) -> Result<()> {
    run(&cmd.resolve()?)
}

/// `host-sim pil`.
pub fn run(args: &PilArgs) -> Result<()> {
    check_pil_args(args)?;
    // The disturbances are none (checked above): the ECU gets the estimate as is.
    let crate::world::set_up::SetUp {
        scenario,
        nominal: vehicle,
        plant_car,
        mut opts,
        ..
    } = crate::commands::run::prepare(&args.run)?;
    opts.cycles_per_instruction = args.cpi;
    let pil_opts = PilOptions {
        elf: args.elf.clone(),
        qemu: args.qemu.clone(),
        icount_shift: args.icount_shift,
        work_dir: args.run.out.join("ecu"),
        frame_timeout_s: args.frame_timeout,
        cycles_per_instruction: args.cpi,
        trace: args.trace.clone(),
    };
    let wall = std::time::Instant::now();
    let mut ecu = QemuEcu::start(&scenario, &vehicle, &opts, &pil_opts)?;
    let bar = indicatif::ProgressBar::new(opts.max_duration_s.ceil() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} PIL: simulated {pos} s  {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
    );
    let result = timeline::run_with(&scenario, &plant_car, &opts, &mut ecu, |t, d| {
        bar.set_position(t as u64);
        bar.set_message(format!("{d:.0} m driven"));
    });
    bar.finish_and_clear();
    let counters = ecu.counters;
    let tick_overruns = ecu.tick_overruns;
    let ecu_counts = ecu.ecu_counts;
    let done = match &result {
        Ok(_) => Some(ecu.stop()?),
        Err(_) => None,
    };
    let result = result?;
    let done = done.unwrap_or(DoneFrame {
        stack_high_water_bytes: 0,
        stack_size_bytes: 0,
        rejected_frames: 0,
    });
    let wall_s = wall.elapsed().as_secs_f64();
    crate::output::run_files::write_outputs(&args.run.out, &scenario, &result, !args.run.no_plots)?;

    let plans = &result.plan_activations;
    let work: Vec<crate::closed_loop::cost_model::Counters> =
        plans.iter().map(Into::into).collect();
    let max_of = |f: &dyn Fn(&PlanActivation) -> bool| {
        plans
            .iter()
            .filter(|a| f(a))
            .map(|a| a.instructions)
            .fold(0.0f64, f64::max)
    };
    let comparison = if args.no_compare {
        None
    } else {
        let mut host_ecu = SimulatedEcu::<f32>::new(&scenario, &vehicle, &opts)?;
        let host = timeline::run_with(&scenario, &plant_car, &opts, &mut host_ecu, |_, _| {})?;
        // The in-process run beside it, for a look at any divergence.
        crate::output::run_files::write_outputs(
            &args.run.out.join("host"),
            &scenario,
            &host,
            false,
        )?;
        Some(compare(&result, &host))
    };
    let report = PilReport {
        icount_shift: args.icount_shift,
        ns_per_instruction: pil_opts.ns_per_instruction(),
        elf: args.elf.display().to_string(),
        stack_high_water_bytes: done.stack_high_water_bytes,
        stack_size_bytes: done.stack_size_bytes,
        ecu_rejected_frames: done.rejected_frames,
        host_rejected_frames: counters.rejected,
        stale_frames: counters.stale,
        control_max_instructions: percentile(&result.control_instructions, 1.0),
        control_p50_instructions: percentile(&result.control_instructions, 0.5),
        plan_max_instructions: max_of(&|_| true),
        warm_max_instructions: max_of(&|a| a.passes == 1),
        cold_max_instructions: max_of(&|a| a.passes > 1),
        model_error: opts.cost_model.error_on(&work),
        refit: crate::closed_loop::cost_model::CostModel::fit(
            &work,
            percentile(&result.control_instructions, 1.0),
        ),
        comparison,
        tick_overruns,
        count_mismatches: count_mismatches(&result.summary, &tick_overruns),
        ecu_counts,
        wall_s,
    };
    let pil_path = args.run.out.join("pil.json");
    fs::write(&pil_path, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("cannot write {}", pil_path.display()))?;

    let s = &result.summary;
    println!("{}", crate::commands::run::summary_line(&scenario, s));
    println!("{}", crate::commands::run::friction_line(s));
    if !s.completed {
        println!("stopped: {}", s.stop_reason);
    }
    println!(
        "ECU (QEMU, {} ns/instruction): plan max {:.0} instructions (warm {:.0}, cold {:.0}), p50 {:.0}; control max {:.0}; stack high-water {} of {} B; frames refused: ECU {}, host {}, stale {}",
        report.ns_per_instruction,
        report.plan_max_instructions,
        report.warm_max_instructions,
        report.cold_max_instructions,
        s.plan_p50_instructions,
        report.control_max_instructions,
        report.stack_high_water_bytes,
        report.stack_size_bytes,
        report.ecu_rejected_frames,
        report.host_rejected_frames,
        report.stale_frames,
    );
    let e = &report.model_error;
    println!(
        "cost model vs ECU over {} plan activations: |error| max {:.1} %, p99 {:.1} %, largest underestimate {:.1} %",
        e.activations, e.max_abs_pct, e.p99_abs_pct, e.max_under_pct
    );
    if let Some(c) = &report.comparison {
        match c.first_divergence_s {
            None => println!("against the in-process run: {}", c.cause),
            Some(t) => println!(
                "against the in-process run: first divergence at {t:.2} s: {}",
                c.cause
            ),
        }
    }
    let opt = |x: Option<u64>| x.map_or("-".to_string(), |v| v.to_string());
    println!(
        "deadlines, ECU's own count / host's: plan misses {} / {}, skipped releases {} / {}, budget overruns (ECU clock) {} / {}; control misses {} / {}, skipped releases {} / {}, budget overruns (ECU clock) {} / {}; watchdog trips {}; largest response times on the ECU: plan {} µs, control {} µs",
        opt(s.ecu_plan_deadline_misses),
        s.plan_deadline_misses,
        opt(s.ecu_skipped_releases),
        s.plan_skipped_releases,
        opt(s.ecu_plan_budget_overruns),
        tick_overruns.plan,
        opt(s.ecu_control_deadline_misses),
        s.control_deadline_misses,
        opt(s.ecu_control_skipped_releases),
        s.control_skipped_releases,
        opt(s.ecu_control_budget_overruns),
        tick_overruns.control,
        opt(s.ecu_watchdog_trips),
        opt(ecu_counts.map(|c| c.plan.max_response_us)),
        opt(ecu_counts.map(|c| c.control.max_response_us)),
    );
    println!(
        "PIL wall time {:.1} s; wrote {}",
        wall_s,
        args.run.out.display()
    );
    if !report.count_mismatches.is_empty() {
        bail!(
            "the ECU's own deadline counts differ from the host's: {} (pil.json: count_mismatches)",
            report.count_mismatches.join("; ")
        );
    }
    if let Some(limit) = args.max_model_underestimate_pct {
        if e.max_under_pct > limit {
            bail!(
                "the cost model underestimates a measured plan activation by {:.1} % (> {limit} %): refit it (`host-sim wcet` writes cost_model.json) and update CostModel::default",
                e.max_under_pct
            );
        }
    }
    Ok(())
}
