//! The binary you flash (`cargo ecu-board`: the ECU application over USART1,
//! `defmt` over RTT, no semihosting), checked on its ELF and run in QEMU:
//!
//! * it holds no semihosting instruction (`bkpt`) anywhere, where the lock-step
//!   build (`cargo ecu`) holds them;
//! * in QEMU's `netduinoplus2` (no semihosting option, its first `-serial` on
//!   USART1) it boots through the clock set-up's no-RCC path, takes an
//!   authenticated set-up over the emulated USART and answers `Ready`, answers
//!   sensor frames with authenticated actuation frames (interrupt-driven both
//!   ways), and ends with `Done` when told to stop.
//!
//! QEMU runs without `-icount` here: the ECU's clock follows the host's, so the
//! exchange is not in lock-step (that is the lock-step build's PIL). The host
//! sends each sensor frame once the previous one was answered; the periods in
//! between are answered as dropouts (`SENSOR_MISSING`), which the test counts but
//! does not judge.
//!
//! They need the binaries built first (`cargo ecu-board`, and `cargo ecu` for the
//! lock-step one) and `qemu-system-arm`, so they are ignored by `cargo test`;
//! `.ci/run` builds them and runs `cargo test -p host-sim --test ecu_board -- --ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::thread;
use std::time::{Duration, Instant};

use firmware::link::{
    self, ActuationFrame, Authenticator, ConfigFrame, Down, FrameError, FrameReader, LinkMac,
    SensorFrame, Stream, Up, Verifier, LINK_KEY, MAX_FRAME_BYTES,
};
use firmware::state_estimate::StateEstimate;
use host_sim::closed_loop::SimOptions;
use host_sim::model::vehicle::{vehicle_config, VehicleParams};
use host_sim::pil::frames::path_chunks;
use host_sim::world::route::RouteFeeder;
use host_sim::world::scenario::Scenario;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn board_elf() -> PathBuf {
    let elf = host_sim::pil::built_ecu_board_elf(&root());
    assert!(
        elf.exists(),
        "build the flashed ECU binary first: cargo ecu-board ({} is missing)",
        elf.display()
    );
    elf
}

/// The instructions of `elf`'s disassembly (`llvm-objdump -d`) whose mnemonic is
/// `bkpt`, one line each.
fn bkpt_lines(elf: &Path) -> Vec<String> {
    let text = host_sim::wcet::stack::disassemble(elf)
        .expect("llvm-objdump (rustup component add llvm-tools)");
    text.lines()
        .filter(|l| {
            // `<address>: <mnemonic> <operands>` (no raw bytes: --no-show-raw-insn).
            l.split_once(':')
                .and_then(|(_, rest)| rest.split_whitespace().next())
                .is_some_and(|m| m == "bkpt")
        })
        .map(str::to_string)
        .collect()
}

#[test]
#[ignore = "needs `cargo ecu-board` and `cargo ecu` first (.ci/run)"]
fn the_flashed_binary_holds_no_bkpt_and_the_lockstep_one_does() {
    let board = board_elf();
    let text = host_sim::wcet::stack::disassemble(&board).unwrap();
    // The check reads the real disassembly: the link's interrupt handler and the
    // fault handlers are in it.
    for symbol in ["<USART1>:", "<HardFault>:", "<NonMaskableInt>:", "<main>:"] {
        assert!(
            text.contains(symbol),
            "no {symbol} in the disassembly of {}",
            board.display()
        );
    }
    let found = bkpt_lines(&board);
    assert!(
        found.is_empty(),
        "the flashed binary {} holds {} semihosting/breakpoint instructions (bkpt), which fault on a board without a debugger:\n{}",
        board.display(),
        found.len(),
        found.join("\n")
    );
    // The same check finds them in the lock-step build, which talks through
    // semihosting (so it can fail).
    let lockstep = host_sim::pil::built_ecu_elf(&root());
    if lockstep.exists() {
        let found = bkpt_lines(&lockstep);
        assert!(
            found.iter().any(|l| l.contains("0xab")),
            "the lock-step build {} holds no `bkpt 0xab`: the check does not see semihosting",
            lockstep.display()
        );
    }
}

/// What the reader thread passes on: the first byte (the ECU's receiver is on),
/// a frame from the ECU, verified, or a refusal.
enum FromEcu {
    Listening,
    Frame(Box<Up>),
    Refused(FrameError),
}

/// The flashed ECU in QEMU with its USART1 on QEMU's stdin/stdout.
struct BoardEcu {
    child: Child,
    stdin: ChildStdin,
    frames: Receiver<FromEcu>,
    mac: LinkMac,
    down: Authenticator,
}

