//! Frames between the ECU and the simulator (processor-in-the-loop).
//!
//! The ECU (in QEMU) and the host simulator exchange, every 10 ms control period,
//! one [`Down::Sensor`] frame and one [`Up::Actuation`] frame, after a set-up
//! phase (`Config`, the first window's `PathChunk`s, `Obstacle`s, `Start` →
//! `Ready`) and before a `Stop` → `Done`. While driving, the next window of the
//! road arrives as `PathChunk`s then a [`Down::Window`] (the ECU holds a window,
//! not the whole circuit). Version 2 added `Window` and
//! [`PlanEventFrame::window_ticks`]. Version 3: the ECU watches its own deadlines
//! ([`crate::deadline`]): [`ActuationFrame`] carries its release and send
//! instants and the control task's counts ([`TaskTimingFrame`]) and watchdog
//! trips, [`PlanEventFrame`] its end instant and the plan task's counts;
//! [`SensorFrame::route_frames`] announces the frames of a window of the road sent
//! on the route channel (the plan task receives them); the fault codes
//! [`FAULT_HARDFAULT`] and [`FAULT_DEADLINE`]. Version 4: an activation adopts a
//! new window of the road instead of planning ([`PlanEventFrame::status`]
//! [`PLAN_WINDOW`], its time in `window_ticks`). Version 5: that activation also
//! receives the window's frames (before, the activation before it did, after
//! publishing). Version 7: the control task completes when its actuation frame
//! has been written, so each [`ActuationFrame`] reports the previous
//! activation's response time ([`ActuationFrame::previous_response_us`]) and
//! counts up to it. Version 8: every frame is authenticated ([`secoc`], AUTOSAR
//! SecOC style: a freshness value and a truncated AES-128-CMAC); a receiver
//! refuses a forged, replayed or corrupt frame, counts it by reason
//! ([`Refusal`]) and never acts on it; the ECU reports its counts
//! ([`ActuationFrame::refused`], [`DoneFrame::refused`]) and whether this
//! period's sensor frame was refused ([`ActuationFrame::sensor`]). Version 9:
//! the state estimate carries the four wheel speeds
//! ([`StateEstimate::wheel_speed_mps`], 16 bytes more in a [`SensorFrame`]).
//! Version 10: the tag is keyed BLAKE2s instead of AES-128-CMAC ([`secoc`]
//! says why). Version 11: the state estimate carries the accelerometer's
//! specific force ([`StateEstimate::specific_force_x_mps2`], 4 bytes more).
//! Everything here works on fixed buffers: no heap, no `alloc`, no panic; every
//! refused frame is a [`FrameError`] value the receiver counts.
//!
//! # Wire format
//!
//! ```text
//! body  = [ LINK_VERSION ] ++ postcard(message) ++ freshness ++ tag
//!           1 byte           n bytes               4 bytes      8 bytes
//! raw   = body ++ crc32_le(body)
//!                4 bytes, little-endian
//!
//!         ┌─────────┬────────────────────────────┬───────────┬─────────┬──────────┐
//! raw     │ version │ postcard payload (n bytes) │ freshness │   tag   │ crc32_le │
//!         └─────────┴────────────────────────────┴───────────┴─────────┴──────────┘
//!           └───────────── MAC input (after the stream's Data ID) ───┘
//!           └──────────────────────── covered by the CRC ────────────────┘
//!
//!         ┌──────────────────────────────────────────────────────────┬──────┐
//! frame   │ COBS(raw): n + 17 + 1 + ⌊(n + 17) / 254⌋ bytes at most, no 0x00 │ 0x00 │
//!         └──────────────────────────────────────────────────────────┴──────┘
//! ```
//!
//! * **Payload**: [postcard] v1 encoding of a [`Down`] or [`Up`]: the enum
//!   variant as a varint (`Down`: `Config` 0, `PathChunk` 1, `Obstacle` 2,
//!   `Start` 3, `Sensor` 4, `Stop` 5, `Window` 6; `Up`: `Ready` 0, `Actuation` 1,
//!   `Done` 2),
//!   then the fields in declaration order; `f32` as 4 bytes little-endian
//!   (NaN bits are kept), `u8`/`bool` as one byte, `u16`/`u32`/`u64` as LEB128
//!   varints (at most 3/5/10 bytes), `Option` as a 0/1 byte then the value,
//!   arrays as their elements back to back (no length).
//! * **Freshness** ([`FRESHNESS_BYTES`]): the stream's counter ([`Authenticator`]),
//!   a `u32` little-endian, 1 for a stream's first frame, +1 for each frame sent.
//!   Three streams, each with its own counter: host → ECU on the control channel
//!   ([`Stream::Down`]), host → ECU on the route channel ([`Stream::Route`]),
//!   ECU → host ([`Stream::Up`]).
//! * **Tag** ([`MAC_BYTES`]): keyed BLAKE2s with an 8-byte output under the link key
//!   ([`LINK_KEY`], set at build time) of the stream's Data ID
//!   ([`Stream::data_id`], one byte, not sent) ++ version ++ payload ++
//!   freshness ([`secoc`] says why these sizes).
//! * **CRC**: CRC-32/ISO-HDLC (the zlib/Ethernet CRC, [`crc32`]; four bits a step, a 64-byte table)
//!   of the version byte, the payload, the freshness and the tag, appended
//!   little-endian. It tells a frame damaged on the way (*corrupt*) from one
//!   whose tag was made without the key (*forged*), which the tag alone cannot.
//! * **Framing**: consistent-overhead byte stuffing (COBS) of the whole raw frame,
//!   so the encoded frame holds no 0x00, then one 0x00 delimiter. [`encode`] is
//!   postcard's `Cobs` and `CrcModifier` flavours under the MAC's, [`decode`]
//!   the `cobs` crate's decoder, the `crc` crate's checksum and the MAC before
//!   postcard reads the payload. A receiver that lost sync skips to the next
//!   0x00 ([`FrameReader`]); empty frames (two delimiters in a row) are idle and
//!   ignored.
//!
//! A receiver ([`decode`], with the stream's [`Verifier`]) refuses, in this order:
//! a frame that is not a well-formed frame of this version (COBS, length,
//! version, CRC: [`Refusal::Corrupt`]), one whose tag does not verify
//! ([`FrameError::Authentication`], [`Refusal::Auth`]), one whose freshness is
//! not newer than the last it accepted on the stream ([`FrameError::Replay`],
//! [`Refusal::Replay`]), one whose message postcard cannot read
//! ([`Refusal::Corrupt`]).
//!
//! The largest frames: [`MAX_DOWN_FRAME_BYTES`] (a `PathChunk`) and
//! [`MAX_UP_FRAME_BYTES`] (an `Actuation` with a plan event), both including the
//! delimiter and checked at compile time against [`MAX_FRAME_BYTES`].
//!
//! # Status codes (the `u8` fields)
//!
//! * [`ActuationFrame::mode`]: [`mode_code`] (`Following` 0, `Extrapolating` 1,
//!   `Stopping` 2, `Safe` 3).
//! * [`ActuationFrame::fault`]: [`fault_code`] (0 none, `NonFiniteEstimate` 1,
//!   `NonFinitePlan` 2, `InvalidPlan` 3, `Numerical` 4).
//! * [`PlanEventFrame::status`]: [`mpc_status_code`] (0 optimal, `NonFiniteState`
//!   1, `InvalidFriction` 2, `InvalidSettings` 3, `NoPath` 4, `NonFinitePlan` 5,
//!   `Qp(s)` 0x10 +
//!   [`qp_status_code`]`(s)`, with `Optimal` 0, `NotSolved` 1, `IterationLimit` 2,
//!   `Infeasible` 3, `NotConvex` 4, `NumericalError` 5, `NonFiniteInput` 6,
//!   `InvalidInput` 7, `WorkingSetFull` 8), or [`PLAN_WINDOW`] (0x20) for an
//!   activation that adopted a window of the road instead of planning.
//! * [`ReadyFrame::status`]: 0 accepted, else a [`SetupError`] code.
//! * [`ActuationFrame::sensor`]: 0 accepted, else [`Refusal::code`] (`Auth` 1,
//!   `Replay` 2, `Corrupt` 3), [`SENSOR_UNEXPECTED`] (4) or [`SENSOR_MISSING`] (5,
//!   the flashed build's only).
//!
//! Each has a `*_from_code` inverse and a `*_name` for logs.
//!
//! # Behaviour worth knowing
//!
//! * [`SequenceCheck::accept`] returns `Result<u32, SequenceError>`: `Ok(missed)`
//!   with the count of skipped sequence numbers (0 in order), so a gap is
//!   accepted *and* reported.
//! * [`encode`] takes `M: Serialize + ?Sized`, the [`LinkMac`] and the stream's
//!   [`Authenticator`]; [`decode`] the [`LinkMac`] and the stream's [`Verifier`].
//! * [`decode`] reports trailing bytes after the message as
//!   [`FrameError::Malformed`], and a frame longer than [`MAX_FRAME_BYTES`] − 1
//!   bytes as [`FrameError::TooLong`].
//! * [`FrameReader::push`] yields nothing for an empty frame (two delimiters in a
//!   row: idle line or resynchronisation); [`FrameError::Empty`] is what [`decode`]
//!   says of an empty slice.

