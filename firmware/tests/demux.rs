//! Tests of the sorting of one link's frames into the control and route channels
//! (`firmware::link::demux`): every frame reaches its channel whole and in order,
//! whatever the frames around it, and garbage only costs the frame it hits.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::link::demux::{
    channel_of_message, Channel, Demux, Sorter, PATH_CHUNK_TAG, WINDOW_TAG,
};
use firmware::link::*;
use firmware::state_estimate::StateEstimate;
use firmware::vehicle_config::VehicleConfig;
use proptest::prelude::*;

/// The frames of `msgs`, delimiters included, each on its channel's stream (the
/// control channel's `Down`, the route channel's `Route`), as the host sends them.
fn frames_of(msgs: &[Down]) -> Vec<u8> {
    let mut mac = LinkMac::new(&LINK_KEY);
    let (mut down, mut route) = (
        Authenticator::new(Stream::Down),
        Authenticator::new(Stream::Route),
    );
    let mut out = Vec::new();
    for msg in msgs {
        let tx = match channel_of_message(msg) {
            Channel::Control => &mut down,
            Channel::Route => &mut route,
        };
        let mut buf = [0u8; MAX_FRAME_BYTES];
        let n = encode(msg, &mut mac, tx, &mut buf).unwrap();
        out.extend_from_slice(&buf[..n]);
    }
    out
}

/// The whole frame of `msg` alone, delimiter included.
fn frame_of(msg: &Down) -> Vec<u8> {
    frames_of(std::slice::from_ref(msg))
}

/// The stream sorted: each channel's bytes.
fn sort(stream: &[u8]) -> (Vec<u8>, Vec<u8>) {
    let mut d = Demux::new();
    let (mut control, mut route) = (Vec::new(), Vec::new());
    for &b in stream {
        if let Some(e) = d.push(b) {
            match e.channel {
                Channel::Control => control.extend_from_slice(e.bytes()),
                Channel::Route => route.extend_from_slice(e.bytes()),
            }
        }
    }
    (control, route)
}

/// The messages a channel's bytes decode to (refused frames left out).
fn messages(bytes: &[u8], channel: Channel) -> (Vec<Down>, usize) {
    let mut mac = LinkMac::new(&LINK_KEY);
    let mut rx = Verifier::new(match channel {
        Channel::Control => Stream::Down,
        Channel::Route => Stream::Route,
    });
    let mut reader: FrameReader<MAX_FRAME_BYTES> = FrameReader::new();
    let (mut out, mut refused) = (Vec::new(), 0);
    for &b in bytes {
        match reader.push(b) {
            None => {}
            Some(Ok(frame)) => match decode::<Down>(frame, &mut mac, &mut rx) {
                Ok(m) => out.push(m),
                Err(_) => refused += 1,
            },
            Some(Err(_)) => refused += 1,
        }
    }
    (out, refused)
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
        wheel_speed_mps: [1.0, 2.0, 3.0, 4.0],
        specific_force_x_mps2: -0.75,
    }
}

/// A message of each kind, numbered `k`, with the value `v` in its fields.
fn message(kind: u8, k: u32, v: f32) -> Down {
    match kind % 7 {
        0 => Down::Config(ConfigFrame {
            vehicle: VehicleConfig {
                l_f_m: v,
                l_r_m: v,
                cg_height_m: v,
                width_m: v,
                length_m: v,
                mass_kg: v,
                wheel_radius_m: v,
                max_steer_rad: v,
            },
            mu_planner: v,
            closed: k.is_multiple_of(2),
            path_rows: k as u16,
            obstacles: k as u8,
        }),
        1 => Down::PathChunk(PathChunkFrame {
            first: k as u16,
            count: PATH_CHUNK_ROWS as u8,
            rows: [[v, -v, v, v]; PATH_CHUNK_ROWS],
        }),
        2 => Down::Obstacle(ObstacleFrame {
            index: k as u8,
            total: k as u8,
            id: k,
            count: 4,
            vertices: [[v, -v]; firmware::obstacles::MAX_VERTICES],
        }),
        3 => Down::Start,
        4 => Down::Sensor(SensorFrame {
            seq: k,
            estimate: estimate(u64::from(k) * 10_000, v),
            route_frames: k % 3,
        }),
        5 => Down::Stop,
        _ => Down::Window(WindowFrame {
            rows: k as u16,
            origin_m: v,
            closed: false,
        }),
    }
}

#[test]
fn the_route_tags_are_the_messages_own() {
    // The tag is the raw frame's second byte: COBS leaves it in place (third
    // byte of the frame) when the version and the tag are not zero.
    let chunk = frame_of(&message(1, 3, 1.5));
    let window = frame_of(&message(6, 3, 1.5));
    assert_eq!((chunk[1], chunk[2]), (LINK_VERSION, PATH_CHUNK_TAG));
    assert_eq!((window[1], window[2]), (LINK_VERSION, WINDOW_TAG));
    // `Config`'s tag is 0: its code byte says so.
    let config = frame_of(&message(0, 3, 1.5));
    assert_eq!((config[0], config[1]), (2, LINK_VERSION));
}

