//! Tests of the ECU ↔ simulator frames (`firmware::link`): round trips, sizes,
//! refusal of corrupted, truncated, foreign and garbage frames, stream recovery,
//! sequence checks and the status codes.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::link::*;
use firmware::low_level::{ControlFault, Mode};
use firmware::mpc::MpcError;
use firmware::obstacles::MAX_VERTICES;
use firmware::state_estimate::StateEstimate;
use firmware::vehicle_config::VehicleConfig;
use proptest::prelude::*;
use serde::Serialize;

// ---------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------

/// The whole frame of `msg`, delimiter included.
fn frame_of<M: Serialize>(msg: &M) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let n = encode(msg, &mut buf).expect("encode");
    assert_eq!(buf[n - 1], 0, "frame ends with the delimiter");
    assert!(!buf[..n - 1].contains(&0), "no 0x00 inside a frame");
    buf[..n].to_vec()
}

/// `frame` without its delimiter, decoded as `M`.
fn decode_body<M: for<'a> serde::Deserialize<'a>>(frame: &[u8]) -> Result<M, FrameError> {
    let mut body = frame.strip_suffix(&[0]).unwrap_or(frame).to_vec();
    decode::<M>(&mut body)
}

/// A reference COBS encoder (textbook form), independent of the one under test.
fn ref_cobs(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8];
    let mut code_at = 0;
    let mut code = 1u8;
    for &b in data {
        if b == 0 {
            out[code_at] = code;
            code_at = out.len();
            out.push(0);
            code = 1;
        } else {
            out.push(b);
            code += 1;
            if code == 0xFF {
                out[code_at] = code;
                code_at = out.len();
                out.push(0);
                code = 1;
            }
        }
    }
    out[code_at] = code;
    out
}

/// A frame built by hand: COBS(version ++ payload ++ crc32(version ++ payload)), no delimiter.
fn hand_frame(version: u8, payload: &[u8]) -> Vec<u8> {
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    let mut raw = vec![version];
    raw.extend_from_slice(payload);
    let sum = crc.checksum(&raw);
    raw.extend_from_slice(&sum.to_le_bytes());
    ref_cobs(&raw)
}

fn postcard_bytes<M: Serialize>(msg: &M) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_BYTES];
    postcard::to_slice(msg, &mut buf).unwrap().to_vec()
}

fn vehicle(v: f32) -> VehicleConfig<f32> {
    VehicleConfig {
        l_f_m: v,
        l_r_m: v,
        cg_height_m: v,
        width_m: v,
        length_m: v,
        mass_kg: v,
        wheel_radius_m: v,
        max_steer_rad: v,
    }
}

fn estimate(stamp_us: u64, v: f32) -> StateEstimate<f32> {
    StateEstimate {
        stamp_us,
        x_m: v,
        y_m: -v,
        psi_rad: v,
        vx_mps: v,
        vy_mps: v,
        yaw_rate_radps: v,
        delta_rad: v,
        wheel_speed_mps: [v, 2.0 * v, -v, 0.5 * v],
    }
}

fn plan_event(big: u64, v: f32) -> PlanEventFrame {
    PlanEventFrame {
        activation: big as u32,
        release_us: big,
        finish_us: big,
        end_us: big,
        timing: timing(big),
        ticks: big as u32,
        status: big as u8,
        published: true,
        passes: big as u8,
        warm: true,
        qp_iterations: big as u16,
        qp_added: big as u16,
        qp_removed: big as u16,
        qp_refactorizations: big as u16,
        rows: big as u16,
        active: big as u16,
        window_ticks: big as u32,
        nodes_xy: [[v, -v]; PLAN_NODES],
        v_heur0_mps: v,
    }
}

fn timing(big: u64) -> TaskTimingFrame {
    TaskTimingFrame {
        releases: big as u32,
        deadline_misses: big as u32,
        skipped_releases: big as u32,
        budget_overruns: big as u32,
        max_response_us: big as u32,
    }
}

fn actuation(big: u64, v: f32, plan: Option<PlanEventFrame>) -> ActuationFrame {
    ActuationFrame {
        seq: big as u32,
        torque_nm: [v, -v, v, -v],
        delta_rad: v,
        delta_ol_rad: v,
        delta_cl_rad: v,
        v_ref_mps: v,
        mode: big as u8,
        fault: big as u8,
        control_ticks: big as u32,
        release_us: big,
        sent_us: big,
        previous_response_us: big as u32,
        control: timing(big),
        watchdog_trips: big as u32,
        plan,
    }
}

