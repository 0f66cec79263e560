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
//! [`FAULT_HARDFAULT`] and [`FAULT_DEADLINE`]. Everything here works on fixed buffers: no heap, no `alloc`,
//! no panic; every refused frame is a [`FrameError`] value the receiver counts.
//!
//! # Wire format
//!
//! ```text
//! raw   = [ LINK_VERSION ] ++ postcard(message) ++ crc32_le(LINK_VERSION ++ postcard(message))
//!           1 byte           n bytes               4 bytes, little-endian
//!
//!         ┌─────────┬──────────────────────────────┬──────┬──────┬──────┬──────┐
//! raw     │ version │ postcard payload (n bytes)   │ crc0 │ crc1 │ crc2 │ crc3 │
//!         └─────────┴──────────────────────────────┴──────┴──────┴──────┴──────┘
//!           └──────────── covered by the CRC ──────┘  crc0 = least significant
//!
//!         ┌──────────────────────────────────────────────────────────┬──────┐
//! frame   │ COBS(raw): n + 5 + 1 + ⌊(n + 5) / 254⌋ bytes at most, no 0x00 │ 0x00 │
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
//! * **CRC**: CRC-32/ISO-HDLC (the zlib/Ethernet CRC, [`crc::CRC_32_ISO_HDLC`])
//!   of the version byte and the payload, appended little-endian.
//! * **Framing**: consistent-overhead byte stuffing (COBS) of the whole raw frame,
//!   so the encoded frame holds no 0x00, then one 0x00 delimiter. [`encode`] is
//!   postcard's `Cobs` and `CrcModifier` flavours, [`decode`] the `cobs` crate's
//!   decoder and the `crc` crate's checksum before postcard reads the payload. A receiver that
//!   lost sync skips to the next 0x00 ([`FrameReader`]); empty frames (two
//!   delimiters in a row) are idle and ignored.
//!
//! The largest frames: [`MAX_DOWN_FRAME_BYTES`] (a `PathChunk`, 269 bytes) and
//! [`MAX_UP_FRAME_BYTES`] (an `Actuation` with a plan event, 335 bytes), both
//! including the delimiter and checked at compile time against
//! [`MAX_FRAME_BYTES`].
//!
//! # Status codes (the `u8` fields)
//!
//! * [`ActuationFrame::mode`]: [`mode_code`] (`Following` 0, `Extrapolating` 1,
//!   `Stopping` 2, `Safe` 3).
//! * [`ActuationFrame::fault`]: [`fault_code`] (0 none, `NonFiniteEstimate` 1,
//!   `NonFinitePlan` 2, `InvalidPlan` 3, `Numerical` 4).
//! * [`PlanEventFrame::status`]: [`mpc_status_code`] (0 optimal, `NonFiniteState`
//!   1, `InvalidFriction` 2, `InvalidSettings` 3, `NoPath` 4, `Qp(s)` 0x10 +
//!   [`qp_status_code`]`(s)`, with `Optimal` 0, `NotSolved` 1, `IterationLimit` 2,
//!   `Infeasible` 3, `NotConvex` 4, `NumericalError` 5, `NonFiniteInput` 6,
//!   `InvalidInput` 7, `WorkingSetFull` 8).
//! * [`ReadyFrame::status`]: 0 accepted, else a [`SetupError`] code.
//!
//! Each has a `*_from_code` inverse and a `*_name` for logs.
//!
//! # Behaviour worth knowing
//!
//! * [`SequenceCheck::accept`] returns `Result<u32, SequenceError>`: `Ok(missed)`
//!   with the count of skipped sequence numbers (0 in order), so a gap is
//!   accepted *and* reported.
//! * [`encode`] takes `M: Serialize + ?Sized`.
//! * [`decode`] reports trailing bytes after the message as
//!   [`FrameError::Malformed`], and a frame longer than [`MAX_FRAME_BYTES`] − 1
//!   bytes as [`FrameError::TooLong`].
//! * [`FrameReader::push`] yields nothing for an empty frame (two delimiters in a
//!   row: idle line or resynchronisation); [`FrameError::Empty`] is what [`decode`]
//!   says of an empty slice.

use crc::{Crc, CRC_32_ISO_HDLC};
use serde::{Deserialize, Serialize};