use serde::{Deserialize, Serialize};

use crate::low_level::{ControlFault, Mode};
use crate::mpc::{MpcError, MpcReport};
use crate::obstacles::MAX_VERTICES;
use crate::plan::Plan;
use crate::state_estimate::StateEstimate;
use crate::vehicle_config::VehicleConfig;
use qp::QpStatus;

/// Version of this wire format, the first byte of every raw frame.
pub const LINK_VERSION: u8 = 11;
/// The largest encoded frame, bytes, including its 0x00 delimiter.
pub const MAX_FRAME_BYTES: usize = 512;
/// Track rows per [`PathChunkFrame`].
pub const PATH_CHUNK_ROWS: usize = 16;

/// Frames of one window of `rows` rows of the road on the route channel: its
/// [`PathChunkFrame`]s and its [`WindowFrame`], frames.
pub const fn route_frames(rows: usize) -> usize {
    rows.div_ceil(PATH_CHUNK_ROWS) + 1
}
/// Plan nodes in a [`PlanEventFrame`] (`HORIZON + 1`, the plan's node count).
pub const PLAN_NODES: usize = crate::plan::HORIZON + 1;

/// Bytes of the CRC at the end of a raw frame.
pub const CRC_BYTES: usize = 4;
/// [`ActuationFrame::sensor`] of an authentic, fresh frame on the control channel
/// that was neither `Sensor` nor `Stop` while driving (a host bug): not acted
/// on, the period a dropout.
pub const SENSOR_UNEXPECTED: u8 = 4;
/// [`ActuationFrame::sensor`] of a release at which no whole frame had arrived
/// (the flashed build's USART link, which does not run in lock-step with the
/// host: a frame may be late): no estimate, the period a dropout.
pub const SENSOR_MISSING: u8 = 5;
/// CRC-32/ISO-HDLC (the zlib/Ethernet CRC) of every frame: its reflected
/// polynomial.
const CRC32_POLY: u32 = 0xEDB8_8320;
/// The CRC's initial register and final XOR.
const CRC32_INIT: u32 = 0xFFFF_FFFF;
/// The CRC register's step over four bits, by those bits (64 B). The `crc`
/// crate's byte table is 1 KiB, and every constant of the ECU lives in its RAM
/// (`memory.x`: no wait states for the timing analysis to charge): two steps of
/// four bits per byte cost a few instructions more than one of eight and keep
/// 984 B of RAM. `firmware/tests/link.rs` checks it against the `crc` crate.
const CRC32_NIBBLES: [u32; 16] = {
    let mut table = [0u32; 16];
    let mut i = 0;
    while i < 16 {
        let mut c = i as u32;
        let mut bit = 0;
        while bit < 4 {
            c = if c & 1 != 0 {
                (c >> 1) ^ CRC32_POLY
            } else {
                c >> 1
            };
            bit += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

/// The CRC register `register` after the byte `b`: two steps of four bits.
#[inline(always)]
pub(crate) const fn crc32_byte(register: u32, b: u8) -> u32 {
    let c = register ^ b as u32;
    let c = (c >> 4) ^ CRC32_NIBBLES[(c & 15) as usize];
    (c >> 4) ^ CRC32_NIBBLES[(c & 15) as usize]
}

/// Feeds the bytes `$data` (an iterator of `&u8`) into the CRC register
/// `$register` (a `u32` place, started at [`CRC32_INIT`]). A macro, not a
/// function: its loop is then the caller's line, where the timing analysis'
/// annotation of how many bytes that caller feeds sits (as the `crc` crate's
/// loop, a dependency's, was).
macro_rules! crc32_update {
    ($register:expr, $data:expr) => {{
        let mut c: u32 = $register;
        for &b in $data {
            c = $crate::link::crc32_byte(c, b);
        }
        $register = c;
    }};
}

/// CRC-32/ISO-HDLC of `data` (the check value of `b"123456789"` is
/// `0xCBF4_3926`).
pub fn crc32(data: &[u8]) -> u32 {
    let mut register = CRC32_INIT;
    crc32_update!(register, data);
    !register
}

// ---------------------------------------------------------------------------
// Messages
// ---------------------------------------------------------------------------

/// Host → ECU.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Down {
    /// Set-up: the car, the planner's friction, the track's size.
    Config(ConfigFrame),
    /// Set-up: `count` track rows `[x_m, y_m, w_right_m, w_left_m]` starting at row `first`.
    PathChunk(PathChunkFrame),
    /// Set-up: obstacle `index` of `total`, its polygon.
    Obstacle(ObstacleFrame),
    /// Set-up done: the ECU loads the path and obstacles and answers `Up::Ready`;
    /// then the timeline starts.
    Start,
    /// Every control period: the state estimate at `stamp_us`.
    Sensor(SensorFrame),
    /// End of the run: the ECU answers `Up::Done`.
    Stop,
    /// While driving: the `PathChunk` rows sent since the last `Window` (first row
    /// 0) are the next window of the road; the plan task's next activation receives
    /// it and adopts it instead of planning (version 2; version 4: the adoption's
    /// own activation; version 5: received by that activation too).
    Window(WindowFrame),
}

/// The next window of the reference path: the ECU holds a window of the road, not
/// the whole circuit, so its RAM does not grow with the track.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WindowFrame {
    /// Rows of the window (sent in `PathChunk` frames before this one), rows.
    pub rows: u16,
    /// Distance along the road of the window's first row, m (differences between
    /// windows are what matter: the MPC's warm start moves by them).
    pub origin_m: f32,
    /// The window is the whole of a closed circuit (its last row joins its first).
    pub closed: bool,
}

/// Set-up: what the ECU needs before the track.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConfigFrame {
    /// The car (SI units in each field); the ECU derives its settings from it.
    pub vehicle: VehicleConfig<f32>,
    /// Friction coefficient the planner assumes, dimensionless, > 0.
    pub mu_planner: f32,
    /// True when the first window is the whole of a closed circuit (its last row
    /// joins its first).
    pub closed: bool,
    /// Rows of the first window of the road, that follow in `PathChunk` frames, rows.
    pub path_rows: u16,
    /// Number of obstacles that will follow in `Obstacle` frames, obstacles.
    pub obstacles: u8,
}