/// Every kind of `Down`, its integers at `big` (truncated) and its floats at `v`.
fn all_down(big: u64, v: f32) -> Vec<Down> {
    vec![
        Down::Config(ConfigFrame {
            vehicle: vehicle(v),
            mu_planner: v,
            closed: big % 2 == 1,
            path_rows: big as u16,
            obstacles: big as u8,
        }),
        Down::PathChunk(PathChunkFrame {
            first: big as u16,
            count: big as u8,
            rows: [[v, -v, v, v]; PATH_CHUNK_ROWS],
        }),
        Down::Obstacle(ObstacleFrame {
            index: big as u8,
            total: big as u8,
            id: big as u32,
            count: big as u8,
            vertices: [[v, -v]; MAX_VERTICES],
        }),
        Down::Start,
        Down::Sensor(SensorFrame {
            seq: big as u32,
            estimate: estimate(big, v),
            route_frames: big as u16,
        }),
        Down::Stop,
        Down::Window(WindowFrame {
            rows: big as u16,
            origin_m: v,
            closed: big % 2 == 1,
        }),
    ]
}

/// Every kind of `Up`, as [`all_down`].
fn all_up(big: u64, v: f32) -> Vec<Up> {
    vec![
        Up::Ready(ReadyFrame {
            status: big as u8,
            detail: big as u16,
        }),
        Up::Actuation(actuation(big, v, None)),
        Up::Actuation(actuation(big, v, Some(plan_event(big, v)))),
        Up::Done(DoneFrame {
            stack_high_water_bytes: big as u32,
            stack_size_bytes: big as u32,
            rejected_frames: big as u32,
        }),
    ]
}

/// Integers and floats, ordinary and extreme (floats compared with `==`: no NaN).
const BIGS: [u64; 5] = [0, 1, 127, 300, u64::MAX];
const FLOATS: [f32; 9] = [
    0.0,
    -0.0,
    1.5,
    -3.25e-3,
    f32::MAX,
    f32::MIN,
    f32::MIN_POSITIVE,
    1.0e-45, // smallest subnormal
    f32::INFINITY,
];

// ---------------------------------------------------------------------------
// Round trips and the wire format
// ---------------------------------------------------------------------------

#[test]
fn every_message_round_trips_with_extreme_values() {
    let mut count = 0;
    for big in BIGS {
        for v in FLOATS.into_iter().chain([f32::NEG_INFINITY]) {
            for msg in all_down(big, v) {
                assert_eq!(decode_body::<Down>(&frame_of(&msg)), Ok(msg));
                count += 1;
            }
            for msg in all_up(big, v) {
                assert_eq!(decode_body::<Up>(&frame_of(&msg)), Ok(msg));
                count += 1;
            }
        }
    }
    assert_eq!(count, BIGS.len() * 10 * 11);
}

#[test]
fn nan_round_trips_bit_for_bit() {
    for bits in [0x7FC0_0000u32, 0xFFC0_0001, 0x7F80_0001, 0xFFFF_FFFF] {
        let nan = f32::from_bits(bits);
        let downs = all_down(7, nan);
        let ups = all_up(7, nan);
        for msg in &downs {
            let frame = frame_of(msg);
            let back: Down = decode_body(&frame).unwrap();
            assert_eq!(frame_of(&back), frame, "{msg:?}");
        }
        for msg in &ups {
            let frame = frame_of(msg);
            let back: Up = decode_body(&frame).unwrap();
            assert_eq!(frame_of(&back), frame, "{msg:?}");
        }
        let Ok(Down::Sensor(s)) = decode_body::<Down>(&frame_of(&downs[4])) else {
            panic!("sensor frame")
        };
        assert_eq!(s.estimate.x_m.to_bits(), bits);
        assert_eq!(s.estimate.y_m.to_bits(), (-nan).to_bits());
    }
}

#[test]
fn frame_layout_is_version_postcard_crc_cobs() {
    // Independent construction of the same frame for every kind of message.
    for msg in all_down(300, 1.5) {
        let mut expected = hand_frame(LINK_VERSION, &postcard_bytes(&msg));
        expected.push(0);
        assert_eq!(frame_of(&msg), expected);
    }
    for msg in all_up(u64::MAX, -2.0) {
        let mut expected = hand_frame(LINK_VERSION, &postcard_bytes(&msg));
        expected.push(0);
        assert_eq!(frame_of(&msg), expected);
    }
    // The CRC is CRC-32/ISO-HDLC (check value of "123456789").
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    assert_eq!(crc.checksum(b"123456789"), 0xCBF4_3926);
    // Pinned bytes: `Down::Start` is version 8, tag 3, then its CRC (zlib.crc32(b"\x08\x03")
    // = 0x1009C94D, little-endian, no zero byte), stuffed: one COBS block of 6 bytes.
    assert_eq!(
        frame_of(&Down::Start),
        [0x07, 0x08, 0x03, 0x4D, 0xC9, 0x09, 0x10, 0x00]
    );
}