use crate::low_level::{ControlFault, Mode};
use crate::mpc::{MpcError, MpcReport};
use crate::obstacles::MAX_VERTICES;
use crate::plan::Plan;
use crate::state_estimate::StateEstimate;
use crate::vehicle_config::VehicleConfig;
use qp::QpStatus;

/// Version of this wire format, the first byte of every raw frame.
pub const LINK_VERSION: u8 = 3;
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
const CRC_BYTES: usize = 4;
/// The CRC of every frame (CRC-32/ISO-HDLC, table in flash: 1 KiB).
static CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

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
    /// 0) are the next window of the road; the plan task adopts it after it next
    /// publishes (version 2).
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
    /// Frames of the road (`PathChunk`s then a `Window`) the host wrote on the
    /// route channel since the last sensor frame, frames (version 3): the plan
    /// task reads them after it next publishes.
    pub route_frames: u16,
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
    /// When this frame was sent, µs on the ECU's timeline (`now_us()`): the
    /// activation's completion; the plant applies the actuation from then.
    pub sent_us: u64,
    /// The control task's deadline counts, this activation's completion included
    /// (its skipped releases are counted at its end, so they show in the next
    /// frame).
    pub control: TaskTimingFrame,
    /// Times the control task's watchdog saw no new plan for more than
    /// [`crate::deadline::PLAN_WATCHDOG_PERIODS`] plan periods, trips.
    pub watchdog_trips: u32,
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
    /// Time the activation ended, µs: after the window of the road it received
    /// and adopted after publishing (`finish_us` without one). The next release
    /// is the first not yet past then (version 3).
    pub end_us: u64,
    /// The plan task's deadline counts, this activation's completion and the
    /// releases it skipped included (version 3).
    pub timing: TaskTimingFrame,
    /// ECU clock ticks (168 MHz) of the plan task itself, preemption by the
    /// control task excluded.
    pub ticks: u32,
    /// 0 optimal, else [`mpc_status_code`] (see the module docs for the mapping).
    pub status: u8,
    /// False when the plan was late (dropped) or failed.
    pub published: bool,
    /// MPC passes run (linearise-condense-solve), passes.
    pub passes: u8,
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
    /// after publishing its plan (not in `ticks`; 0: no window), ticks.
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
}

/// Answer to `Down::Stop`: the ECU's end-of-run report.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DoneFrame {
    /// Deepest stack use seen (painted-stack high-water mark), bytes.
    pub stack_high_water_bytes: u32,
    /// Size of the stack region, bytes.
    pub stack_size_bytes: u32,
    /// Frames the ECU refused over the run (all [`FrameError`]s), frames.
    pub rejected_frames: u32,
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
const ESTIMATE_MAX_BYTES: usize = U64_MAX_BYTES + 7 * F32_BYTES;
/// Largest postcard encoding of a [`TaskTimingFrame`] (5 `u32`), bytes.
const TIMING_MAX_BYTES: usize = 5 * U32_MAX_BYTES;
/// Largest postcard encoding of a [`PlanEventFrame`], bytes.
const PLAN_EVENT_MAX_BYTES: usize = U32_MAX_BYTES
    + 3 * U64_MAX_BYTES
    + TIMING_MAX_BYTES
    + U32_MAX_BYTES
    + 3
    + 6 * U16_MAX_BYTES
    + U32_MAX_BYTES
    + (PLAN_NODES * 2 + 1) * F32_BYTES;

/// Largest postcard encoding of a [`Down`], bytes (a `PathChunk`).
pub const MAX_DOWN_PAYLOAD_BYTES: usize = TAG_BYTES
    + max(
        max(
            VEHICLE_MAX_BYTES + F32_BYTES + 1 + U16_MAX_BYTES + 1, // Config
            U16_MAX_BYTES + 1 + PATH_CHUNK_ROWS * 4 * F32_BYTES,   // PathChunk
        ),
        max(
            3 + U32_MAX_BYTES + MAX_VERTICES * 2 * F32_BYTES, // Obstacle
            U32_MAX_BYTES + ESTIMATE_MAX_BYTES + U16_MAX_BYTES, // Sensor
        ),
    );
