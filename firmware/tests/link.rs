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

/// The key the tests authenticate with: the documented development key, spelt
/// out here (not `LINK_KEY`, which a build may set otherwise).
const KEY: LinkKey = *b"DEV-ONLY-SIM-KEY";

/// The whole frame of `msg`, delimiter included: the first frame (freshness 1)
/// of a sender on the down stream.
fn frame_of<M: Serialize>(msg: &M) -> Vec<u8> {
    frame_on(msg, &mut Authenticator::new(Stream::Down))
}

/// The whole frame of `msg` from `tx` (its next freshness), under [`KEY`].
fn frame_on<M: Serialize>(msg: &M, tx: &mut Authenticator) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let n = encode(msg, &mut LinkMac::new(&KEY), tx, &mut buf).expect("encode");
    assert_eq!(buf[n - 1], 0, "frame ends with the delimiter");
    assert!(!buf[..n - 1].contains(&0), "no 0x00 inside a frame");
    buf[..n].to_vec()
}

/// `body` (no delimiter) decoded as `M` by a receiver on the down stream that
/// has accepted nothing yet, under [`KEY`].
fn decode_fresh<M: for<'a> serde::Deserialize<'a>>(body: &mut [u8]) -> Result<M, FrameError> {
    decode::<M>(
        body,
        &mut LinkMac::new(&KEY),
        &mut Verifier::new(Stream::Down),
    )
}

/// `frame` without its delimiter, decoded as `M` ([`decode_fresh`]).
fn decode_body<M: for<'a> serde::Deserialize<'a>>(frame: &[u8]) -> Result<M, FrameError> {
    let mut body = frame.strip_suffix(&[0]).unwrap_or(frame).to_vec();
    decode_fresh::<M>(&mut body)
}

/// Keyed BLAKE2s of `data` under `key`, 8 bytes of output (the link's tag): the
/// RustCrypto crate's own buffered MAC interface, independent of `LinkMac`'s
/// block feeding.
fn ref_tag(key: &LinkKey, data: &[u8]) -> [u8; MAC_BYTES] {
    use blake2::digest::{consts::U8, KeyInit, Mac};
    let mut mac = <blake2::Blake2sMac<U8> as KeyInit>::new_from_slice(key).unwrap();
    mac.update(data);
    mac.finalize().into_bytes().into()
}

/// The raw frame (no COBS) built by hand: `version ++ payload ++ freshness ++ tag`
/// with the tag under `key` on `stream`, then the CRC of all that.
fn hand_raw(key: &LinkKey, stream: Stream, freshness: u32, version: u8, payload: &[u8]) -> Vec<u8> {
    let mut raw = vec![version];
    raw.extend_from_slice(payload);
    raw.extend_from_slice(&freshness.to_le_bytes());
    let mut input = vec![stream.data_id()];
    input.extend_from_slice(&raw);
    raw.extend_from_slice(&ref_tag(key, &input));
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    let sum = crc.checksum(&raw);
    raw.extend_from_slice(&sum.to_le_bytes());
    raw
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

/// A frame built by hand, no delimiter: COBS of [`hand_raw`] under [`KEY`] on the
/// down stream, freshness 1 (what [`frame_of`] makes).
fn hand_frame(version: u8, payload: &[u8]) -> Vec<u8> {
    ref_cobs(&hand_raw(&KEY, Stream::Down, 1, version, payload))
}

/// COBS-decodes a frame without its delimiter (the reference, for tests that
/// alter the raw bytes).
fn ref_uncobs(body: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < body.len() {
        let code = body[i] as usize;
        out.extend_from_slice(&body[i + 1..i + code]);
        i += code;
        if code < 0xFF && i < body.len() {
            out.push(0);
        }
    }
    out
}

/// `raw` with its CRC recomputed (what anyone can do: the CRC is no secret),
/// COBS-encoded, no delimiter.
fn reseal(mut raw: Vec<u8>) -> Vec<u8> {
    let n = raw.len() - CRC_BYTES;
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    let sum = crc.checksum(&raw[..n]);
    raw[n..].copy_from_slice(&sum.to_le_bytes());
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
        specific_force_x_mps2: 0.25 * v,
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
        sensor: big as u8,
        refused: refusals(big),
        plan,
    }
}