impl Drop for BoardEcu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl BoardEcu {
    fn start(elf: &Path) -> Self {
        let mut child = Command::new("qemu-system-arm")
            .args(["-cpu", "cortex-m4", "-machine", "netduinoplus2"])
            // No semihosting option: a `bkpt` would fault. The first serial port is
            // the SoC's USART1, the link's.
            .args(["-display", "none", "-monitor", "none", "-serial", "stdio"])
            // ECU_BOARD_QEMU_LOG=FILE: QEMU's log of interrupts, unimplemented
            // devices and guest errors there (by hand, when it fails).
            .args(
                std::env::var_os("ECU_BOARD_QEMU_LOG")
                    .into_iter()
                    .flat_map(|f| ["-d".into(), "int,unimp,guest_errors".into(), "-D".into(), f]),
            )
            .arg("-kernel")
            .arg(elf)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("starting qemu-system-arm (apt-get install qemu-system-arm)");
        let stdin = child.stdin.take().unwrap();
        let mut stdout = child.stdout.take().unwrap();
        let (tx, frames) = mpsc::channel();
        thread::spawn(move || {
            let mut mac = LinkMac::new(&LINK_KEY);
            let mut up = Verifier::new(Stream::Up);
            let mut reader: FrameReader<MAX_FRAME_BYTES> = FrameReader::new();
            let mut buf = [0u8; 4096];
            let mut first = true;
            while let Ok(n) = stdout.read(&mut buf) {
                if n == 0 {
                    return;
                }
                if std::mem::take(&mut first) && tx.send(FromEcu::Listening).is_err() {
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
                    if tx.send(got).is_err() {
                        return;
                    }
                }
            }
        });
        Self {
            child,
            stdin,
            frames,
            mac: LinkMac::new(&LINK_KEY),
            down: Authenticator::new(Stream::Down),
        }
    }

    /// Sends `msg` on the control channel's down stream, authenticated.
    fn send(&mut self, msg: &Down) {
        let mut buf = [0u8; MAX_FRAME_BYTES];
        let n = link::encode(msg, &mut self.mac, &mut self.down, &mut buf).unwrap();
        self.stdin.write_all(&buf[..n]).unwrap();
        self.stdin.flush().unwrap();
    }

    /// The next frame from the ECU within `timeout`.
    fn next(&self, timeout: Duration) -> FromEcu {
        self.frames
            .recv_timeout(timeout)
            .unwrap_or_else(|e| panic!("no frame from the ECU within {timeout:?} ({e})"))
    }
}