/// Largest postcard encoding of an [`Up`], bytes (an `Actuation` with a plan event).
pub const MAX_UP_PAYLOAD_BYTES: usize = TAG_BYTES
    + max(
        max(1 + U16_MAX_BYTES, 3 * U32_MAX_BYTES), // Ready, Done
        U32_MAX_BYTES
            + 8 * F32_BYTES
            + 2
            + U32_MAX_BYTES
            + 2 * U64_MAX_BYTES
            + TIMING_MAX_BYTES
            + U32_MAX_BYTES
            + 1
            + PLAN_EVENT_MAX_BYTES,
    );
/// Largest encoded [`Down`] frame, bytes, delimiter included.
pub const MAX_DOWN_FRAME_BYTES: usize = frame_bytes_for_payload(MAX_DOWN_PAYLOAD_BYTES);
/// Largest encoded [`Up`] frame, bytes, delimiter included.
pub const MAX_UP_FRAME_BYTES: usize = frame_bytes_for_payload(MAX_UP_PAYLOAD_BYTES);

const _: () = assert!(MAX_DOWN_FRAME_BYTES <= MAX_FRAME_BYTES);
const _: () = assert!(MAX_UP_FRAME_BYTES <= MAX_FRAME_BYTES);
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
/// `payload` bytes: version + payload + CRC, plus COBS's worst case of one code
/// byte and one more per 254 bytes, plus the 0x00.
pub const fn frame_bytes_for_payload(payload: usize) -> usize {
    let raw = 1 + payload + CRC_BYTES;
    raw + 1 + raw / 254 + 1
}

// ---------------------------------------------------------------------------
// Status codes
// ---------------------------------------------------------------------------

/// One table per enum sent as a byte: from `Type { Variant = code, .. }` come the
/// array of every variant in code order, the code of a variant, the variant of a
/// code and the variant's name, so that they cannot disagree. With `impl`, as
/// associated items (`ALL`, `code`, `from_code`, `name`) of an enum of this
/// crate; else as the named functions of a foreign one (optionally a name
/// wrapped as `Wrapper(Variant)`).
macro_rules! wire_codes {
    (impl $ty:ident { $($variant:ident = $code:literal),+ $(,)? }) => {
        impl $ty {
            /// Every variant, in code order (for tests and tables).
            pub const ALL: [$ty; [$($code),+].len()] = [$($ty::$variant),+];

            /// The variant's wire code.
            pub const fn code(self) -> u8 {
                match self {
                    $($ty::$variant => $code),+
                }
            }

            /// The variant of a wire code; `None` for unknown codes.
            pub const fn from_code(code: u8) -> Option<$ty> {
                match code {
                    $($code => Some($ty::$variant),)+
                    _ => None,
                }
            }

            /// The variant's name, for logs.
            pub const fn name(self) -> &'static str {
                match self {
                    $($ty::$variant => stringify!($variant)),+
                }
            }
        }
    };
    (
        $(#[$all_doc:meta])* $all:ident, $code_fn:ident, $from_fn:ident, $name_fn:ident
        $(, $wrapped_fn:ident($wrapper:literal))?: $ty:ident $body:tt
    ) => {
        wire_codes!(@fns [$(#[$all_doc])*] $all $code_fn $from_fn $name_fn $ty $body);
        $(wire_codes!(@wrapped $wrapped_fn $wrapper $ty $body);)?
    };
    (
        @fns [$($attr:tt)*] $all:ident $code_fn:ident $from_fn:ident $name_fn:ident
        $ty:ident { $($variant:ident = $code:literal),+ $(,)? }
    ) => {
        $($attr)*
        pub const $all: [$ty; [$($code),+].len()] = [$($ty::$variant),+];

        #[doc = concat!("Wire code of a [`", stringify!($ty), "`] (the order of [`", stringify!($all), "`]).")]
        pub const fn $code_fn(v: $ty) -> u8 {
            match v {
                $($ty::$variant => $code),+
            }
        }

        #[doc = concat!("The [`", stringify!($ty), "`] of a code from [`", stringify!($code_fn), "`]; `None` when unknown.")]
        pub const fn $from_fn(code: u8) -> Option<$ty> {
            match code {
                $($code => Some($ty::$variant),)+
                _ => None,
            }
        }

        #[doc = concat!("Name of a [`", stringify!($ty), "`], for logs.")]
        pub const fn $name_fn(v: $ty) -> &'static str {
            match v {
                $($ty::$variant => stringify!($variant)),+
            }
        }
    };
    (@wrapped $wrapped_fn:ident $wrapper:literal $ty:ident { $($variant:ident = $code:literal),+ $(,)? }) => {
        #[doc = concat!("Name of a [`", stringify!($ty), "`] wrapped as `", $wrapper, "(Variant)`, for logs.")]
        pub const fn $wrapped_fn(v: $ty) -> &'static str {
            match v {
                $($ty::$variant => concat!($wrapper, "(", stringify!($variant), ")")),+
            }
        }
    };
}

/// Why the ECU refused the set-up (the [`ReadyFrame::status`] codes, 1..=12).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SetupError {
    /// `Start`, a `PathChunk` or an `Obstacle` came before any `Config` (detail 0).
    NoConfig,
    /// The vehicle is invalid or `mu_planner` is not positive and finite (detail 0).
    InvalidConfig,
    /// `path_rows` exceeds the ECU's path capacity (detail: the capacity, rows).
    PathTooLong,
    /// A `PathChunk` reaches past `path_rows` or its `count` exceeds
    /// `PATH_CHUNK_ROWS` (detail: its `first`).
    PathChunkOutOfRange,
    /// A track row never arrived (detail: the first missing row).
    MissingPathRow,
    /// A track row is non-finite or has a negative width (detail: the row).
    InvalidPathRow,
    /// The reference path refused the rows (too few, degenerate; detail 0).
    PathRejected,
    /// `obstacles` exceeds the ECU's capacity (detail: the capacity).
    TooManyObstacles,
    /// An `Obstacle` has `index ≥ total`, a `total` other than the configured
    /// count, or `count > MAX_VERTICES` (detail: its index).
    ObstacleOutOfRange,
    /// An obstacle never arrived (detail: the first missing index).
    MissingObstacle,
    /// An obstacle's polygon was refused (non-finite, too few vertices; detail: its
    /// index).
    InvalidObstacle,
    /// An obstacle leaves the car no room to pass on either side (detail: its
    /// index).
    ObstacleBlocksRoad,
}