/// Set-up: a chunk of the track's centre line.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PathChunkFrame {
    /// Index of the chunk's first row in the track, row.
    pub first: u16,
    /// Number of valid rows in `rows` (`≤ PATH_CHUNK_ROWS`), rows.
    pub count: u8,
    /// Track rows `[x_m, y_m, w_right_m, w_left_m]`: centre-line point in the global
    /// frame, m, and the road's half widths to the right and left of it, m. Rows at
    /// and past `count` are padding (send zeros).
    pub rows: [[f32; 4]; PATH_CHUNK_ROWS],
}

/// Set-up: one obstacle's polygon.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObstacleFrame {
    /// Index of this obstacle, `0..total`.
    pub index: u8,
    /// Number of obstacles in the set-up (equals [`ConfigFrame::obstacles`]).
    pub total: u8,
    /// The obstacle's identifier in the scenario (dimensionless, for logs).
    pub id: u32,
    /// Number of valid vertices in `vertices` (`≤ MAX_VERTICES`), vertices.
    pub count: u8,
    /// Polygon vertices `[x_m, y_m]` in the global frame, m; entries at and past
    /// `count` are padding.
    pub vertices: [[f32; 2]; MAX_VERTICES],
}

/// Every control period: the state estimate.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SensorFrame {
    /// Sequence number, dimensionless, +1 per sensor frame (the first is any value).
    pub seq: u32,
    /// The state estimate (its `stamp_us` is the simulated time, µs; SI units).
    pub estimate: StateEstimate<f32>,
    /// Frames of the road (`PathChunk`s then a `Window`) the host has written on
    /// the route channel since `Start`, in all, frames (version 8: a total, no
    /// longer those since the last sensor frame, so that a sensor frame refused
    /// loses no announcement; version 3 added it): the plan task's next
    /// activation reads those not yet announced (and adopts the window they
    /// complete).
    pub route_frames: u32,
}