#[test]
#[ignore = "needs `cargo ecu-board` first and qemu-system-arm (.ci/run)"]
fn the_flashed_binary_exchanges_authenticated_frames_over_usart1_in_qemu() {
    let mut ecu = BoardEcu::start(&board_elf());
    // The ECU booted (the clock set-up's no-RCC path, the stack painted) and
    // turned its receiver on: its first byte, an empty frame.
    assert!(
        matches!(ecu.next(Duration::from_secs(30)), FromEcu::Listening),
        "the ECU's first byte"
    );

    // The set-up: the paper track's first window of the road, the default car,
    // no obstacles; written straight after one another (QEMU's USART holds the
    // bytes back while the ECU's polled set-up decodes a frame).
    let scenario = Scenario::paper(false);
    let vehicle = VehicleParams::default();
    let first = RouteFeeder::new(&scenario.track).unwrap().first();
    ecu.send(&Down::Config(ConfigFrame {
        vehicle: vehicle_config::<f32>(&vehicle),
        mu_planner: SimOptions::default().mu_planner as f32,
        closed: first.closed,
        path_rows: first.rows.len() as u16,
        obstacles: 0,
    }));
    for chunk in path_chunks(&first.rows) {
        ecu.send(&chunk);
    }
    ecu.send(&Down::Start);
    // Its first frame: Ready.
    let ready = match ecu.next(Duration::from_secs(30)) {
        FromEcu::Frame(m) => match *m {
            Up::Ready(r) => r,
            other => panic!("before Ready the ECU sent {other:?}"),
        },
        FromEcu::Refused(e) => panic!("a frame of the ECU was refused before Ready: {e:?}"),
        FromEcu::Listening => unreachable!("one Listening"),
    };
    // Status 0: the set-up accepted, and the clock set-up did not fail (QEMU's
    // RCC reads 0: the no-RCC path, `ClockSource::Fixed`).
    assert_eq!(
        (ready.status, ready.detail),
        (0, 0),
        "the ECU refused the set-up: {}",
        host_sim::pil::frames::setup_refusal(ready.status, ready.detail)
    );

    // Driving: one sensor frame at a time, at the start pose and speed, the next
    // sent once the ECU answered the previous one (its seq in an actuation frame).
    let [x, y, psi] = scenario.start_pose;
    let frames = 40u32;
    let mut answered: Vec<ActuationFrame> = Vec::new();
    let mut missing = 0u32;
    let mut others = 0u32;
    let mut plan_events = 0u32;
    let mut planned = 0u32;
    let start = Instant::now();
    for seq in 1..=frames {
        let est = StateEstimate {
            stamp_us: u64::from(seq) * 10_000,
            x_m: x as f32,
            y_m: y as f32,
            psi_rad: psi as f32,
            vx_mps: scenario.initial_speed_mps as f32,
            ..StateEstimate::zeroed()
        };
        ecu.send(&Down::Sensor(SensorFrame {
            seq,
            estimate: est,
            route_frames: 0,
        }));
        loop {
            match ecu.next(Duration::from_secs(10)) {
                FromEcu::Refused(e) => panic!("an ECU frame was refused by the host: {e:?}"),
                FromEcu::Listening => unreachable!("one Listening"),
                FromEcu::Frame(m) => match *m {
                    Up::Actuation(a) => {
                        if let Some(p) = &a.plan {
                            plan_events += 1;
                            planned += u32::from(p.published);
                        }
                        if a.sensor == link::SENSOR_MISSING {
                            missing += 1;
                            continue;
                        }
                        assert_eq!(a.sensor, 0, "sensor frame {seq} refused: {a:?}");
                        assert_eq!(a.seq, seq, "the answer to sensor frame {seq}: {a:?}");
                        answered.push(a);
                        break;
                    }
                    _ => others += 1,
                },
            }
        }
    }
    let elapsed = start.elapsed();
    ecu.send(&Down::Stop);
    let done = loop {
        match ecu.next(Duration::from_secs(10)) {
            FromEcu::Frame(m) => match *m {
                Up::Done(d) => break d,
                Up::Actuation(a) if a.sensor == link::SENSOR_MISSING => missing += 1,
                other => panic!("after Stop the ECU sent {other:?}"),
            },
            FromEcu::Refused(e) => panic!("an ECU frame was refused by the host: {e:?}"),
            FromEcu::Listening => unreachable!("one Listening"),
        }
    };
    eprintln!(
        "flashed ECU over USART1 in QEMU: {} sensor frames answered in {:.2} s, {missing} dropout answers (no frame at the release), {plan_events} plan events ({planned} published), {others} other frames; Done: stack {} of {} B, {} frames refused",
        answered.len(),
        elapsed.as_secs_f64(),
        done.stack_high_water_bytes,
        done.stack_size_bytes,
        done.rejected_frames
    );
    assert_eq!(answered.len(), frames as usize);
    assert_eq!(
        others, 0,
        "frames other than actuation frames while driving"
    );
    // Before the first plan the control task has none to follow (InvalidPlan:
    // the controlled stop); from the answer after the one that reported the first
    // published plan, it follows the ECU's plan, without a fault.
    let first_plan = answered
        .iter()
        .position(|a| a.plan.is_some_and(|p| p.published))
        .expect("no published plan reported");
    for a in &answered[..=first_plan] {
        assert!(
            a.fault == 0 || link::fault_name(a.fault) == "InvalidPlan",
            "before the first plan: {a:?}"
        );
    }
    for a in &answered[first_plan + 1..] {
        assert_eq!(a.fault, 0, "a fault after the first plan: {a:?}");
        assert!(
            a.v_ref_mps > 0.0,
            "no reference speed after the first plan: {a:?}"
        );
    }
    for a in &answered {
        assert!(
            a.torque_nm
                .iter()
                .chain([&a.delta_rad, &a.v_ref_mps])
                .all(|v| v.is_finite()),
            "a non-finite actuation: {a:?}"
        );
        assert_eq!(
            a.refused,
            link::RefusalCounts::new(),
            "the ECU refused frames: {a:?}"
        );
    }
    // The plan task ran on the estimates (a plan event reaches the host in the
    // control task's frames) and the ECU refused nothing.
    assert!(
        plan_events > 0,
        "no plan event in {} actuation frames",
        answered.len()
    );
    assert_eq!(done.rejected_frames, 0);
    assert!(
        done.stack_high_water_bytes > 0 && done.stack_high_water_bytes <= done.stack_size_bytes
    );
}