wire_codes!(impl SetupError {
    NoConfig = 1,
    InvalidConfig = 2,
    PathTooLong = 3,
    PathChunkOutOfRange = 4,
    MissingPathRow = 5,
    InvalidPathRow = 6,
    PathRejected = 7,
    TooManyObstacles = 8,
    ObstacleOutOfRange = 9,
    MissingObstacle = 10,
    InvalidObstacle = 11,
    ObstacleBlocksRoad = 12,
});

/// Name of a [`ReadyFrame::status`]: `"Accepted"` for 0, the [`SetupError`]'s
/// name, or `"Unknown"`.
pub const fn setup_status_name(code: u8) -> &'static str {
    match SetupError::from_code(code) {
        Some(e) => e.name(),
        None if code == 0 => "Accepted",
        None => "Unknown",
    }
}

wire_codes!(
    /// Every [`QpStatus`], in code order (`Optimal` 0 … `WorkingSetFull` 8).
    QP_STATUSES, qp_status_code, qp_status_from_code, qp_status_name, qp_status_wrapped_name("Qp"):
    QpStatus {
        Optimal = 0,
        NotSolved = 1,
        IterationLimit = 2,
        Infeasible = 3,
        NotConvex = 4,
        NumericalError = 5,
        NonFiniteInput = 6,
        InvalidInput = 7,
        WorkingSetFull = 8,
    }
);

/// [`PlanEventFrame::status`] of a successful MPC step.
pub const MPC_OK: u8 = 0;
/// Added to [`qp_status_code`] for [`MpcError::Qp`].
pub const MPC_QP_BASE: u8 = 0x10;

/// Code of an MPC error: `NonFiniteState` 1, `InvalidFriction` 2,
/// `InvalidSettings` 3, `NoPath` 4, `Qp(s)` `0x10 + qp_status_code(s)`.
pub const fn mpc_error_code(e: MpcError) -> u8 {
    match e {
        MpcError::NonFiniteState => 1,
        MpcError::InvalidFriction => 2,
        MpcError::InvalidSettings => 3,
        MpcError::NoPath => 4,
        MpcError::Qp(s) => MPC_QP_BASE + qp_status_code(s),
    }
}