/// ECU → host.
// No heap to box into: the enum is one value of its largest variant (≈ 240 bytes).
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Up {
    /// Answer to `Down::Start`: `status` 0 when the set-up was accepted, else an
    /// error code (see [`SetupError`]), `detail` an index (row/obstacle) or 0.
    Ready(ReadyFrame),
    /// Answer to every `Down::Sensor`: the actuation of that control activation,
    /// and what the plan task did since the last one.
    Actuation(ActuationFrame),
    /// Answer to `Down::Stop`.
    Done(DoneFrame),
}

/// An [`Up`] to encode, by reference: the same variants in the same order, so
/// the same bytes, without the message copied into an enum the size of the
/// largest variant (an actuation frame with its plan event) on the sender's
/// stack.
#[derive(Clone, Copy, Debug, Serialize)]
pub enum UpRef<'a> {
    /// [`Up::Ready`].
    Ready(&'a ReadyFrame),
    /// [`Up::Actuation`].
    Actuation(&'a ActuationFrame),
    /// [`Up::Done`].
    Done(&'a DoneFrame),
}

impl<'a> From<&'a Up> for UpRef<'a> {
    fn from(up: &'a Up) -> Self {
        match up {
            Up::Ready(r) => UpRef::Ready(r),
            Up::Actuation(a) => UpRef::Actuation(a),
            Up::Done(d) => UpRef::Done(d),
        }
    }
}

/// Answer to `Down::Start`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReadyFrame {
    /// 0 when the set-up was accepted, else a [`SetupError::code`].
    pub status: u8,
    /// The row or obstacle index the error concerns (see [`SetupError`]), else 0.
    pub detail: u16,
}