#[test]
fn variant_tags_are_as_documented() {
    // Module docs: `Down` Config 0 … Stop 5, Window 6, `Up` Ready 0, Actuation 1, Done 2.
    let down_tags: Vec<u8> = all_down(1, 1.0)
        .iter()
        .map(|m| postcard_bytes(m)[0])
        .collect();
    assert_eq!(down_tags, [0, 1, 2, 3, 4, 5, 6]);
    let up_tags: Vec<u8> = all_up(1, 1.0)
        .iter()
        .map(|m| postcard_bytes(m)[0])
        .collect();
    assert_eq!(up_tags, [0, 1, 1, 2]);
}

#[test]
fn cobs_long_runs_without_zero_round_trip() {
    // 16 rows of non-zero bytes: runs past 254 bytes force extra COBS blocks.
    let v = f32::from_bits(0x4141_4141);
    let msg = Down::PathChunk(PathChunkFrame {
        first: 0x4141,
        count: 0x41,
        rows: [[v; 4]; PATH_CHUNK_ROWS],
    });
    let frame = frame_of(&msg);
    assert_eq!(decode_body::<Down>(&frame), Ok(msg));
}

/// The largest value of each message kind: every varint at its maximum and every
/// byte non-zero (COBS's worst case).
fn maximal_down() -> Vec<Down> {
    all_down(u64::MAX, f32::from_bits(0xFFFF_FFFF))
}

fn maximal_up() -> Vec<Up> {
    all_up(u64::MAX, f32::from_bits(0xFFFF_FFFF))
}

#[test]
fn largest_frames_fit_max_frame_bytes() {
    let downs = maximal_down();
    let ups = maximal_up();
    let names_down = [
        "Config",
        "PathChunk",
        "Obstacle",
        "Start",
        "Sensor",
        "Stop",
        "Window",
    ];
    let names_up = ["Ready", "Actuation(None)", "Actuation(Some)", "Done"];
    let mut largest_down_payload = 0;
    let mut largest_up_payload = 0;
    for (msg, name) in downs.iter().zip(names_down) {
        let n = frame_of(msg).len();
        let p = postcard_bytes(msg).len();
        println!("Down::{name}: payload {p} bytes, frame {n} bytes");
        assert!(n <= frame_bytes_for_payload(p));
        assert!(n <= MAX_DOWN_FRAME_BYTES);
        largest_down_payload = largest_down_payload.max(p);
    }
    for (msg, name) in ups.iter().zip(names_up) {
        let n = frame_of(msg).len();
        let p = postcard_bytes(msg).len();
        println!("Up::{name}: payload {p} bytes, frame {n} bytes");
        assert!(n <= frame_bytes_for_payload(p));
        assert!(n <= MAX_UP_FRAME_BYTES);
        largest_up_payload = largest_up_payload.max(p);
    }
    // The compile-time bounds are exact, not loose.
    assert_eq!(largest_down_payload, MAX_DOWN_PAYLOAD_BYTES);
    assert_eq!(largest_up_payload, MAX_UP_PAYLOAD_BYTES);
    assert_eq!(MAX_DOWN_FRAME_BYTES, 269);
    // Version 3: release and send instants, the two tasks' deadline counts, the
    // watchdog's trips and the plan's end (249 bytes in version 2); version 7:
    // the previous control activation's response time (336 bytes in version 6).
    assert_eq!(MAX_UP_FRAME_BYTES, 341);
    assert_eq!(frame_of(&downs[1]).len(), MAX_DOWN_FRAME_BYTES);
    // What the control link carries while driving: `Sensor`, `Stop`; the largest
    // sensor frame is exactly the bound the ECU's receive loop stops at.
    let sensor = frame_of(&downs[4]);
    assert_eq!(sensor.len(), MAX_DRIVING_DOWN_FRAME_BYTES);
    assert!(frame_of(&downs[5]).len() < MAX_DRIVING_DOWN_FRAME_BYTES);
    assert_eq!(
        postcard_bytes(&downs[4]).len(),
        MAX_DRIVING_DOWN_PAYLOAD_BYTES
    );
    println!("driving frame bound: {MAX_DRIVING_DOWN_FRAME_BYTES} bytes");
}