/// [`PlanEventFrame::status`] of an MPC step's result: [`MPC_OK`] (0) for `Ok`,
/// else [`mpc_error_code`].
pub fn mpc_status_code<R>(r: &Result<R, MpcError>) -> u8 {
    match r {
        Ok(_) => MPC_OK,
        Err(e) => mpc_error_code(*e),
    }
}

/// The MPC error of a status code; `None` for 0 (optimal) and unknown codes.
pub const fn mpc_error_from_code(code: u8) -> Option<MpcError> {
    match code {
        1 => Some(MpcError::NonFiniteState),
        2 => Some(MpcError::InvalidFriction),
        3 => Some(MpcError::InvalidSettings),
        4 => Some(MpcError::NoPath),
        c if c >= MPC_QP_BASE => match qp_status_from_code(c - MPC_QP_BASE) {
            Some(s) => Some(MpcError::Qp(s)),
            None => None,
        },
        _ => None,
    }
}

/// Name of a [`PlanEventFrame::status`]: `"Optimal"` for 0, the error's name
/// (`"Qp(Infeasible)"`…), or `"Unknown"`.
pub const fn mpc_status_name(code: u8) -> &'static str {
    match mpc_error_from_code(code) {
        None if code == MPC_OK => "Optimal",
        None => "Unknown",
        Some(MpcError::NonFiniteState) => "NonFiniteState",
        Some(MpcError::InvalidFriction) => "InvalidFriction",
        Some(MpcError::InvalidSettings) => "InvalidSettings",
        Some(MpcError::NoPath) => "NoPath",
        Some(MpcError::Qp(s)) => qp_status_wrapped_name(s),
    }
}

wire_codes!(
    /// Every [`Mode`], in code order ([`ActuationFrame::mode`]: `Following` 0,
    /// `Extrapolating` 1, `Stopping` 2, `Safe` 3).
    MODES, mode_code, mode_from_code, mode_variant_name:
    Mode {
        Following = 0,
        Extrapolating = 1,
        Stopping = 2,
        Safe = 3,
    }
);

/// Name of an [`ActuationFrame::mode`] code, or `"Unknown"`.
pub const fn mode_name(code: u8) -> &'static str {
    match mode_from_code(code) {
        Some(m) => mode_variant_name(m),
        None => "Unknown",
    }
}

/// [`ActuationFrame::fault`] of the ECU's panic handler: zero torque, steering held.
pub const FAULT_PANIC: u8 = 255;
/// [`ActuationFrame::fault`] of the ECU's fault handler (HardFault, and MemManage,
/// BusFault and UsageFault escalated to it): zero torque, steering held.
pub const FAULT_HARDFAULT: u8 = 254;
/// [`ActuationFrame::fault`] of the control task's consecutive-miss rule
/// ([`crate::deadline::CONTROL_MISS_LIMIT`]): zero torque, steering held.
pub const FAULT_DEADLINE: u8 = 253;

/// [`ActuationFrame::fault`] of a control result's fault: 0 none,
/// `NonFiniteEstimate` 1, `NonFinitePlan` 2, `InvalidPlan` 3, `Numerical` 4.
pub const fn fault_code(f: Option<ControlFault>) -> u8 {
    match f {
        None => 0,
        Some(ControlFault::NonFiniteEstimate) => 1,
        Some(ControlFault::NonFinitePlan) => 2,
        Some(ControlFault::InvalidPlan) => 3,
        Some(ControlFault::Numerical) => 4,
    }
}

/// The fault of a code from [`fault_code`]: `Ok(None)` for 0, `Err(code)` when
/// unknown.
pub const fn fault_from_code(code: u8) -> Result<Option<ControlFault>, u8> {
    match code {
        0 => Ok(None),
        1 => Ok(Some(ControlFault::NonFiniteEstimate)),
        2 => Ok(Some(ControlFault::NonFinitePlan)),
        3 => Ok(Some(ControlFault::InvalidPlan)),
        4 => Ok(Some(ControlFault::Numerical)),
        c => Err(c),
    }
}