/// Answer to a `Down::Sensor`: one control activation's output.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ActuationFrame {
    /// The `seq` of the sensor frame this answers, dimensionless.
    pub seq: u32,
    /// Wheel torques `[FL, FR, RL, RR]`, N·m, positive driving forward.
    pub torque_nm: [f32; 4],
    /// Front steering angle commanded, rad (`δ = δ_ol + δ_cl`, saturated).
    pub delta_rad: f32,
    /// Open-loop (feed-forward) part of the steering angle, rad.
    pub delta_ol_rad: f32,
    /// Closed-loop (yaw PID) part of the steering angle, rad.
    pub delta_cl_rad: f32,
    /// Speed reference the speed PID tracked, m/s.
    pub v_ref_mps: f32,
    /// Controller mode, [`mode_code`] (`Following` 0, `Extrapolating` 1,
    /// `Stopping` 2, `Safe` 3).
    pub mode: u8,
    /// 0 none, else [`fault_code`] of the [`ControlFault`] that forced the safe
    /// actuation.
    pub fault: u8,
    /// ECU clock ticks (168 MHz) of this control activation's own work: the
    /// estimate stored and `ControlTask::run` under the plan's lock. The link's
    /// frame decoding and encoding (a stand-in for the vehicle's bus drivers) are
    /// not included.
    pub control_ticks: u32,
    /// The control release this activation ran at, µs on the ECU's timeline
    /// (release `k` at `k`·10 ms; version 3).
    pub release_us: u64,
    /// When this frame was sent, µs on the ECU's timeline: stamped once
    /// everything else it carries is final, immediately before it is encoded and
    /// written (an instant carried inside a frame's bytes cannot follow their
    /// encoding). The plant applies the actuation from then.
    pub sent_us: u64,
    /// Response time of the previous control activation, µs (saturated at
    /// `u32::MAX`): from its release to its completion, the instant its
    /// actuation frame had been written, which only the next frame can carry;
    /// 0 in the first frame, which has no previous activation (version 7).
    pub previous_response_us: u32,
    /// The control task's deadline counts up to the previous activation: its
    /// completion ([`ActuationFrame::previous_response_us`]) and the releases it
    /// skipped at its end; of this activation, only its release.
    pub control: TaskTimingFrame,
    /// Times the control task's watchdog saw no new plan for more than
    /// [`crate::deadline::PLAN_WATCHDOG_PERIODS`] plan periods, trips.
    pub watchdog_trips: u32,
    /// This period's sensor frame: 0 accepted, else the [`Refusal::code`] of its
    /// refusal (`Auth` 1, `Replay` 2, `Corrupt` 3) or [`SENSOR_UNEXPECTED`] for an
    /// authentic frame that was neither `Sensor` nor `Stop`, or [`SENSOR_MISSING`]
    /// when no whole frame had arrived (the flashed build's USART link). A refused frame is
    /// never acted on: the period ran on [`StateEstimate::unavailable`] (the
    /// dropout policy: the safe actuation, [`fault_code`] `NonFiniteEstimate`),
    /// and [`ActuationFrame::seq`] is then the one the ECU expected, the last
    /// accepted `seq` plus the periods since (version 8).
    pub sensor: u8,
    /// Frames the ECU refused since `Start`, by reason, on both its channels
    /// (the control channel's and the route channel's), frames (version 8).
    pub refused: RefusalCounts,
    /// The plan activation that finished since the last actuation frame, if any.
    pub plan: Option<PlanEventFrame>,
}

/// A task's deadline counts on the ECU's clock, cumulative since `Start` (see
/// [`crate::deadline::DeadlineCounts`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TaskTimingFrame {
    /// Releases that ran, activations.
    pub releases: u32,
    /// Late completions plus skipped releases, misses.
    pub deadline_misses: u32,
    /// Releases skipped because the task was still busy, releases.
    pub skipped_releases: u32,
    /// Activations over their cycle budget, activations.
    pub budget_overruns: u32,
    /// Largest response time, µs.
    pub max_response_us: u32,
}

impl From<crate::deadline::DeadlineCounts> for TaskTimingFrame {
    fn from(c: crate::deadline::DeadlineCounts) -> Self {
        Self {
            releases: c.releases,
            deadline_misses: c.deadline_misses,
            skipped_releases: c.skipped_releases,
            budget_overruns: c.budget_overruns,
            max_response_us: c.max_response_us,
        }
    }
}

