//! The status codes of the link's `u8` fields (see [`super`]'s *Status codes*):
//! each code, its inverse and its name for logs.

use super::*;
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

/// Why the ECU refused the set-up (the [`ReadyFrame::status`] codes, 1..=13).
/// On the ECU its log names the variant through defmt (the name interned in the
/// `.defmt` section, not in static RAM as `name()`'s strings would be).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "ecu", derive(defmt::Format))]
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
    /// The ECU's clock set-up failed: the core runs on its internal oscillator,
    /// not at its clock, and the control loop does not start (detail: the
    /// [`crate::clock_tree::ClockError`]'s code).
    ClockFailed,
    /// A set-up frame was refused (detail: the [`Refusal::code`], `Auth` 1 when
    /// the ECU and the simulator hold different link keys; version 8): a set-up
    /// with a frame missing is not completed.
    FrameRefused,
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
    ClockFailed = 13,
    FrameRefused = 14,
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
/// [`PlanEventFrame::status`] of an activation that adopted a new window of the
/// road instead of planning (no MPC step, nothing published; the next
/// activation plans on the window).
pub const PLAN_WINDOW: u8 = 0x20;

/// Code of an MPC error: `NonFiniteState` 1, `InvalidFriction` 2,
/// `InvalidSettings` 3, `NoPath` 4, `NonFinitePlan` 5, `Qp(s)`
/// `0x10 + qp_status_code(s)`.
pub const fn mpc_error_code(e: MpcError) -> u8 {
    match e {
        MpcError::NonFiniteState => 1,
        MpcError::InvalidFriction => 2,
        MpcError::InvalidSettings => 3,
        MpcError::NoPath => 4,
        MpcError::NonFinitePlan => 5,
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
        5 => Some(MpcError::NonFinitePlan),
        c if c >= MPC_QP_BASE => match qp_status_from_code(c - MPC_QP_BASE) {
            Some(s) => Some(MpcError::Qp(s)),
            None => None,
        },
        _ => None,
    }
}

/// Name of a [`PlanEventFrame::status`]: `"Optimal"` for 0, `"Window"` for
/// [`PLAN_WINDOW`], the error's name (`"Qp(Infeasible)"`…), or `"Unknown"`.
pub const fn mpc_status_name(code: u8) -> &'static str {
    match mpc_error_from_code(code) {
        None if code == MPC_OK => "Optimal",
        None if code == PLAN_WINDOW => "Window",
        None => "Unknown",
        Some(MpcError::NonFiniteState) => "NonFiniteState",
        Some(MpcError::InvalidFriction) => "InvalidFriction",
        Some(MpcError::InvalidSettings) => "InvalidSettings",
        Some(MpcError::NoPath) => "NoPath",
        Some(MpcError::NonFinitePlan) => "NonFinitePlan",
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
/// [`ActuationFrame::fault`] of the ECU's NMI handler: zero torque, steering
/// held. On the STM32F405 the clock security system raises the NMI when the
/// crystal (HSE) fails; the hardware has then switched the core to its internal
/// oscillator.
pub const FAULT_NMI: u8 = 252;
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
/// `"HardFault"`, `"Nmi"`, `"DeadlineMisses"` for the ECU's own codes), or
/// `"Unknown"`.
pub const fn fault_name(code: u8) -> &'static str {
    match fault_from_code(code) {
        Ok(None) => "None",
        Ok(Some(ControlFault::NonFiniteEstimate)) => "NonFiniteEstimate",
        Ok(Some(ControlFault::NonFinitePlan)) => "NonFinitePlan",
        Ok(Some(ControlFault::InvalidPlan)) => "InvalidPlan",
        Ok(Some(ControlFault::Numerical)) => "Numerical",
        Err(FAULT_PANIC) => "Panic",
        Err(FAULT_HARDFAULT) => "HardFault",
        Err(FAULT_NMI) => "Nmi",
        Err(FAULT_DEADLINE) => "DeadlineMisses",
        Err(_) => "Unknown",
    }
}