/// Name of an [`ActuationFrame::fault`] code (`"None"` for 0; `"Panic"`,
/// `"HardFault"`, `"DeadlineMisses"` for the ECU's own codes), or `"Unknown"`.
pub const fn fault_name(code: u8) -> &'static str {
    match fault_from_code(code) {
        Ok(None) => "None",
        Ok(Some(ControlFault::NonFiniteEstimate)) => "NonFiniteEstimate",
        Ok(Some(ControlFault::NonFinitePlan)) => "NonFinitePlan",
        Ok(Some(ControlFault::InvalidPlan)) => "InvalidPlan",
        Ok(Some(ControlFault::Numerical)) => "Numerical",
        Err(FAULT_PANIC) => "Panic",
        Err(FAULT_HARDFAULT) => "HardFault",
        Err(FAULT_DEADLINE) => "DeadlineMisses",
        Err(_) => "Unknown",
    }
}

// ---------------------------------------------------------------------------
// Encoding and decoding
// ---------------------------------------------------------------------------

/// Why a frame was refused (each counted by the receiver, never a panic).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// [`decode`] was given no bytes.
    Empty,
    /// More bytes than fit arrived before a delimiter ([`FrameReader`]), or a frame
    /// longer than `MAX_FRAME_BYTES − 1` ([`decode`]).
    TooLong,
    /// The COBS encoding is invalid (a 0x00 inside, or a block past the end).
    Cobs,
    /// The decoded frame is shorter than a version byte and a CRC.
    TooShort,
    /// The frame is of another version of this format.
    Version {
        /// The version byte received.
        got: u8,
    },
    /// The CRC does not match.
    Checksum,
    /// postcard could not decode the message, or bytes trail it.
    Malformed,
    /// [`encode`]'s output buffer is too small (see [`MAX_FRAME_BYTES`]).
    BufferTooSmall,
}

impl FrameError {
    /// The variant's name, for logs.
    pub const fn name(self) -> &'static str {
        match self {
            FrameError::Empty => "Empty",
            FrameError::TooLong => "TooLong",
            FrameError::Cobs => "Cobs",
            FrameError::TooShort => "TooShort",
            FrameError::Version { .. } => "Version",
            FrameError::Checksum => "Checksum",
            FrameError::Malformed => "Malformed",
            FrameError::BufferTooSmall => "BufferTooSmall",
        }
    }
}

/// Encodes `msg` as one whole frame (see the module docs) into `out`, the 0x00
/// delimiter included; returns the frame's length, bytes. A buffer of
/// [`MAX_FRAME_BYTES`] holds any [`Down`] or [`Up`]. postcard's flavours do the
/// work in one pass: the version byte and the message through the CRC (appended
/// little-endian) and COBS, into `out`.
pub fn encode<M: Serialize + ?Sized>(msg: &M, out: &mut [u8]) -> Result<usize, FrameError> {
    use postcard::ser_flavors::{crc::CrcModifier, Cobs};
    let cobs = Cobs::try_new(FrameBuffer::new(out)).map_err(|_| FrameError::BufferTooSmall)?;
    let flavor = CrcModifier::new(cobs, CRC32.digest());
    // postcard writes a `u8` as its one byte: the tuple is the version byte, then
    // the message.
    match postcard::serialize_with_flavor(&(LINK_VERSION, msg), flavor) {
        Ok(len) => Ok(len),
        Err(postcard::Error::SerializeBufferFull) => Err(FrameError::BufferTooSmall),
        Err(_) => Err(FrameError::Malformed),
    }
}

/// The output of [`encode`]: bytes pushed into a fixed buffer, a push past its end
/// refused. postcard's `Cobs` flavour also rewrites the code byte of each block
/// through `IndexMut`, always at an index it pushed before; an index past the end
/// reaches a spare byte instead of panicking (postcard's `Slice` would panic,
/// which puts the panic handler, which sends a frame, on its own path).
struct FrameBuffer<'a> {
    /// The frame's bytes.
    buf: &'a mut [u8],
    /// Bytes pushed.
    len: usize,
    /// What an index past the end reads and writes.
    spare: u8,
}

impl<'a> FrameBuffer<'a> {
    fn new(buf: &'a mut [u8]) -> Self {
        Self {
            buf,
            len: 0,
            spare: 0,
        }
    }
}