#[test]
fn encode_into_a_small_buffer_is_refused() {
    for msg in maximal_up() {
        let n = frame_of(&msg).len();
        let mut buf = vec![0u8; n];
        assert_eq!(encode(&msg, &mut buf), Ok(n));
        for short in 0..n {
            let mut buf = vec![0u8; short];
            assert_eq!(
                encode(&msg, &mut buf),
                Err(FrameError::BufferTooSmall),
                "{short}"
            );
        }
    }
}

// ---------------------------------------------------------------------------
// Refusals
// ---------------------------------------------------------------------------

#[test]
fn each_refusal_has_its_error() {
    assert_eq!(decode::<Down>(&mut []), Err(FrameError::Empty));
    assert_eq!(
        decode::<Down>(&mut vec![1u8; MAX_FRAME_BYTES]),
        Err(FrameError::TooLong)
    );
    // A 0x00 inside, a block past the end.
    assert_eq!(decode::<Down>(&mut [3, 1, 0, 1]), Err(FrameError::Cobs));
    assert_eq!(decode::<Down>(&mut [5, 1, 2]), Err(FrameError::Cobs));
    // Shorter than version + CRC.
    assert_eq!(
        decode::<Down>(&mut [5, 1, 2, 3, 4]),
        Err(FrameError::TooShort)
    );
    // Another version, with its own valid CRC.
    let mut v1 = hand_frame(1, &postcard_bytes(&Down::Start));
    assert_eq!(decode::<Down>(&mut v1), Err(FrameError::Version { got: 1 }));
    // A wrong CRC.
    let mut frame = frame_of(&Down::Stop);
    frame.pop();
    frame[3] ^= 0x10;
    assert_eq!(decode::<Down>(&mut frame), Err(FrameError::Checksum));
    // A valid CRC around an invalid message (unknown variant 9), trailing bytes,
    // a truncated message, and a `Down` read as an `Up`.
    assert_eq!(
        decode::<Down>(&mut hand_frame(LINK_VERSION, &[9])),
        Err(FrameError::Malformed)
    );
    let mut trailing = postcard_bytes(&Down::Stop);
    trailing.push(0);
    assert_eq!(
        decode::<Down>(&mut hand_frame(LINK_VERSION, &trailing)),
        Err(FrameError::Malformed)
    );
    let sensor = postcard_bytes(&all_down(5, 1.0)[4]);
    assert_eq!(
        decode::<Down>(&mut hand_frame(LINK_VERSION, &sensor[..sensor.len() - 1])),
        Err(FrameError::Malformed)
    );
    assert_eq!(
        decode_body::<Up>(&frame_of(&Down::Start)),
        Err(FrameError::Malformed)
    );
    assert_eq!(
        decode::<Down>(&mut hand_frame(LINK_VERSION, &[])),
        Err(FrameError::Malformed)
    );
}

#[test]
fn frame_reader_drops_an_over_long_frame_then_recovers() {
    let mut reader = FrameReader::<MAX_FRAME_BYTES>::new();
    let mut errors = Vec::new();
    for _ in 0..(MAX_FRAME_BYTES + 100) {
        assert!(reader.push(0x55).is_none());
    }
    assert_eq!(reader.pending(), 0);
    if let Some(r) = reader.push(0) {
        errors.push(r.map(|b| b.to_vec()));
    }
    assert_eq!(errors, [Err(FrameError::TooLong)]);
    // Idle delimiters yield nothing.
    assert!(reader.push(0).is_none());
    assert!(reader.push(0).is_none());
    let frame = frame_of(&Down::Stop);
    let mut got = None;
    for &b in &frame {
        if let Some(r) = reader.push(b) {
            got = Some(decode::<Down>(r.unwrap()));
        }
    }
    assert_eq!(got, Some(Ok(Down::Stop)));

    // A reader too small for a frame reports it as too long.
    let mut small = FrameReader::<8>::default();
    let frame = frame_of(&all_down(1, 1.0)[4]);
    let results: Vec<_> = frame
        .iter()
        .filter_map(|&b| small.push(b).map(|r| r.map(|s| s.len())))
        .collect();
    assert_eq!(results, [Err(FrameError::TooLong)]);
    // `reset` drops a partial frame.
    small.push(7);
    small.reset();
    assert_eq!(small.pending(), 0);
    assert!(small.push(0).is_none());
}

// ---------------------------------------------------------------------------
// Sequence numbers and counters
// ---------------------------------------------------------------------------

