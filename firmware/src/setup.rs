//! The ECU's set-up: the car, the track and the obstacles, received piece by piece
//! before the timeline starts, then loaded into the two tasks.
//!
//! The simulator loads the same data into the same tasks with the same library
//! calls (`ReferencePath::load_track`, `ObstacleManager::update`,
//! [`VehicleConfig`]'s settings), so the ECU and the simulator plan alike, bit for
//! bit. Every failure is a [`SetupError`] (sent back to the host in the `Ready`
//! frame), never a panic.

use crate::link::{ConfigFrame, ObstacleFrame, PathChunkFrame};
use crate::low_level::LowLevelConfig;
use crate::obstacles::{Obstacle, ObstacleError, MAX_OBSTACLES, MAX_VERTICES};
use crate::reference_path::PathError;
use crate::tasks::{ControlTask, PlanTask};

/// Why the set-up was refused. [`SetupError::code`] and [`SetupError::detail`]
/// are what the `Ready` frame carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SetupError {
    /// `Start` arrived before a `Config` frame.
    NoConfig,
    /// The vehicle numbers are not finite and positive.
    InvalidVehicle,
    /// The planner's friction is not a positive finite number.
    InvalidFriction,
    /// The track has more rows than the ECU's path capacity.
    TrackTooLong {
        /// Rows announced.
        rows: u16,
        /// The ECU's capacity, rows.
        capacity: u16,
    },
    /// A path chunk lies outside the announced rows.
    ChunkOutOfRange {
        /// First row of the chunk.
        first: u16,
    },
    /// Rows never received (the first missing one).
    MissingRows {
        /// First missing row.
        first_missing: u16,
    },
    /// The path refused the track.
    Path(PathError),
    /// More obstacles than the ECU holds, or an obstacle frame out of range.
    TooManyObstacles,
    /// An obstacle polygon is invalid or blocks the road (index of the obstacle).
    Obstacle {
        /// Index of the obstacle.
        index: u8,
        /// The obstacle manager's reason.
        error: ObstacleError<f32>,
    },
    /// The low-level controller refused the derived configuration.
    LowLevelConfig,
}

impl SetupError {
    /// Code carried by the `Ready` frame (0 is success).
    pub fn code(&self) -> u8 {
        match self {
            SetupError::NoConfig => 1,
            SetupError::InvalidVehicle => 2,
            SetupError::InvalidFriction => 3,
            SetupError::TrackTooLong { .. } => 4,
            SetupError::ChunkOutOfRange { .. } => 5,
            SetupError::MissingRows { .. } => 6,
            SetupError::Path(_) => 7,
            SetupError::TooManyObstacles => 8,
            SetupError::Obstacle { .. } => 9,
            SetupError::LowLevelConfig => 10,
        }
    }

    /// A row or obstacle index that locates the error (0 when none applies).
    pub fn detail(&self) -> u16 {
        match *self {
            SetupError::TrackTooLong { rows, .. } => rows,
            SetupError::ChunkOutOfRange { first } => first,
            SetupError::MissingRows { first_missing } => first_missing,
            SetupError::Path(e) => match e {
                PathError::NonFinite { index }
                | PathError::RepeatedPoint { index }
                | PathError::NegativeWidth { index } => index.min(u16::MAX as usize) as u16,
                PathError::TooFewPoints { count } => count.min(u16::MAX as usize) as u16,
                _ => 0,
            },
            SetupError::Obstacle { index, .. } => index as u16,
            _ => 0,
        }
    }

    /// What a `Ready` frame's `status` code means, for the host's error message.
    pub fn describe(code: u8) -> &'static str {
        match code {
            0 => "accepted",
            1 => "no Config frame before Start",
            2 => "the vehicle numbers are not finite and positive",
            3 => "the planner's friction is not a positive finite number",
            4 => "the track has more rows than the ECU's path capacity (detail: rows)",
            5 => "a path chunk lies outside the announced rows (detail: first row)",
            6 => "track rows were not received (detail: first missing row)",
            7 => "the path refused the track: too few, non-finite, repeated points or negative widths (detail: row)",
            8 => "more obstacles than the ECU holds",
            9 => "an obstacle is invalid or blocks the road (detail: obstacle index)",
            10 => "the low-level controller refused the derived configuration",
            _ => "unknown set-up error",
        }
    }
}

/// Set-up in progress: what has arrived so far. The track rows go straight into
/// the planner's path storage ([`crate::reference_path::ReferencePath::stage_row`]).
#[derive(Clone, Debug)]
pub struct Setup {
    config: Option<ConfigFrame>,
    /// Rows received, as a count of distinct rows (chunks may not repeat).
    rows_received: u32,
    /// Next row expected (chunks arrive in order).
    next_row: u16,
    obstacles: heapless::Vec<Obstacle<f32>, MAX_OBSTACLES>,
    error: Option<SetupError>,
}