impl postcard::ser_flavors::Flavor for FrameBuffer<'_> {
    /// The frame's length, bytes.
    type Output = usize;

    fn try_push(&mut self, data: u8) -> postcard::Result<()> {
        let slot = self
            .buf
            .get_mut(self.len)
            .ok_or(postcard::Error::SerializeBufferFull)?;
        *slot = data;
        self.len += 1;
        Ok(())
    }

    fn finalize(self) -> postcard::Result<usize> {
        Ok(self.len)
    }
}

impl core::ops::Index<usize> for FrameBuffer<'_> {
    type Output = u8;

    fn index(&self, i: usize) -> &u8 {
        self.buf.get(i).unwrap_or(&self.spare)
    }
}

impl core::ops::IndexMut<usize> for FrameBuffer<'_> {
    fn index_mut(&mut self, i: usize) -> &mut u8 {
        match self.buf.get_mut(i) {
            Some(b) => b,
            None => &mut self.spare,
        }
    }
}

/// Decodes COBS in place with the `cobs` crate's decoder, one byte at a time (its
/// step is constant: the loop is the only one); returns the decoded length, bytes.
/// The output never overtakes the input: each byte read gives at most one byte.
fn cobs_decode_in_place(buf: &mut [u8]) -> Result<usize, FrameError> {
    let mut state = cobs::DecoderState::Idle;
    let mut write = 0;
    // len < MAX_FRAME_BYTES: decode, the only caller, refuses longer frames.
    // wcet-bound: MAX_FRAME_BYTES
    for read in 0..buf.len() {
        let byte = match buf.get(read) {
            Some(&b) if b != 0 => b,
            _ => return Err(FrameError::Cobs),
        };
        match state.feed(byte) {
            Ok(cobs::DecodeResult::DataContinue(out)) => {
                match buf.get_mut(write) {
                    Some(slot) => *slot = out,
                    None => return Err(FrameError::Cobs),
                }
                write += 1;
            }
            Ok(cobs::DecodeResult::NoData) => {}
            Ok(cobs::DecodeResult::DataComplete) | Err(_) => return Err(FrameError::Cobs),
        }
    }
    // The delimiter ends the frame: complete only where the last block ends.
    match state.feed(0) {
        Ok(cobs::DecodeResult::DataComplete) => Ok(write),
        _ => Err(FrameError::Cobs),
    }
}

/// Decodes one frame: `frame` is the bytes between two delimiters (no 0x00).
/// Undoes COBS in place (so `frame` is overwritten), then checks the length, the
/// version, the CRC, and that postcard consumes the payload exactly.
pub fn decode<'a, M: Deserialize<'a>>(frame: &'a mut [u8]) -> Result<M, FrameError> {
    if frame.is_empty() {
        return Err(FrameError::Empty);
    }
    if frame.len() >= MAX_FRAME_BYTES {
        return Err(FrameError::TooLong);
    }
    let n = cobs_decode_in_place(frame)?;
    let frame: &'a [u8] = frame;
    let raw = frame.get(..n).ok_or(FrameError::Cobs)?;
    if raw.len() < 1 + CRC_BYTES {
        return Err(FrameError::TooShort);
    }
    let (body, crc) = raw
        .split_at_checked(raw.len() - CRC_BYTES)
        .ok_or(FrameError::TooShort)?;
    let (&version, payload) = body.split_first().ok_or(FrameError::TooShort)?;
    if version != LINK_VERSION {
        return Err(FrameError::Version { got: version });
    }
    let crc: [u8; CRC_BYTES] = crc.try_into().map_err(|_| FrameError::TooShort)?;
    // The CRC's loop takes at least a byte of `body` (< MAX_FRAME_BYTES) per iteration.
    // wcet-bound: MAX_FRAME_BYTES
    if CRC32.checksum(body) != u32::from_le_bytes(crc) {
        return Err(FrameError::Checksum);
    }
    match postcard::take_from_bytes::<M>(payload) {
        Ok((msg, [])) => Ok(msg),
        _ => Err(FrameError::Malformed),
    }
}

// ---------------------------------------------------------------------------
// Stream framing and bookkeeping
// ---------------------------------------------------------------------------