fn refusals(big: u64) -> RefusalCounts {
    RefusalCounts {
        auth: big as u32,
        replay: (big as u32).rotate_left(1),
        corrupt: big as u32,
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
            route_frames: big as u32,
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
            refused: refusals(big),
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
fn frame_layout_is_version_postcard_freshness_tag_crc_cobs() {
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
    // The tag is keyed BLAKE2s with an 8-byte output (RFC 7693): a value computed
    // apart (Python's `hashlib.blake2s(msg, key=key, digest_size=8)`).
    let key = [
        0x2b, 0x7e, 0x15, 0x16, 0x28, 0xae, 0xd2, 0xa6, 0xab, 0xf7, 0x15, 0x88, 0x09, 0xcf, 0x4f,
        0x3c,
    ];
    let msg = [
        0x6b, 0xc1, 0xbe, 0xe2, 0x2e, 0x40, 0x9f, 0x96, 0xe9, 0x3d, 0x7e, 0x11, 0x73, 0x93, 0x17,
        0x2a,
    ];
    assert_eq!(
        ref_tag(&key, &msg),
        [0xde, 0x98, 0x71, 0xc0, 0x07, 0x1d, 0x52, 0xe4]
    );
    // Pinned bytes, computed apart (Python's `hashlib.blake2s` and `zlib.crc32`):
    // `Down::Start` under the development key is version 11, tag 3, freshness 1
    // (01 00 00 00), the tag 09 5c dc 3a 74 5a 93 ce (keyed BLAKE2s of
    // 01 0b 03 01 00 00 00: the down stream's Data ID first), the CRC d3 2c 7d 6e;
    // stuffed: COBS blocks of 4, 1, 1 and 13 bytes.
    assert_eq!(
        frame_of(&Down::Start),
        [
            0x04, 0x0b, 0x03, 0x01, 0x01, 0x01, 0x0d, 0x09, 0x5c, 0xdc, 0x3a, 0x74, 0x5a, 0x93,
            0xce, 0xd3, 0x2c, 0x7d, 0x6e, 0x00
        ]
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

/// The frame of `msg` with the largest freshness value (`u32::MAX`, no zero byte
/// in it: COBS's worst case), bytes.
fn largest<M: Serialize>(msg: &M, stream: Stream) -> Vec<u8> {
    frame_on(msg, &mut Authenticator::resumed(stream, u32::MAX - 1))
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
        let n = largest(msg, Stream::Down).len();
        let p = postcard_bytes(msg).len();
        println!("Down::{name}: payload {p} bytes, frame {n} bytes");
        assert!(n <= frame_bytes_for_payload(p));
        assert!(n <= MAX_DOWN_FRAME_BYTES);
        largest_down_payload = largest_down_payload.max(p);
    }
    for (msg, name) in ups.iter().zip(names_up) {
        let n = largest(msg, Stream::Up).len();
        let p = postcard_bytes(msg).len();
        println!("Up::{name}: payload {p} bytes, frame {n} bytes");
        assert!(n <= frame_bytes_for_payload(p));
        assert!(n <= MAX_UP_FRAME_BYTES);
        largest_up_payload = largest_up_payload.max(p);
        // An actuation frame without a plan event within its own bound, exact.
        if name == "Actuation(None)" {
            assert!(n <= MAX_ACTUATION_FRAME_BYTES);
            assert_eq!(p, MAX_ACTUATION_PAYLOAD_BYTES);
        }
    }
    // The compile-time bounds are exact, not loose.
    assert_eq!(largest_down_payload, MAX_DOWN_PAYLOAD_BYTES);
    assert_eq!(largest_up_payload, MAX_UP_PAYLOAD_BYTES);
    // Version 8: a freshness value and a tag in every frame (12 bytes; 269
    // before).
    assert_eq!(MAX_DOWN_FRAME_BYTES, 281);
    // Version 3: release and send instants, the two tasks' deadline counts, the
    // watchdog's trips and the plan's end (249 bytes in version 2); version 7:
    // the previous control activation's response time (336 bytes in version 6).
    // Version 8: the freshness value and the tag, this period's sensor frame's
    // refusal and the refusal counts (341 bytes in version 7).
    assert_eq!(MAX_UP_FRAME_BYTES, 369);
    // The plan event is 233 of them (the link's budget per plan period).
    assert_eq!(MAX_ACTUATION_FRAME_BYTES, 136);
    assert_eq!(largest(&downs[1], Stream::Down).len(), MAX_DOWN_FRAME_BYTES);
    // What the control link carries while driving: `Sensor`, `Stop`; the largest
    // sensor frame is exactly the bound the ECU's receive loop stops at.
    let sensor = largest(&downs[4], Stream::Down);
    assert_eq!(sensor.len(), MAX_DRIVING_DOWN_FRAME_BYTES);
    assert!(largest(&downs[5], Stream::Down).len() < MAX_DRIVING_DOWN_FRAME_BYTES);
    assert_eq!(
        postcard_bytes(&downs[4]).len(),
        MAX_DRIVING_DOWN_PAYLOAD_BYTES
    );
    println!("driving frame bound: {MAX_DRIVING_DOWN_FRAME_BYTES} bytes");
}

#[test]
fn encode_into_a_small_buffer_is_refused() {
    let mut mac = LinkMac::new(&KEY);
    for msg in maximal_up() {
        let n = frame_of(&msg).len();
        let mut tx = Authenticator::new(Stream::Up);
        for short in 0..n {
            let mut buf = vec![0u8; short];
            assert_eq!(
                encode(&msg, &mut mac, &mut tx, &mut buf),
                Err(FrameError::BufferTooSmall),
                "{short}"
            );
            // A frame not encoded takes no freshness value.
            assert_eq!(tx.last_sent(), 0);
        }
        let mut buf = vec![0u8; n];
        assert_eq!(encode(&msg, &mut mac, &mut tx, &mut buf), Ok(n));
        assert_eq!(tx.last_sent(), 1);
    }
}

// ---------------------------------------------------------------------------
// Refusals
// ---------------------------------------------------------------------------

#[test]
fn each_refusal_has_its_error() {
    assert_eq!(decode_fresh::<Down>(&mut []), Err(FrameError::Empty));
    assert_eq!(
        decode_fresh::<Down>(&mut vec![1u8; MAX_FRAME_BYTES]),
        Err(FrameError::TooLong)
    );
    // A 0x00 inside, a block past the end.
    assert_eq!(
        decode_fresh::<Down>(&mut [3, 1, 0, 1]),
        Err(FrameError::Cobs)
    );
    assert_eq!(decode_fresh::<Down>(&mut [5, 1, 2]), Err(FrameError::Cobs));
    // Shorter than version + freshness + tag + CRC (17 bytes).
    assert_eq!(
        decode_fresh::<Down>(&mut [5, 1, 2, 3, 4]),
        Err(FrameError::TooShort)
    );
    let mut short = ref_cobs(&[LINK_VERSION; 16]);
    assert_eq!(decode_fresh::<Down>(&mut short), Err(FrameError::TooShort));
    // Another version, with its own valid CRC and tag.
    let mut v1 = hand_frame(1, &postcard_bytes(&Down::Start));
    assert_eq!(
        decode_fresh::<Down>(&mut v1),
        Err(FrameError::Version { got: 1 })
    );
    // A wrong CRC.
    let mut frame = frame_of(&Down::Stop);
    frame.pop();
    frame[3] ^= 0x10;
    assert_eq!(decode_fresh::<Down>(&mut frame), Err(FrameError::Checksum));
    // A valid CRC around a tag under another key, or of another stream.
    let other_key = *b"not-the-link-key";
    let payload = postcard_bytes(&Down::Stop);
    let mut forged = ref_cobs(&hand_raw(
        &other_key,
        Stream::Down,
        1,
        LINK_VERSION,
        &payload,
    ));
    assert_eq!(
        decode_fresh::<Down>(&mut forged),
        Err(FrameError::Authentication)
    );
    let mut other_stream = ref_cobs(&hand_raw(&KEY, Stream::Route, 1, LINK_VERSION, &payload));
    assert_eq!(
        decode_fresh::<Down>(&mut other_stream),
        Err(FrameError::Authentication)
    );
    // An authentic frame of freshness 0: never newer than a receiver's start.
    let mut stale = ref_cobs(&hand_raw(&KEY, Stream::Down, 0, LINK_VERSION, &payload));
    assert_eq!(
        decode_fresh::<Down>(&mut stale),
        Err(FrameError::Replay {
            freshness: 0,
            last: 0
        })
    );
    // Authentic frames around an invalid message (unknown variant 9), trailing
    // bytes, a truncated message, and a `Down` read as an `Up`.
    assert_eq!(
        decode_fresh::<Down>(&mut hand_frame(LINK_VERSION, &[9])),
        Err(FrameError::Malformed)
    );
    let mut trailing = postcard_bytes(&Down::Stop);
    trailing.push(0);
    assert_eq!(
        decode_fresh::<Down>(&mut hand_frame(LINK_VERSION, &trailing)),
        Err(FrameError::Malformed)
    );
    let sensor = postcard_bytes(&all_down(5, 1.0)[4]);
    assert_eq!(
        decode_fresh::<Down>(&mut hand_frame(LINK_VERSION, &sensor[..sensor.len() - 1])),
        Err(FrameError::Malformed)
    );
    assert_eq!(
        decode_body::<Up>(&frame_of(&Down::Start)),
        Err(FrameError::Malformed)
    );
    assert_eq!(
        decode_fresh::<Down>(&mut hand_frame(LINK_VERSION, &[])),
        Err(FrameError::Malformed)
    );
    // Each refusal counts under its reason.
    let corrupt = [
        FrameError::Empty,
        FrameError::TooLong,
        FrameError::Cobs,
        FrameError::TooShort,
        FrameError::Version { got: 1 },
        FrameError::Checksum,
        FrameError::Malformed,
    ];
    for e in corrupt {
        assert_eq!(e.refusal(), Refusal::Corrupt, "{e:?}");
    }
    assert_eq!(FrameError::Authentication.refusal(), Refusal::Auth);
    assert_eq!(
        FrameError::Replay {
            freshness: 3,
            last: 4
        }
        .refusal(),
        Refusal::Replay
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
            got = Some(decode_fresh::<Down>(r.unwrap()));
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
    stats.record::<()>(&Err(FrameError::Authentication));
    stats.record::<()>(&Err(FrameError::Cobs));
    assert_eq!((stats.accepted, stats.rejected), (1, 3));
    assert_eq!(
        stats.refused,
        RefusalCounts {
            auth: 1,
            replay: 0,
            corrupt: 2
        }
    );
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
        prop::array::uniform12(any_f32()),
        any::<u32>(),
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
                    specific_force_x_mps2: v[11],
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
        (any::<u32>(), any::<u8>(), any_refusals()),
        prop::option::of(any_plan_event()),
    )
        .prop_map(
            |(
                (seq, mode, fault, control_ticks),
                f,
                (release_us, sent_us, control, watchdog_trips),
                (previous_response_us, sensor, refused),
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
                    sensor,
                    refused,
                    plan,
                })
            },
        );
    prop_oneof![
        any::<(u8, u16)>().prop_map(|(status, detail)| Up::Ready(ReadyFrame { status, detail })),
        actuation,
        (any::<(u32, u32, u32)>(), any_refusals()).prop_map(|((a, b, c), refused)| {
            Up::Done(DoneFrame {
                stack_high_water_bytes: a,
                stack_size_bytes: b,
                rejected_frames: c,
                refused,
            })
        }),
    ]
}

fn any_refusals() -> impl Strategy<Value = RefusalCounts> {
    any::<(u32, u32, u32)>().prop_map(|(auth, replay, corrupt)| RefusalCounts {
        auth,
        replay,
        corrupt,
    })
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
            AnyMsg::Down(_) => decode_fresh::<Down>(body).map(|m| frame_of(&m)),
            AnyMsg::Up(_) => decode_fresh::<Up>(body).map(|m| frame_of(&m)),
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
    fn the_frames_cobs_is_postcards_cobs_flavour_on_the_same_bytes(msg in any_msg()) {
        // `encode` encodes COBS in place; postcard's `Cobs` flavour (which the
        // frames were written with before) on the raw bytes gives the same frame,
        // long runs of non-zero bytes (random floats) and block ends included.
        let frame = msg.frame();
        let mut raw = vec![0u8; frame.len()];
        let n = cobs::decode(&frame[..frame.len() - 1], &mut raw).expect("valid COBS");
        raw.truncate(n);
        let mut buf = vec![0u8; MAX_FRAME_BYTES];
        let mut flavour = postcard::ser_flavors::Cobs::try_new(
            postcard::ser_flavors::Slice::new(&mut buf),
        )
        .expect("room");
        for &b in &raw {
            postcard::ser_flavors::Flavor::try_push(&mut flavour, b).expect("room");
        }
        let reference = postcard::ser_flavors::Flavor::finalize(flavour).expect("room");
        prop_assert_eq!(&frame[..], &reference[..]);
    }

    #[test]
    fn arbitrary_bytes_never_decode(mut bytes in prop::collection::vec(any::<u8>(), 0..700)) {
        let mut copy = bytes.clone();
        prop_assert!(decode_fresh::<Down>(&mut bytes).is_err());
        prop_assert!(decode_fresh::<Up>(&mut copy).is_err());
    }

    #[test]
    fn arbitrary_nonzero_bytes_never_decode(
        mut bytes in prop::collection::vec(1u8..=255, 1..600),
    ) {
        // No 0x00: only the COBS structure, version, length and CRC stand in the way.
        let mut copy = bytes.clone();
        prop_assert!(decode_fresh::<Down>(&mut bytes).is_err());
        prop_assert!(decode_fresh::<Up>(&mut copy).is_err());
    }

    #[test]
    fn arbitrary_stream_yields_no_message(bytes in prop::collection::vec(any::<u8>(), 0..2000)) {
        let mut reader = FrameReader::<MAX_FRAME_BYTES>::new();
        let mut stats = LinkStats::new();
        for b in bytes {
            if let Some(frame) = reader.push(b) {
                let r = frame.and_then(decode_fresh::<Down>);
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
                    match decode_fresh::<Down>(f) {
                        Ok(m) => Ok(frame_of(&m)),
                        Err(_) => decode_fresh::<Up>(&mut copy).map(|m| frame_of(&m)),
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

// ---------------------------------------------------------------------------
// Authentication (SecOC style): the tag, the freshness, the key, the streams
// ---------------------------------------------------------------------------

/// The raw frame (COBS undone, no delimiter) of `frame`.
fn raw_of(frame: &[u8]) -> Vec<u8> {
    ref_uncobs(frame.strip_suffix(&[0]).unwrap_or(frame))
}

#[test]
fn a_frame_with_one_flipped_mac_bit_is_refused() {
    let sensor = all_down(12, 3.5)[4];
    let frame = frame_of(&sensor);
    let raw = raw_of(&frame);
    // The tag: the 8 bytes before the CRC.
    let tag_at = raw.len() - CRC_BYTES - MAC_BYTES;
    for bit in 0..MAC_BYTES * 8 {
        let mut flipped = raw.clone();
        flipped[tag_at + bit / 8] ^= 1 << (bit % 8);
        // The CRC made to match again (anyone can): the tag alone refuses it.
        let mut resealed = reseal(flipped.clone());
        assert_eq!(
            decode_fresh::<Down>(&mut resealed),
            Err(FrameError::Authentication),
            "bit {bit}"
        );
        // The CRC left as it was: a frame damaged on the way, corrupt.
        let mut damaged = ref_cobs(&flipped);
        assert_eq!(
            decode_fresh::<Down>(&mut damaged),
            Err(FrameError::Checksum),
            "bit {bit}"
        );
    }
    // Untouched, it is accepted: the refusals above are the bit's.
    assert_eq!(decode_body::<Down>(&frame), Ok(sensor));
}

#[test]
fn a_replayed_frame_is_refused() {
    let mut tx = Authenticator::new(Stream::Down);
    let mut rx = Verifier::new(Stream::Down);
    let mut mac = LinkMac::new(&KEY);
    let msgs = all_down(9, -1.25);
    let frames: Vec<Vec<u8>> = msgs.iter().map(|m| frame_on(m, &mut tx)).collect();
    let mut decode_in = |frame: &[u8], rx: &mut Verifier| {
        let mut body = frame[..frame.len() - 1].to_vec();
        decode::<Down>(&mut body, &mut mac, rx)
    };
    assert_eq!(decode_in(&frames[0], &mut rx), Ok(msgs[0]));
    assert_eq!(decode_in(&frames[1], &mut rx), Ok(msgs[1]));
    assert_eq!(rx.last_accepted(), 2);
    // The same frame again, and an older one: authentic, not newer.
    assert_eq!(
        decode_in(&frames[1], &mut rx),
        Err(FrameError::Replay {
            freshness: 2,
            last: 2
        })
    );
    assert_eq!(
        decode_in(&frames[0], &mut rx),
        Err(FrameError::Replay {
            freshness: 1,
            last: 2
        })
    );
    assert_eq!(rx.last_accepted(), 2);
    // A gap (frames 3 and 4 lost) is accepted; then 3 and 4 are old.
    assert_eq!(decode_in(&frames[4], &mut rx), Ok(msgs[4]));
    assert_eq!(
        decode_in(&frames[3], &mut rx),
        Err(FrameError::Replay {
            freshness: 4,
            last: 5
        })
    );
    assert_eq!(decode_in(&frames[5], &mut rx), Ok(msgs[5]));
}

#[test]
fn the_receiver_takes_a_freshness_only_from_a_frame_it_accepts() {
    let mut mac = LinkMac::new(&KEY);
    let mut rx = Verifier::new(Stream::Down);
    // Authentic and fresh, but not a message: refused, the freshness not taken.
    let mut bad = ref_cobs(&hand_raw(&KEY, Stream::Down, 7, LINK_VERSION, &[9]));
    assert_eq!(
        decode::<Down>(&mut bad, &mut mac, &mut rx),
        Err(FrameError::Malformed)
    );
    // Forged with a freshness far ahead: refused, not taken either (a forger
    // cannot push the receiver's freshness past the sender's).
    let payload = postcard_bytes(&Down::Stop);
    let mut forged = ref_cobs(&hand_raw(
        b"not-the-link-key",
        Stream::Down,
        u32::MAX,
        LINK_VERSION,
        &payload,
    ));
    assert_eq!(
        decode::<Down>(&mut forged, &mut mac, &mut rx),
        Err(FrameError::Authentication)
    );
    assert_eq!(rx.last_accepted(), 0);
    let mut good = ref_cobs(&hand_raw(&KEY, Stream::Down, 7, LINK_VERSION, &payload));
    assert_eq!(decode::<Down>(&mut good, &mut mac, &mut rx), Ok(Down::Stop));
    assert_eq!(rx.last_accepted(), 7);
}

#[test]
fn frames_of_one_stream_do_not_verify_on_another() {
    let msg = Down::Stop;
    for from in [Stream::Down, Stream::Route, Stream::Up] {
        let frame = frame_on(&msg, &mut Authenticator::new(from));
        for to in [Stream::Down, Stream::Route, Stream::Up] {
            let mut body = frame[..frame.len() - 1].to_vec();
            let r = decode::<Down>(&mut body, &mut LinkMac::new(&KEY), &mut Verifier::new(to));
            if from == to {
                assert_eq!(r, Ok(msg));
            } else {
                assert_eq!(r, Err(FrameError::Authentication), "{from:?} on {to:?}");
            }
        }
    }
    let ids = [Stream::Down, Stream::Route, Stream::Up].map(Stream::data_id);
    assert!(ids[0] != ids[1] && ids[1] != ids[2] && ids[0] != ids[2]);
}

#[test]
fn a_sender_refuses_to_wrap_its_freshness() {
    let mut mac = LinkMac::new(&KEY);
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let mut tx = Authenticator::resumed(Stream::Up, u32::MAX - 1);
    assert!(encode(
        &Up::Ready(ReadyFrame {
            status: 0,
            detail: 0
        }),
        &mut mac,
        &mut tx,
        &mut buf
    )
    .is_ok());
    assert_eq!(tx.last_sent(), u32::MAX);
    assert_eq!(
        encode(
            &Up::Ready(ReadyFrame {
                status: 0,
                detail: 0
            }),
            &mut mac,
            &mut tx,
            &mut buf
        ),
        Err(FrameError::FreshnessExhausted)
    );
    assert_eq!(tx.last_sent(), u32::MAX);
    // A receiver resumed at the last value refuses that frame again.
    let frame = largest(&Down::Stop, Stream::Down);
    let mut body = frame[..frame.len() - 1].to_vec();
    let mut rx = Verifier::resumed(Stream::Down, u32::MAX);
    assert_eq!(
        decode::<Down>(&mut body, &mut mac, &mut rx),
        Err(FrameError::Replay {
            freshness: u32::MAX,
            last: u32::MAX
        })
    );
}

#[test]
fn the_build_key_is_the_documented_development_key_unless_set() {
    if !LINK_KEY_FROM_ENV {
        assert_eq!(LINK_KEY, *b"DEV-ONLY-SIM-KEY");
    }
    // Either way, the frames of this build verify under its key and not under
    // another.
    let mut tx = Authenticator::new(Stream::Up);
    let mut buf = [0u8; MAX_FRAME_BYTES];
    let n = encode(
        &Up::Ready(ReadyFrame {
            status: 3,
            detail: 4,
        }),
        &mut LinkMac::new(&LINK_KEY),
        &mut tx,
        &mut buf,
    )
    .unwrap();
    let mut a = buf[..n - 1].to_vec();
    let mut b = a.clone();
    assert!(decode::<Up>(
        &mut a,
        &mut LinkMac::new(&LINK_KEY),
        &mut Verifier::new(Stream::Up)
    )
    .is_ok());
    let mut other = LINK_KEY;
    other[15] ^= 1;
    assert_eq!(
        decode::<Up>(
            &mut b,
            &mut LinkMac::new(&other),
            &mut Verifier::new(Stream::Up)
        ),
        Err(FrameError::Authentication)
    );
}

#[test]
fn refusal_codes_round_trip_and_counts_add_up() {
    let mut names = std::collections::HashSet::new();
    for r in Refusal::ALL {
        assert_eq!(Refusal::from_code(r.code()), Some(r));
        assert_ne!(r.code(), 0, "0 is an accepted frame");
        assert_ne!(r.code(), SENSOR_UNEXPECTED);
        assert!(names.insert(r.name()));
    }
    assert_eq!(Refusal::from_code(0), None);
    assert_eq!(Refusal::from_code(SENSOR_UNEXPECTED), None);
    let mut c = RefusalCounts::new();
    c.count(Refusal::Auth);
    c.count(Refusal::Auth);
    c.count(Refusal::Corrupt);
    assert_eq!(
        (
            c.of(Refusal::Auth),
            c.of(Refusal::Replay),
            c.of(Refusal::Corrupt)
        ),
        (2, 0, 1)
    );
    assert_eq!(c.total(), 3);
    let sum = c.plus(RefusalCounts {
        auth: u32::MAX,
        replay: 5,
        corrupt: 0,
    });
    assert_eq!(
        sum,
        RefusalCounts {
            auth: u32::MAX,
            replay: 5,
            corrupt: 1
        }
    );
    assert_eq!(sum.total(), u32::MAX);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// `LinkMac`'s tags, fed a block at a time (decode) or a byte at a time
    /// (encode), are the keyed BLAKE2s of the RustCrypto crate's own interface, for
    /// every length (whole last blocks included).
    #[test]
    fn link_mac_tags_are_the_reference_blake2s(
        input in prop::collection::vec(any::<u8>(), 0..700),
        key in any::<[u8; 16]>(),
    ) {
        for stream in [Stream::Down, Stream::Route, Stream::Up] {
            let mut reference = vec![stream.data_id()];
            reference.extend_from_slice(&input);
            let expected = ref_tag(&key, &reference);
            let mut mac = LinkMac::new(&key);
            prop_assert_eq!(mac.tag(stream, &input), expected);
            prop_assert!(mac.verify(stream, &input, &expected));
            let mut wrong = expected;
            wrong[0] ^= 0x80;
            prop_assert!(!mac.verify(stream, &input, &wrong));
        }
    }

    /// Frames encoded one after the other (a byte at a time through the MAC) are
    /// those built by hand with the reference MAC, freshness counting up.
    #[test]
    fn encoded_frames_are_the_hand_built_ones(msgs in prop::collection::vec(any_msg(), 1..6)) {
        let mut tx = Authenticator::new(Stream::Up);
        for (k, msg) in msgs.iter().enumerate() {
            let (frame, payload) = match msg {
                AnyMsg::Down(m) => (frame_on(m, &mut tx), postcard_bytes(m)),
                AnyMsg::Up(m) => (frame_on(m, &mut tx), postcard_bytes(m)),
            };
            let mut expected = ref_cobs(&hand_raw(&KEY, Stream::Up, k as u32 + 1, LINK_VERSION, &payload));
            expected.push(0);
            prop_assert_eq!(frame, expected);
        }
    }

    /// Any bit of the tag flipped, the CRC made to match: refused as forged.
    #[test]
    fn any_flipped_tag_bit_is_refused_as_forged(msg in any_msg(), bit in 0..MAC_BYTES * 8) {
        let frame = msg.frame();
        let mut raw = raw_of(&frame);
        let tag_at = raw.len() - CRC_BYTES - MAC_BYTES;
        raw[tag_at + bit / 8] ^= 1 << (bit % 8);
        let mut body = reseal(raw);
        prop_assert_eq!(msg.decode_like(&mut body), Err(FrameError::Authentication));
    }
}

/// The frames' CRC, four bits a step: CRC-32/ISO-HDLC's check value, and the
/// `crc` crate's byte-table CRC on any bytes.
#[test]
fn the_frames_crc_is_crc32_iso_hdlc() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    assert_eq!(crc32(b""), 0);
}

proptest! {
    #[test]
    fn the_frames_crc_matches_the_crc_crate(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let reference = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
        prop_assert_eq!(crc32(&bytes), reference.checksum(&bytes));
    }
}

// ---------------------------------------------------------------------------
// The newest whole frame (the flashed build's real-time receiver)
// ---------------------------------------------------------------------------

/// Sensor frames `seqs` from one down-stream sender, back to back.
fn sensor_stream(seqs: &[u32]) -> Vec<u8> {
    let mut tx = Authenticator::new(Stream::Down);
    seqs.iter()
        .flat_map(|&seq| {
            frame_on(
                &Down::Sensor(SensorFrame {
                    seq,
                    estimate: estimate(u64::from(seq) * 10_000, seq as f32),
                    route_frames: 0,
                }),
                &mut tx,
            )
        })
        .collect()
}

/// The sequence number of the newest frame `r` holds, decoded by `rx`.
fn newest_seq<const N: usize>(r: &mut NewestFrameReader<N>, rx: &mut Verifier) -> Option<u32> {
    let frame = r.take_newest()?;
    match decode::<Down>(frame, &mut LinkMac::new(&KEY), rx) {
        Ok(Down::Sensor(f)) => Some(f.seq),
        other => panic!("not a sensor frame: {other:?}"),
    }
}

#[test]
fn the_newest_whole_frame_supersedes_older_ones_and_a_partial_one_waits() {
    let bytes = sensor_stream(&[7, 8, 9]);
    let first_two = bytes.iter().filter(|&&b| b == 0).count();
    assert_eq!(first_two, 3, "three frames, three delimiters");
    // Two whole frames and half of the third arrive before a release.
    let cut = bytes.len() - 10;
    let mut r: NewestFrameReader<MAX_DRIVING_DOWN_FRAME_BYTES> = NewestFrameReader::new();
    let mut rx = Verifier::new(Stream::Down);
    let ended: Vec<_> = bytes[..cut].iter().filter_map(|&b| r.push(b)).collect();
    assert_eq!(ended, [Ok(()), Ok(())]);
    // The release takes the newest (8, not 7: the late one is superseded, and
    // the freshness check accepts the gap).
    assert_eq!(newest_seq(&mut r, &mut rx), Some(8));
    assert_eq!(r.take_newest().map(|f| f.len()), None, "taken once");
    // The rest of the third frame arrives: it was kept whole across the take.
    for &b in &bytes[cut..] {
        let _ = r.push(b);
    }
    assert_eq!(newest_seq(&mut r, &mut rx), Some(9));
}

#[test]
fn an_over_long_newest_frame_leaves_no_frame_to_take() {
    let good = sensor_stream(&[1]);
    let mut r: NewestFrameReader<MAX_DRIVING_DOWN_FRAME_BYTES> = NewestFrameReader::new();
    for &b in &good {
        let _ = r.push(b);
    }
    // A frame longer than the buffer after it: the newest frame is that refused
    // one, not the older good frame.
    let long = [0x55u8; MAX_DRIVING_DOWN_FRAME_BYTES + 5];
    let ended: Vec<_> = long.iter().filter_map(|&b| r.push(b)).collect();
    assert!(ended.is_empty());
    assert_eq!(r.push(0), Some(Err(FrameError::TooLong)));
    assert!(r.take_newest().is_none());
    // The stream recovers at the next whole frame.
    let next = sensor_stream(&[1, 2]);
    for &b in &next[good.len()..] {
        let _ = r.push(b);
    }
    assert_eq!(
        newest_seq(&mut r, &mut Verifier::new(Stream::Down)),
        Some(2)
    );
    r.reset();
    assert!(r.take_newest().is_none());
}

proptest! {
    /// Whatever the split of a stream of whole frames into releases, each
    /// release's newest frame is the last one that ended in it.
    #[test]
    fn each_release_takes_the_last_frame_that_ended_in_it(
        cuts in proptest::collection::vec(0usize..400, 0..6),
    ) {
        let seqs: Vec<u32> = (1..=5).collect();
        let bytes = sensor_stream(&seqs);
        let ends: Vec<usize> = bytes.iter().enumerate().filter(|(_, &b)| b == 0).map(|(i, _)| i).collect();
        let mut cuts: Vec<usize> = cuts.into_iter().map(|c| c.min(bytes.len())).collect();
        cuts.push(bytes.len());
        cuts.sort_unstable();
        let mut r: NewestFrameReader<MAX_DRIVING_DOWN_FRAME_BYTES> = NewestFrameReader::new();
        let mut rx = Verifier::new(Stream::Down);
        let mut from = 0;
        for cut in cuts {
            for &b in &bytes[from..cut] {
                let _ = r.push(b);
            }
            let expected = ends
                .iter()
                .rposition(|&e| e >= from && e < cut)
                .map(|k| seqs[k]);
            prop_assert_eq!(newest_seq(&mut r, &mut rx), expected);
            from = cut;
        }
    }
}

// ---------------------------------------------------------------------------
// The USART interrupt's receive budgets (`link::usart::RxBudgets`)
// ---------------------------------------------------------------------------

#[test]
fn the_receive_budgets_spend_the_control_periods_first_then_the_plan_periods() {
    use firmware::link::usart::{RxBudgets, ROUTE_RX_BUDGET_BYTES, SENSOR_RX_BUDGET_BYTES};
    let b = RxBudgets::new();
    // Before any renewal the line takes nothing.
    assert!(!b.spend());
    b.renew_control();
    b.renew_plan();
    let both = u32::from(SENSOR_RX_BUDGET_BYTES) + u32::from(ROUTE_RX_BUDGET_BYTES);
    assert_eq!(b.left(), both);
    // A sensor frame's bytes come from the control period's budget: the plan
    // period's is whole after them.
    for _ in 0..SENSOR_RX_BUDGET_BYTES {
        assert!(b.spend());
    }
    assert_eq!(b.left(), u32::from(ROUTE_RX_BUDGET_BYTES));
    // A control release renews its own budget only.
    b.renew_control();
    assert_eq!(b.left(), both);
    let mut taken = 0;
    while b.spend() {
        taken += 1;
    }
    assert_eq!(taken, both);
    // A renewal stores, never adds: two in a row give one budget.
    b.renew_plan();
    b.renew_plan();
    assert_eq!(b.left(), u32::from(ROUTE_RX_BUDGET_BYTES));
}

proptest! {
    /// Whatever the line sends and whenever the tasks renew, the bytes taken are
    /// at most one budget per renewal: what the response-time analysis charges
    /// the link's interrupt (`ENTRIES_PER_BUDGET`, `ENTRIES_PER_PLAN_BUDGET`).
    #[test]
    fn the_receive_budgets_admit_no_more_than_their_renewals(
        ops in proptest::collection::vec(0u8..10, 0..3_000)
    ) {
        use firmware::link::usart::{RxBudgets, ROUTE_RX_BUDGET_BYTES, SENSOR_RX_BUDGET_BYTES};
        let b = RxBudgets::new();
        let (mut control, mut plan, mut taken) = (0u64, 0u64, 0u64);
        for op in ops {
            match op {
                0 => { b.renew_control(); control += 1; }
                1 => { b.renew_plan(); plan += 1; }
                _ => {
                    let left = b.left();
                    let took = b.spend();
                    // A byte is refused only with both budgets spent.
                    prop_assert_eq!(took, left > 0);
                    taken += u64::from(took);
                }
            }
            prop_assert!(
                taken <= control * u64::from(SENSOR_RX_BUDGET_BYTES)
                    + plan * u64::from(ROUTE_RX_BUDGET_BYTES)
            );
        }
    }
}