#[test]
fn sequence_check_refuses_stale_and_counts_gaps() {
    let mut check = SequenceCheck::new();
    let mut stats = LinkStats::new();
    let mut run = |seq: u32| {
        let r = check.accept(seq);
        stats.record_sequence(&r);
        r
    };
    assert_eq!(run(10), Ok(0)); // any first number
    assert_eq!(run(11), Ok(0));
    assert_eq!(run(11), Err(SequenceError::Stale)); // duplicate
    assert_eq!(run(5), Err(SequenceError::Stale)); // older
    assert_eq!(run(12), Ok(0));
    assert_eq!(run(15), Ok(2)); // 13, 14 missed: accepted, reported
    assert_eq!(run(14), Err(SequenceError::Stale)); // late after the gap
    assert_eq!(run(u32::MAX), Ok(u32::MAX - 16));
    assert_eq!(run(u32::MAX), Err(SequenceError::Stale));
    assert_eq!(run(0), Err(SequenceError::Stale));
    assert_eq!(stats.stale, 5);
    assert_eq!(stats.gaps, 2);
    assert_eq!(check.last(), Some(u32::MAX));
    check.reset();
    assert_eq!(check.accept(3), Ok(0));

    let mut stats = LinkStats::default();
    stats.record::<()>(&Ok(()));
    stats.record::<()>(&Err(FrameError::Checksum));
    stats.record::<()>(&Err(FrameError::Cobs));
    assert_eq!((stats.accepted, stats.rejected), (1, 2));
    assert_eq!(stats.last_error, Some(FrameError::Cobs));
}

// ---------------------------------------------------------------------------
// Status codes
// ---------------------------------------------------------------------------

#[test]
fn status_codes_round_trip_and_names_are_distinct() {
    let mut names = std::collections::HashSet::new();
    for (i, s) in QP_STATUSES.into_iter().enumerate() {
        assert_eq!(usize::from(qp_status_code(s)), i);
        assert_eq!(qp_status_from_code(qp_status_code(s)), Some(s));
        assert!(names.insert(qp_status_name(s)));
    }
    assert_eq!(qp_status_from_code(9), None);

    let mut errors = vec![
        MpcError::NonFiniteState,
        MpcError::InvalidFriction,
        MpcError::InvalidSettings,
        MpcError::NoPath,
        MpcError::NonFinitePlan,
    ];
    errors.extend(QP_STATUSES.map(MpcError::Qp));
    let mut names = std::collections::HashSet::from(["Optimal"]);
    for e in errors {
        let code = mpc_status_code::<()>(&Err(e));
        assert_ne!(code, MPC_OK);
        assert_eq!(mpc_error_from_code(code), Some(e));
        assert!(names.insert(mpc_status_name(code)), "{e:?}");
    }
    assert_eq!(mpc_status_code(&Ok::<u8, MpcError>(3)), 0);
    assert_eq!(mpc_status_name(0), "Optimal");
    // The names logs and CSV files carry (the simulator's plan_activations.csv).
    assert_eq!(mpc_status_name(0x12), "Qp(IterationLimit)");
    assert_eq!(mpc_status_name(4), "NoPath");
    assert_eq!(
        qp_status_name(qp::QpStatus::WorkingSetFull),
        "WorkingSetFull"
    );
    assert_eq!(mode_name(3), "Safe");
    assert_eq!(mode_name(4), "Unknown");
    assert_eq!(SetupError::ObstacleBlocksRoad.name(), "ObstacleBlocksRoad");
    assert_eq!(setup_status_name(0), "Accepted");
    assert_eq!(
        mpc_status_code::<()>(&Err(MpcError::Qp(qp::QpStatus::Infeasible))),
        0x13
    );
    assert_eq!(mpc_status_name(5), "NonFinitePlan");
    // An activation that adopted a window: no MPC error, a name of its own.
    assert_eq!(mpc_error_from_code(PLAN_WINDOW), None);
    assert!(names.insert(mpc_status_name(PLAN_WINDOW)));
    assert_eq!(mpc_status_name(PLAN_WINDOW), "Window");
    let w = PlanEventFrame::window(7, 1_000, 2_000, 12_345);
    assert_eq!(
        (w.status, w.ticks, w.window_ticks, w.published, w.passes),
        (PLAN_WINDOW, 12_345, 12_345, false, 0)
    );
    for unknown in [6u8, 0x0F, 0x19, 0x21, 0xFF] {
        assert_eq!(mpc_error_from_code(unknown), None);
        assert_eq!(mpc_status_name(unknown), "Unknown");
    }

    for (i, m) in [
        Mode::Following,
        Mode::Extrapolating,
        Mode::Stopping,
        Mode::Safe,
    ]
    .into_iter()
    .enumerate()
    {
        assert_eq!(usize::from(mode_code(m)), i);
        assert_eq!(mode_from_code(mode_code(m)), Some(m));
        assert_ne!(mode_name(mode_code(m)), "Unknown");
    }
    assert_eq!(mode_from_code(4), None);

    let faults = [
        None,
        Some(ControlFault::NonFiniteEstimate),
        Some(ControlFault::NonFinitePlan),
        Some(ControlFault::InvalidPlan),
        Some(ControlFault::Numerical),
    ];
    for (i, f) in faults.into_iter().enumerate() {
        assert_eq!(usize::from(fault_code(f)), i);
        assert_eq!(fault_from_code(fault_code(f)), Ok(f));
        assert_ne!(fault_name(fault_code(f)), "Unknown");
    }
    assert_eq!(fault_from_code(5), Err(5));
    assert_eq!(fault_name(5), "Unknown");
    // The ECU's own codes: outside the control faults, named, distinct.
    let own = [FAULT_PANIC, FAULT_HARDFAULT, FAULT_NMI, FAULT_DEADLINE];
    let names: std::collections::HashSet<_> = own.iter().map(|&c| fault_name(c)).collect();
    assert_eq!(names.len(), 4);
    assert_eq!(fault_name(FAULT_NMI), "Nmi");
    for c in own {
        assert!(fault_from_code(c).is_err());
        assert_ne!(fault_name(c), "Unknown");
    }

    for (i, e) in SetupError::ALL.into_iter().enumerate() {
        assert_eq!(usize::from(e.code()), i + 1);
        assert_eq!(SetupError::from_code(e.code()), Some(e));
        assert_eq!(setup_status_name(e.code()), e.name());
    }
    assert_eq!(SetupError::from_code(0), None);
    assert_eq!(setup_status_name(0), "Accepted");
    assert_eq!(setup_status_name(200), "Unknown");
}