/// One finished plan activation, as the ECU saw it.
// The derived serialize_field's loops found at this line are postcard's varint
// bytes of one integer field: at most 10 (a u64, 64 bits in 7-bit groups).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)] // wcet-bound: 10
pub struct PlanEventFrame {
    /// Plan activation number since `Start`, dimensionless (0 first).
    pub activation: u32,
    /// Release time of the activation (the estimate's stamp it planned from), µs.
    pub release_us: u64,
    /// Time the activation finished (its plan published or dropped), µs, on the
    /// same clock as `release_us`.
    pub finish_us: u64,
    /// Time the activation ended, µs (its event recorded; since version 5 it
    /// receives a window's frames before adopting, not after). The next release is
    /// the first not yet past then (version 3).
    pub end_us: u64,
    /// The plan task's deadline counts, this activation's completion and the
    /// releases it skipped included (version 3).
    pub timing: TaskTimingFrame,
    /// ECU clock ticks (168 MHz) of the plan task itself, preemption by the
    /// control task excluded.
    pub ticks: u32,
    /// 0 optimal, else [`mpc_status_code`], or [`PLAN_WINDOW`] (see the module
    /// docs for the mapping).
    pub status: u8,
    /// False when the plan was late (dropped) or failed.
    pub published: bool,
    /// MPC passes run (linearise-condense-solve), passes.
    pub passes: u8,
    /// Whether the MPC started from the previous plan (warm) rather than from
    /// zero inputs (a cold start: the first plan, or after 1.6 s without one);
    /// false for an activation that did not plan (version 6: with one pass on a
    /// cold start, `passes` no longer tells them apart).
    pub warm: bool,
    /// QP iterations over all passes, iterations.
    pub qp_iterations: u16,
    /// Constraints added to the working set over all passes, constraints.
    pub qp_added: u16,
    /// Constraints removed from the working set over all passes, constraints.
    pub qp_removed: u16,
    /// Full refactorisations over all passes, refactorisations.
    pub qp_refactorizations: u16,
    /// Constraint rows of the last QP, rows.
    pub rows: u16,
    /// Active constraints at the last QP's solution, constraints.
    pub active: u16,
    /// Core clock ticks the activation spent adopting a new window of the road
    /// instead of planning (status [`PLAN_WINDOW`]; then equal to `ticks`; 0: no
    /// window), preemption excluded, ticks.
    pub window_ticks: u32,
    /// Planned positions `[x_m, y_m]` of the plan's nodes, global frame, m.
    pub nodes_xy: [[f32; 2]; PLAN_NODES],
    /// Heuristic speed `V_heur` at the first node, m/s.
    pub v_heur0_mps: f32,
}

impl PlanEventFrame {
    /// The record of one plan activation: when it ran (µs on the ECU's timeline),
    /// its own execution in core clock `ticks` (preemption excluded), its outcome,
    /// its work counters (`report`: those of the activation, failed ones included)
    /// and the positions of the plan it computed (zero when none).
    #[allow(clippy::too_many_arguments)]
    pub fn new<R>(
        activation: u32,
        release_us: u64,
        finish_us: u64,
        ticks: u32,
        result: &Result<R, MpcError>,
        report: &MpcReport<f32>,
        published: bool,
        window_ticks: u32,
        plan: Option<&Plan<f32>>,
    ) -> Self {
        // `end_us` and `timing` are set by the caller once the activation ends.
        let sat16 = |x: u32| x.min(u16::MAX as u32) as u16;
        let mut nodes_xy = [[0.0f32; 2]; PLAN_NODES];
        let mut v_heur0_mps = 0.0;
        if let Some(p) = plan {
            for (xy, n) in nodes_xy.iter_mut().zip(p.nodes.iter()) {
                *xy = [n.x_m, n.y_m];
            }
            v_heur0_mps = p.v_heur_mps[0];
        }
        Self {
            activation,
            release_us,
            finish_us,
            end_us: finish_us,
            timing: TaskTimingFrame::default(),
            ticks,
            status: mpc_status_code(result),
            published,
            passes: report.passes.min(u8::MAX as u32) as u8,
            warm: report.warm,
            qp_iterations: sat16(report.qp_iterations),
            qp_added: sat16(report.qp_added),
            qp_removed: sat16(report.qp_removed),
            qp_refactorizations: sat16(report.qp_refactorizations),
            rows: sat16(report.rows),
            active: sat16(report.active_constraints),
            window_ticks,
            nodes_xy,
            v_heur0_mps,
        }
    }