/// Splits a byte stream into frames at 0x00 delimiters with a fixed buffer of `N`
/// bytes (use `N = MAX_FRAME_BYTES`); over-long frames are dropped (and reported
/// as [`FrameError::TooLong`] once their delimiter arrives). Empty frames (two
/// delimiters in a row) yield nothing.
pub struct FrameReader<const N: usize> {
    /// The frame being received (COBS-encoded, without the delimiter).
    buf: [u8; N],
    /// Bytes of `buf` in use.
    len: usize,
    /// The current frame overflowed `buf`; it is skipped until its delimiter.
    overflowed: bool,
}

impl<const N: usize> FrameReader<N> {
    /// An empty reader (a valid `const` initialiser).
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflowed: false,
        }
    }

    /// Feeds one byte; at a delimiter returns the frame's bytes (for [`decode`],
    /// which decodes them in place) or `TooLong`; otherwise `None`.
    pub fn push(&mut self, byte: u8) -> Option<Result<&mut [u8], FrameError>> {
        if byte == 0 {
            let len = core::mem::replace(&mut self.len, 0);
            if core::mem::replace(&mut self.overflowed, false) {
                return Some(Err(FrameError::TooLong));
            }
            if len == 0 {
                return None;
            }
            return Some(self.buf.get_mut(..len).ok_or(FrameError::TooLong));
        }
        if !self.overflowed {
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => {
                    self.overflowed = true;
                    self.len = 0;
                }
            }
        }
        None
    }

    /// Bytes of the frame being received, bytes (0 while skipping an over-long one).
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Drops the frame being received (e.g. after a link reset).
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }
}

impl<const N: usize> Default for FrameReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// Why [`SequenceCheck::accept`] refused a sequence number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SequenceError {
    /// `seq ≤ last`: a duplicate or an older frame.
    Stale,
}

/// Detects stale (duplicate or older) and skipped sequence numbers. Sequence
/// numbers do not wrap (a `u32` at 100 Hz lasts 497 days).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SequenceCheck {
    /// The last accepted sequence number, if any.
    last: Option<u32>,
}

impl SequenceCheck {
    /// A check that accepts any first sequence number.
    pub const fn new() -> Self {
        Self { last: None }
    }

    /// Accepts `seq` when newer than the last accepted one; `Ok(missed)` counts the
    /// sequence numbers skipped (0 in order, > 0 for a gap, which is accepted).
    pub fn accept(&mut self, seq: u32) -> Result<u32, SequenceError> {
        let missed = match self.last {
            None => 0,
            Some(last) if seq <= last => return Err(SequenceError::Stale),
            Some(last) => seq - last - 1,
        };
        self.last = Some(seq);
        Ok(missed)
    }

    /// The last accepted sequence number, if any.
    pub const fn last(&self) -> Option<u32> {
        self.last
    }

    /// Forgets the last sequence number (a new run accepts any first number).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

/// Counts of a receiver's frames (all saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Frames decoded, frames.
    pub accepted: u32,
    /// Frames refused (any [`FrameError`]), frames.
    pub rejected: u32,
    /// Decoded frames refused as stale (duplicate or older `seq`), frames.
    pub stale: u32,
    /// Gaps in the sequence (each jump counts once, whatever its size), gaps.
    pub gaps: u32,
    /// The last refusal, if any.
    pub last_error: Option<FrameError>,
}

impl LinkStats {
    /// All zero.
    pub const fn new() -> Self {
        Self {
            accepted: 0,
            rejected: 0,
            stale: 0,
            gaps: 0,
            last_error: None,
        }
    }

    /// Counts a frame's outcome ([`decode`]'s or [`FrameReader::push`]'s result).
    pub fn record<T>(&mut self, r: &Result<T, FrameError>) {
        match r {
            Ok(_) => self.accepted = self.accepted.saturating_add(1),
            Err(e) => {
                self.rejected = self.rejected.saturating_add(1);
                self.last_error = Some(*e);
            }
        }
    }

    /// Counts a [`SequenceCheck::accept`] outcome: a stale frame or a gap.
    pub fn record_sequence(&mut self, r: &Result<u32, SequenceError>) {
        match r {
            Err(SequenceError::Stale) => self.stale = self.stale.saturating_add(1),
            Ok(0) => {}
            Ok(_) => self.gaps = self.gaps.saturating_add(1),
        }
    }
}