// ---------------------------------------------------------------------------
// Properties
// ---------------------------------------------------------------------------

/// Any `f32`, NaN payloads and infinities included.
fn any_f32() -> impl Strategy<Value = f32> {
    any::<u32>().prop_map(f32::from_bits)
}

fn any_down() -> impl Strategy<Value = Down> {
    let config = (
        prop::array::uniform8(any_f32()),
        any_f32(),
        any::<bool>(),
        any::<u16>(),
        any::<u8>(),
    )
        .prop_map(|(v, mu, closed, path_rows, obstacles)| {
            Down::Config(ConfigFrame {
                vehicle: VehicleConfig {
                    l_f_m: v[0],
                    l_r_m: v[1],
                    cg_height_m: v[2],
                    width_m: v[3],
                    length_m: v[4],
                    mass_kg: v[5],
                    wheel_radius_m: v[6],
                    max_steer_rad: v[7],
                },
                mu_planner: mu,
                closed,
                path_rows,
                obstacles,
            })
        });
    let chunk = (
        any::<u16>(),
        any::<u8>(),
        prop::array::uniform16(prop::array::uniform4(any_f32())),
    )
        .prop_map(|(first, count, rows)| Down::PathChunk(PathChunkFrame { first, count, rows }));
    let obstacle = (
        any::<(u8, u8, u32, u8)>(),
        prop::array::uniform8(prop::array::uniform2(any_f32())),
    )
        .prop_map(|((index, total, id, count), vertices)| {
            Down::Obstacle(ObstacleFrame {
                index,
                total,
                id,
                count,
                vertices,
            })
        });
    let sensor = (
        any::<u32>(),
        any::<u64>(),
        prop::array::uniform11(any_f32()),
        any::<u16>(),
    )
        .prop_map(|(seq, stamp_us, v, route_frames)| {
            Down::Sensor(SensorFrame {
                seq,
                route_frames,
                estimate: StateEstimate {
                    stamp_us,
                    x_m: v[0],
                    y_m: v[1],
                    psi_rad: v[2],
                    vx_mps: v[3],
                    vy_mps: v[4],
                    yaw_rate_radps: v[5],
                    delta_rad: v[6],
                    wheel_speed_mps: [v[7], v[8], v[9], v[10]],
                },
            })
        });
    let window = (any::<u16>(), any_f32(), any::<bool>()).prop_map(|(rows, origin_m, closed)| {
        Down::Window(WindowFrame {
            rows,
            origin_m,
            closed,
        })
    });
    prop_oneof![
        config,
        chunk,
        obstacle,
        Just(Down::Start),
        sensor,
        Just(Down::Stop),
        window
    ]
}

fn any_timing() -> impl Strategy<Value = TaskTimingFrame> {
    any::<(u32, u32, u32, u32, u32)>().prop_map(|(a, b, c, d, e)| TaskTimingFrame {
        releases: a,
        deadline_misses: b,
        skipped_releases: c,
        budget_overruns: d,
        max_response_us: e,
    })
}