    /// The record of an activation that adopted a new window of the road instead
    /// of planning: status [`PLAN_WINDOW`], `ticks` and `window_ticks` its own
    /// core clock ticks (preemption excluded), no work counters, no plan.
    pub fn window(activation: u32, release_us: u64, finish_us: u64, ticks: u32) -> Self {
        let none: Result<(), MpcError> = Ok(());
        Self {
            status: PLAN_WINDOW,
            ..Self::new(
                activation,
                release_us,
                finish_us,
                ticks,
                &none,
                &MpcReport::default(),
                false,
                ticks,
                None,
            )
        }
    }
}

/// Answer to `Down::Stop`: the ECU's end-of-run report.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DoneFrame {
    /// Deepest stack use seen (painted-stack high-water mark), bytes.
    pub stack_high_water_bytes: u32,
    /// Size of the stack region, bytes.
    pub stack_size_bytes: u32,
    /// Frames the ECU refused over the run (all [`FrameError`]s, and authentic
    /// frames it did not expect), frames.
    pub rejected_frames: u32,
    /// Of those, the ones refused by reason (version 8), frames.
    pub refused: RefusalCounts,
}

// ---------------------------------------------------------------------------
// Sizes, checked at compile time
// ---------------------------------------------------------------------------

/// Largest postcard varint of a `u16`, bytes.
const U16_MAX_BYTES: usize = 3;
/// Largest postcard varint of a `u32`, bytes.
const U32_MAX_BYTES: usize = 5;
/// Largest postcard varint of a `u64`, bytes.
const U64_MAX_BYTES: usize = 10;
/// An `f32`, bytes.
const F32_BYTES: usize = 4;
/// An enum discriminant below 128, bytes.
const TAG_BYTES: usize = 1;

/// Largest postcard encoding of a [`VehicleConfig<f32>`] (8 `f32`), bytes.
const VEHICLE_MAX_BYTES: usize = 8 * F32_BYTES;
/// Largest postcard encoding of a [`StateEstimate<f32>`], bytes.
const ESTIMATE_MAX_BYTES: usize = U64_MAX_BYTES + 12 * F32_BYTES;
/// Largest postcard encoding of a [`TaskTimingFrame`] (5 `u32`), bytes.
const TIMING_MAX_BYTES: usize = 5 * U32_MAX_BYTES;
/// Largest postcard encoding of a [`RefusalCounts`] (3 `u32`), bytes.
const REFUSALS_MAX_BYTES: usize = 3 * U32_MAX_BYTES;
/// Largest postcard encoding of a [`PlanEventFrame`], bytes.
const PLAN_EVENT_MAX_BYTES: usize = U32_MAX_BYTES
    + 3 * U64_MAX_BYTES
    + TIMING_MAX_BYTES
    + U32_MAX_BYTES
    + 4 // status, published, passes, warm: a byte each
    + 6 * U16_MAX_BYTES
    + U32_MAX_BYTES
    + (PLAN_NODES * 2 + 1) * F32_BYTES;

/// Largest postcard encoding of a [`Down::Sensor`], bytes.
const SENSOR_MAX_BYTES: usize = U32_MAX_BYTES + ESTIMATE_MAX_BYTES + U32_MAX_BYTES;

/// Largest postcard encoding of a [`Down`] the control link carries while driving,
/// bytes: a `Sensor` (the only other one, `Stop`, is its tag alone).
pub const MAX_DRIVING_DOWN_PAYLOAD_BYTES: usize = TAG_BYTES + SENSOR_MAX_BYTES;

/// Largest postcard encoding of a [`Down`], bytes (a `PathChunk`).
pub const MAX_DOWN_PAYLOAD_BYTES: usize = TAG_BYTES
    + max(
        max(
            VEHICLE_MAX_BYTES + F32_BYTES + 1 + U16_MAX_BYTES + 1, // Config
            U16_MAX_BYTES + 1 + PATH_CHUNK_ROWS * 4 * F32_BYTES,   // PathChunk
        ),
        max(
            3 + U32_MAX_BYTES + MAX_VERTICES * 2 * F32_BYTES, // Obstacle
            SENSOR_MAX_BYTES,                                 // Sensor
        ),
    );
/// Largest postcard encoding of an [`ActuationFrame`] without its plan event
/// (`plan: None`, its tag byte alone), bytes.
const ACTUATION_MAX_BYTES: usize = U32_MAX_BYTES
    + 8 * F32_BYTES
    + 2
    + U32_MAX_BYTES
    + 2 * U64_MAX_BYTES
    + U32_MAX_BYTES
    + TIMING_MAX_BYTES
    + U32_MAX_BYTES
    + 1
    + REFUSALS_MAX_BYTES
    + 1;