#[test]
fn a_frame_shorter_than_its_head_goes_to_control_and_the_stream_goes_on() {
    let mut stream = vec![5, 7, 0, 0, 1, 0];
    let sensor = message(4, 9, 2.0);
    let chunk = message(1, 9, 2.0);
    stream.extend(frames_of(&[sensor, chunk]));
    let (control, route) = sort(&stream);
    let (got, refused) = messages(&control, Channel::Control);
    assert_eq!(got, vec![sensor]);
    assert_eq!(
        refused, 2,
        "the two short frames are refused, the empty one idle"
    );
    assert_eq!(messages(&route, Channel::Route), (vec![chunk], 0));
}

/// The stream sorted by a [`Sorter`] in batches of the given sizes (cycled), its
/// held bytes taken after each batch as the ECU does: after each batch, the
/// bytes of the stream so far and each channel's; and the most bytes held after
/// a push.
#[allow(clippy::type_complexity)]
fn sort_one_by_one(stream: &[u8], batches: &[usize]) -> (Vec<(usize, Vec<u8>, Vec<u8>)>, usize) {
    let mut s = Sorter::new();
    let (mut control, mut route) = (Vec::new(), Vec::new());
    let mut snapshots = Vec::new();
    let mut most_held = 0;
    let mut done = 0;
    for &n in batches.iter().cycle() {
        if done == stream.len() {
            break;
        }
        let end = (done + n.max(1)).min(stream.len());
        let mut handed = Vec::new();
        for &b in &stream[done..end] {
            handed.extend(s.push(b));
            let mut probe = s;
            let mut held = 0;
            while probe.take_held().is_some() {
                held += 1;
            }
            most_held = most_held.max(held);
        }
        for _ in 0..Sorter::MAX_HELD_AFTER_PUSH {
            handed.extend(s.take_held());
        }
        assert!(
            s.take_held().is_none(),
            "more held than MAX_HELD_AFTER_PUSH"
        );
        for (c, b) in handed {
            match c {
                Channel::Control => control.push(b),
                Channel::Route => route.push(b),
            }
        }
        done = end;
        snapshots.push((done, control.clone(), route.clone()));
    }
    (snapshots, most_held)
}

proptest! {
    /// The sorter that hands over a byte per byte gives each channel the same
    /// bytes as the demultiplexer, whatever the stream (garbage, short frames,
    /// runs of delimiters, route tags) and however it is cut into batches, and
    /// holds at most two bytes after a push.
    #[test]
    fn one_byte_per_byte_sorting_gives_each_channel_the_same_bytes(
        stream in prop::collection::vec(
            prop_oneof![Just(0u8), Just(1u8), Just(2u8), Just(PATH_CHUNK_TAG), Just(WINDOW_TAG), any::<u8>()],
            0..400,
        ),
        batches in prop::collection::vec(1usize..80, 1..8),
    ) {
        let (snapshots, most_held) = sort_one_by_one(&stream, &batches);
        for (done, control, route) in snapshots {
            prop_assert_eq!((control, route), sort(&stream[..done]));
        }
        prop_assert!(most_held <= Sorter::MAX_HELD_AFTER_PUSH, "{} held", most_held);
    }

    /// Any sequence of frames: each channel decodes exactly its frames, in order.
    #[test]
    fn every_frame_reaches_its_channel_whole_and_in_order(
        kinds in prop::collection::vec((0u8..7, any::<u32>(), -1.0e6f32..1.0e6), 1..40),
    ) {
        let msgs: Vec<Down> = kinds.iter().map(|&(kind, k, v)| message(kind, k, v)).collect();
        let stream = frames_of(&msgs);
        let (control, route) = sort(&stream);
        let want = |c: Channel| -> Vec<Down> {
            msgs.iter().filter(|m| channel_of_message(m) == c).copied().collect()
        };
        prop_assert_eq!(messages(&control, Channel::Control), (want(Channel::Control), 0));
        prop_assert_eq!(messages(&route, Channel::Route), (want(Channel::Route), 0));
        // No byte is lost or made up: the channels hold the stream's bytes.
        prop_assert_eq!(control.len() + route.len(), stream.len());
    }

    /// Garbage between frames (ending with a delimiter) costs no frame after it.
    #[test]
    fn garbage_costs_only_itself(
        kinds in prop::collection::vec((0u8..7, any::<u32>()), 1..12),
        garbage in prop::collection::vec(1u8..=255, 0..40),
    ) {
        let msgs: Vec<Down> = kinds.iter().map(|&(kind, k)| message(kind, k, 0.5)).collect();
        let mut stream = garbage.clone();
        stream.push(0);
        stream.extend(frames_of(&msgs));
        let (control, route) = sort(&stream);
        let (got_control, _) = messages(&control, Channel::Control);
        let (got_route, refused_route) = messages(&route, Channel::Route);
        let want = |c: Channel| -> Vec<Down> {
            msgs.iter().filter(|m| channel_of_message(m) == c).copied().collect()
        };
        prop_assert_eq!(got_route, want(Channel::Route));
        // Garbage that looks like a route frame's head is refused there, never
        // decoded; the control channel gets all its frames after the garbage.
        prop_assert!(refused_route <= 1);
        let tail = &got_control[got_control.len() - want(Channel::Control).len()..];
        prop_assert_eq!(tail.to_vec(), want(Channel::Control));
    }
}