fn any_plan_event() -> impl Strategy<Value = PlanEventFrame> {
    (
        any::<(u32, u64, u64, u32, u8, bool, u8)>(),
        (any::<u64>(), any_timing(), any::<bool>()),
        any::<(u16, u16, u16, u16, u16, u16, u32)>(),
        prop::array::uniform17(prop::array::uniform2(any_f32())),
        any_f32(),
    )
        .prop_map(
            |(
                (activation, release_us, finish_us, ticks, status, published, passes),
                (end_us, timing, warm),
                (
                    qp_iterations,
                    qp_added,
                    qp_removed,
                    qp_refactorizations,
                    rows,
                    active,
                    window_ticks,
                ),
                nodes_xy,
                v_heur0_mps,
            )| PlanEventFrame {
                activation,
                release_us,
                finish_us,
                end_us,
                timing,
                ticks,
                status,
                published,
                passes,
                warm,
                qp_iterations,
                qp_added,
                qp_removed,
                qp_refactorizations,
                rows,
                active,
                window_ticks,
                nodes_xy,
                v_heur0_mps,
            },
        )
}

fn any_up() -> impl Strategy<Value = Up> {
    let actuation = (
        any::<(u32, u8, u8, u32)>(),
        prop::array::uniform8(any_f32()),
        (any::<u64>(), any::<u64>(), any_timing(), any::<u32>()),
        any::<u32>(),
        prop::option::of(any_plan_event()),
    )
        .prop_map(
            |(
                (seq, mode, fault, control_ticks),
                f,
                (release_us, sent_us, control, watchdog_trips),
                previous_response_us,
                plan,
            )| {
                Up::Actuation(ActuationFrame {
                    seq,
                    torque_nm: [f[0], f[1], f[2], f[3]],
                    delta_rad: f[4],
                    delta_ol_rad: f[5],
                    delta_cl_rad: f[6],
                    v_ref_mps: f[7],
                    mode,
                    fault,
                    control_ticks,
                    release_us,
                    sent_us,
                    previous_response_us,
                    control,
                    watchdog_trips,
                    plan,
                })
            },
        );
    prop_oneof![
        any::<(u8, u16)>().prop_map(|(status, detail)| Up::Ready(ReadyFrame { status, detail })),
        actuation,
        any::<(u32, u32, u32)>().prop_map(|(a, b, c)| Up::Done(DoneFrame {
            stack_high_water_bytes: a,
            stack_size_bytes: b,
            rejected_frames: c,
        })),
    ]
}

/// A frame (with delimiter) of any message, `Down` or `Up`, and a decoder that
/// re-encodes what it decodes (bit-exact comparison, NaN included).
#[derive(Clone, Debug)]
enum AnyMsg {
    Down(Down),
    Up(Up),
}

fn any_msg() -> impl Strategy<Value = AnyMsg> {
    prop_oneof![
        any_down().prop_map(AnyMsg::Down),
        any_up().prop_map(AnyMsg::Up)
    ]
}

impl AnyMsg {
    fn frame(&self) -> Vec<u8> {
        match self {
            AnyMsg::Down(m) => frame_of(m),
            AnyMsg::Up(m) => frame_of(m),
        }
    }