/// Largest postcard encoding of an [`Up`], bytes (an `Actuation` with a plan event).
pub const MAX_UP_PAYLOAD_BYTES: usize = TAG_BYTES
    + max(
        max(1 + U16_MAX_BYTES, 3 * U32_MAX_BYTES + REFUSALS_MAX_BYTES), // Ready, Done
        ACTUATION_MAX_BYTES + PLAN_EVENT_MAX_BYTES,
    );
/// Largest postcard encoding of an [`Up::Actuation`] that carries no plan event,
/// bytes (the control task's frame in the nine control periods of ten that no
/// plan activation finishes in).
pub const MAX_ACTUATION_PAYLOAD_BYTES: usize = TAG_BYTES + ACTUATION_MAX_BYTES;
/// Largest encoded [`Down`] frame, bytes, delimiter included.
pub const MAX_DOWN_FRAME_BYTES: usize = frame_bytes_for_payload(MAX_DOWN_PAYLOAD_BYTES);
/// Largest encoded frame of the control link while driving (a [`Down::Sensor`]),
/// bytes, delimiter included: the set-up's frames (`Config`, `PathChunk`,
/// `Obstacle`) come before the timeline starts and the road's `Window`s on the
/// route channel, so a longer frame on the control link while driving is refused.
pub const MAX_DRIVING_DOWN_FRAME_BYTES: usize =
    frame_bytes_for_payload(MAX_DRIVING_DOWN_PAYLOAD_BYTES);
/// Largest encoded [`Up`] frame, bytes, delimiter included.
pub const MAX_UP_FRAME_BYTES: usize = frame_bytes_for_payload(MAX_UP_PAYLOAD_BYTES);
/// Largest encoded [`Up::Actuation`] frame without a plan event, bytes,
/// delimiter included. An actuation frame carries a plan event at most once per
/// plan activation (the plan task leaves one event for the control task's next
/// frame; a newer one replaces it), so the link carries at most
/// [`MAX_UP_FRAME_BYTES`] − [`MAX_ACTUATION_FRAME_BYTES`] more per plan
/// activation than this per control activation (`link::usart`'s budgets).
pub const MAX_ACTUATION_FRAME_BYTES: usize = frame_bytes_for_payload(MAX_ACTUATION_PAYLOAD_BYTES);

/// Bytes through the MAC for a frame of `payload` bytes: the stream's Data ID,
/// the version byte, the payload and the freshness value (the tag's input, see
/// [`secoc`]).
pub const fn mac_input_bytes(payload: usize) -> usize {
    1 + 1 + payload + FRESHNESS_BYTES
}
/// Largest MAC input of an [`Up`] frame, bytes.
pub const MAX_UP_MAC_INPUT_BYTES: usize = mac_input_bytes(MAX_UP_PAYLOAD_BYTES);
/// Largest MAC input of a [`Down`] frame, bytes.
pub const MAX_DOWN_MAC_INPUT_BYTES: usize = mac_input_bytes(MAX_DOWN_PAYLOAD_BYTES);
/// Largest MAC input of a frame of the control link while driving (a
/// [`Down::Sensor`]), bytes.
pub const MAX_DRIVING_DOWN_MAC_INPUT_BYTES: usize = mac_input_bytes(MAX_DRIVING_DOWN_PAYLOAD_BYTES);

const _: () = assert!(MAX_DOWN_FRAME_BYTES <= MAX_FRAME_BYTES);
const _: () = assert!(MAX_DRIVING_DOWN_FRAME_BYTES <= MAX_DOWN_FRAME_BYTES);
const _: () = assert!(MAX_UP_FRAME_BYTES <= MAX_FRAME_BYTES);
const _: () = assert!(MAX_ACTUATION_FRAME_BYTES <= MAX_UP_FRAME_BYTES);
const _: () = assert!(PATH_CHUNK_ROWS <= u8::MAX as usize);
const _: () = assert!(MAX_VERTICES <= u8::MAX as usize);

/// The larger of two sizes (a `const` [`Ord::max`]).
const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

/// Largest encoded frame, bytes with the delimiter, of a postcard payload of
/// `payload` bytes: version + payload + freshness + tag + CRC, plus COBS's worst
/// case of one code byte and one more per 254 bytes, plus the 0x00.
pub const fn frame_bytes_for_payload(payload: usize) -> usize {
    let raw = 1 + payload + SECURED_BYTES + CRC_BYTES;
    raw + 1 + raw / 254 + 1
}

mod codes;
pub mod demux;
mod framing;
pub mod secoc;
pub mod usart;
pub use codes::*;
pub use framing::*;
pub use secoc::{
    Authenticator, LinkKey, LinkMac, Refusal, RefusalCounts, Stream, Verifier, FRESHNESS_BYTES,
    LINK_KEY, LINK_KEY_FROM_ENV, MAC_BYTES, SECURED_BYTES,
};