impl Default for Setup {
    fn default() -> Self {
        Self::new()
    }
}

impl Setup {
    /// Nothing received yet.
    pub const fn new() -> Self {
        Self {
            config: None,
            rows_received: 0,
            next_row: 0,
            obstacles: heapless::Vec::new(),
            error: None,
        }
    }

    fn fail(&mut self, e: SetupError) {
        if self.error.is_none() {
            self.error = Some(e);
        }
    }

    /// A `Config` frame: checked, kept; the planner's settings derive from it.
    pub fn config<const CAP: usize>(&mut self, c: &ConfigFrame, planner: &mut PlanTask<f32, CAP>) {
        if !c.vehicle.is_valid() {
            return self.fail(SetupError::InvalidVehicle);
        }
        if !(c.mu_planner.is_finite() && c.mu_planner > 0.0) {
            return self.fail(SetupError::InvalidFriction);
        }
        if c.path_rows as usize > CAP {
            return self.fail(SetupError::TrackTooLong {
                rows: c.path_rows,
                capacity: CAP.min(u16::MAX as usize) as u16,
            });
        }
        if c.obstacles as usize > MAX_OBSTACLES {
            return self.fail(SetupError::TooManyObstacles);
        }
        planner.settings = c.vehicle.mpc_settings();
        planner.mu = c.mu_planner;
        self.config = Some(*c);
    }

    /// A `PathChunk` frame: its rows are written into the planner's path storage.
    /// Chunks must arrive in order, without overlap.
    pub fn path_chunk<const CAP: usize>(
        &mut self,
        chunk: &PathChunkFrame,
        planner: &mut PlanTask<f32, CAP>,
    ) {
        let total = self.config.map_or(0, |c| c.path_rows);
        let count = chunk.count as usize;
        let end = chunk.first as usize + count;
        if chunk.first != self.next_row || count > chunk.rows.len() || end > total as usize {
            return self.fail(SetupError::ChunkOutOfRange { first: chunk.first });
        }
        for (k, row) in chunk.rows.iter().take(count).enumerate() {
            if !planner.path.stage_row(chunk.first as usize + k, *row) {
                return self.fail(SetupError::ChunkOutOfRange { first: chunk.first });
            }
        }
        self.rows_received += count as u32;
        self.next_row = end as u16;
    }

    /// An `Obstacle` frame: its polygon is kept until `Start`.
    pub fn obstacle(&mut self, o: &ObstacleFrame) {
        let n = (o.count as usize).min(MAX_VERTICES);
        match Obstacle::from_vertices(o.id, &o.vertices[..n]) {
            Ok(ob) => {
                if self.obstacles.push(ob).is_err() {
                    self.fail(SetupError::TooManyObstacles);
                }
            }
            Err(error) => self.fail(SetupError::Obstacle {
                index: o.index,
                error,
            }),
        }
    }

    /// `Start`: loads the path and the obstacles into the planner and returns the
    /// control task, or the first error met.
    pub fn finish<const CAP: usize>(
        &mut self,
        planner: &mut PlanTask<f32, CAP>,
    ) -> Result<ControlTask<f32>, SetupError> {
        if let Some(e) = self.error {
            return Err(e);
        }
        let c = self.config.ok_or(SetupError::NoConfig)?;
        if self.next_row != c.path_rows {
            return Err(SetupError::MissingRows {
                first_missing: self.next_row,
            });
        }
        planner
            .path
            .load_staged(c.path_rows as usize, c.closed)
            .map_err(SetupError::Path)?;
        planner
            .obstacles
            .update(
                &c.vehicle.obstacle_settings(c.mu_planner),
                &planner.path,
                &self.obstacles,
            )
            .map_err(|error| SetupError::Obstacle {
                index: obstacle_index(&error),
                error,
            })?;
        planner.reset();
        let config: LowLevelConfig<f32> = c.vehicle.low_level_config();
        ControlTask::new(config).map_err(|_| SetupError::LowLevelConfig)
    }
}

fn obstacle_index(e: &ObstacleError<f32>) -> u8 {
    match *e {
        ObstacleError::RoadBlocked { obstacle, .. }
        | ObstacleError::NoVertices { obstacle }
        | ObstacleError::TooManyVertices { obstacle, .. }
        | ObstacleError::NonFiniteVertex { obstacle, .. } => obstacle.min(u8::MAX as usize) as u8,
        _ => 0,
    }
}