    /// Decodes `body` (no delimiter) as this message's type; re-encodes it.
    fn decode_like(&self, body: &mut [u8]) -> Result<Vec<u8>, FrameError> {
        match self {
            AnyMsg::Down(_) => decode::<Down>(body).map(|m| frame_of(&m)),
            AnyMsg::Up(_) => decode::<Up>(body).map(|m| frame_of(&m)),
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn any_message_round_trips_bit_for_bit(msg in any_msg()) {
        let frame = msg.frame();
        prop_assert!(frame.len() <= MAX_FRAME_BYTES);
        let mut body = frame[..frame.len() - 1].to_vec();
        prop_assert_eq!(msg.decode_like(&mut body), Ok(frame));
    }

    #[test]
    fn arbitrary_bytes_never_decode(mut bytes in prop::collection::vec(any::<u8>(), 0..700)) {
        let mut copy = bytes.clone();
        prop_assert!(decode::<Down>(&mut bytes).is_err());
        prop_assert!(decode::<Up>(&mut copy).is_err());
    }

    #[test]
    fn arbitrary_nonzero_bytes_never_decode(
        mut bytes in prop::collection::vec(1u8..=255, 1..600),
    ) {
        // No 0x00: only the COBS structure, version, length and CRC stand in the way.
        let mut copy = bytes.clone();
        prop_assert!(decode::<Down>(&mut bytes).is_err());
        prop_assert!(decode::<Up>(&mut copy).is_err());
    }

    #[test]
    fn arbitrary_stream_yields_no_message(bytes in prop::collection::vec(any::<u8>(), 0..2000)) {
        let mut reader = FrameReader::<MAX_FRAME_BYTES>::new();
        let mut stats = LinkStats::new();
        for b in bytes {
            if let Some(frame) = reader.push(b) {
                let r = frame.and_then(decode::<Down>);
                stats.record(&r);
            }
        }
        prop_assert_eq!(stats.accepted, 0);
    }

    #[test]
    fn any_single_bit_flip_is_refused(msg in any_msg(), bit in any::<prop::sample::Index>()) {
        let frame = msg.frame();
        let mut body = frame[..frame.len() - 1].to_vec();
        let i = bit.index(body.len() * 8);
        body[i / 8] ^= 1 << (i % 8);
        prop_assert!(msg.decode_like(&mut body).is_err());
    }

    #[test]
    fn every_single_bit_flip_of_one_frame_is_refused(msg in any_msg()) {
        let frame = msg.frame();
        let body = &frame[..frame.len() - 1];
        for i in 0..body.len() * 8 {
            let mut flipped = body.to_vec();
            flipped[i / 8] ^= 1 << (i % 8);
            prop_assert!(msg.decode_like(&mut flipped).is_err(), "bit {}", i);
        }
    }

    #[test]
    fn any_truncation_is_refused(msg in any_msg(), cut in any::<prop::sample::Index>()) {
        let frame = msg.frame();
        let body = &frame[..frame.len() - 1];
        let k = cut.index(body.len());
        // Keep the first k bytes; or drop the first k + 1.
        prop_assert!(msg.decode_like(&mut body[..k].to_vec()).is_err());
        prop_assert!(msg.decode_like(&mut body[k + 1..].to_vec()).is_err());
    }

    #[test]
    fn other_versions_are_refused_by_version(msg in any_msg(), version in any::<u8>()) {
        prop_assume!(version != LINK_VERSION);
        let payload = match &msg {
            AnyMsg::Down(m) => postcard_bytes(m),
            AnyMsg::Up(m) => postcard_bytes(m),
        };
        let mut body = hand_frame(version, &payload);
        prop_assert_eq!(msg.decode_like(&mut body), Err(FrameError::Version { got: version }));
    }

    #[test]
    fn frames_between_garbage_are_recovered(
        parts in prop::collection::vec(
            (prop::collection::vec(any::<u8>(), 0..80), any_msg()),
            1..12,
        ),
        tail in prop::collection::vec(any::<u8>(), 0..80),
    ) {
        // Stream: garbage 0x00 frame, garbage 0x00 frame, …, garbage 0x00.
        let mut stream = Vec::new();
        let mut expected_frames = Vec::new();
        let mut expected_garbage = 0u32;
        let garbage = |g: &[u8], stream: &mut Vec<u8>| {
            stream.extend_from_slice(g);
            stream.push(0);
            g.split(|&b| b == 0).filter(|piece| !piece.is_empty()).count() as u32
        };
        for (g, msg) in &parts {
            expected_garbage += garbage(g, &mut stream);
            let frame = msg.frame();
            stream.extend_from_slice(&frame);
            expected_frames.push(frame);
        }
        expected_garbage += garbage(&tail, &mut stream);

        let mut reader = FrameReader::<MAX_FRAME_BYTES>::new();
        let mut stats = LinkStats::new();
        let mut got = Vec::new();
        for b in stream {
            if let Some(r) = reader.push(b) {
                // Try both message types: a frame decodes as at most one of them.
                let r = r.and_then(|f| {
                    let mut copy = f.to_vec();
                    match decode::<Down>(f) {
                        Ok(m) => Ok(frame_of(&m)),
                        Err(_) => decode::<Up>(&mut copy).map(|m| frame_of(&m)),
                    }
                });
                stats.record(&r);
                if let Ok(frame) = r {
                    got.push(frame);
                }
            }
        }
        prop_assert_eq!(got, expected_frames);
        prop_assert_eq!(stats.accepted as usize, parts.len());
        prop_assert_eq!(stats.rejected, expected_garbage);
    }

    #[test]
    fn sequence_check_matches_a_model(seqs in prop::collection::vec(0u32..64, 0..64)) {
        let mut check = SequenceCheck::new();
        let mut last: Option<u32> = None;
        for s in seqs {
            let expected = match last {
                Some(l) if s <= l => Err(SequenceError::Stale),
                Some(l) => Ok(s - l - 1),
                None => Ok(0),
            };
            if expected.is_ok() {
                last = Some(s);
            }
            prop_assert_eq!(check.accept(s), expected);
        }
        prop_assert_eq!(check.last(), last);
    }
}
