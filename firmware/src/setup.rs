//! The ECU's set-up: the car, the first window of the road and the obstacles,
//! received piece by piece before the timeline starts, then loaded into the two
//! tasks. Later windows arrive while driving (`Down::Window`).
//!
//! The simulator loads the same data into the same tasks with the same library
//! calls (`ReferencePath::load_track`, `ObstacleManager::update`,
//! [`crate::vehicle_config::VehicleConfig`]'s settings), so the ECU and the
//! simulator plan alike, bit for bit. Every failure is a [`SetupFailure`] (the
//! `Ready` frame's status and detail), never a panic.

use crate::link::{ConfigFrame, ObstacleFrame, PathChunkFrame, SetupError};
use crate::obstacles::{Obstacle, MAX_OBSTACLES, MAX_VERTICES};
use crate::reference_path::PathError;
use crate::tasks::{ControlTask, PlanTask};

/// Why the set-up was refused, and where: `detail` is the row, obstacle index or
/// capacity the [`SetupError`] documents.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SetupFailure {
    /// What went wrong.
    pub error: SetupError,
    /// Where (see [`SetupError`]'s variants).
    pub detail: u16,
}

fn failure(error: SetupError, detail: usize) -> SetupFailure {
    SetupFailure {
        error,
        detail: detail.min(u16::MAX as usize) as u16,
    }
}

/// Set-up in progress: what has arrived so far. The track rows go straight into
/// the planner's path storage ([`crate::reference_path::ReferencePath::stage_row`]),
/// so the ECU never holds a second copy of the track.
#[derive(Clone, Debug, Default)]
pub struct Setup {
    config: Option<ConfigFrame>,
    /// Next row expected (chunks arrive in order, without overlap).
    next_row: u16,
    obstacles: heapless::Vec<Obstacle<f32>, MAX_OBSTACLES>,
    error: Option<SetupFailure>,
}

impl Setup {
    /// Nothing received yet.
    pub const fn new() -> Self {
        Self {
            config: None,
            next_row: 0,
            obstacles: heapless::Vec::new(),
            error: None,
        }
    }

    fn fail(&mut self, f: SetupFailure) {
        if self.error.is_none() {
            self.error = Some(f);
        }
    }

    /// A `Config` frame: checked and kept; the planner's settings derive from it.
    pub fn config<const CAP: usize>(&mut self, c: &ConfigFrame, planner: &mut PlanTask<f32, CAP>) {
        if !(c.vehicle.is_valid() && c.mu_planner.is_finite() && c.mu_planner > 0.0) {
            return self.fail(failure(SetupError::InvalidConfig, 0));
        }
        if c.path_rows as usize > CAP {
            return self.fail(failure(SetupError::PathTooLong, CAP));
        }
        if c.obstacles as usize > MAX_OBSTACLES {
            return self.fail(failure(SetupError::TooManyObstacles, MAX_OBSTACLES));
        }
        planner.settings = c.vehicle.mpc_settings();
        planner.mu = c.mu_planner;
        self.config = Some(*c);
    }

    /// A `PathChunk` frame: its rows are written into the planner's path storage.
    pub fn path_chunk<const CAP: usize>(
        &mut self,
        chunk: &PathChunkFrame,
        planner: &mut PlanTask<f32, CAP>,
    ) {
        let Some(c) = self.config else {
            return self.fail(failure(SetupError::NoConfig, 0));
        };
        let count = chunk.count as usize;
        let end = chunk.first as usize + count;
        if chunk.first != self.next_row || count > chunk.rows.len() || end > c.path_rows as usize {
            return self.fail(failure(
                SetupError::PathChunkOutOfRange,
                chunk.first as usize,
            ));
        }
        for (k, row) in chunk.rows.iter().take(count).enumerate() {
            if !planner.path.stage_row(chunk.first as usize + k, *row) {
                return self.fail(failure(SetupError::PathTooLong, CAP));
            }
        }
        self.next_row = end as u16;
    }

    /// An `Obstacle` frame: its polygon is kept until `Start`.
    pub fn obstacle(&mut self, o: &ObstacleFrame) {
        let Some(c) = self.config else {
            return self.fail(failure(SetupError::NoConfig, 0));
        };
        let n = o.count as usize;
        if o.index as usize != self.obstacles.len() || o.total != c.obstacles || n > MAX_VERTICES {
            return self.fail(failure(SetupError::ObstacleOutOfRange, o.index as usize));
        }
        match Obstacle::from_vertices(o.id, &o.vertices[..n]) {
            Ok(ob) => {
                if self.obstacles.push(ob).is_err() {
                    self.fail(failure(SetupError::TooManyObstacles, MAX_OBSTACLES));
                }
            }
            Err(_) => self.fail(failure(SetupError::InvalidObstacle, o.index as usize)),
        }
    }

    /// `Start`: loads the path and the obstacles into the planner and returns the
    /// control task, or the first error met.
    pub fn finish<const CAP: usize>(
        &mut self,
        planner: &mut PlanTask<f32, CAP>,
    ) -> Result<ControlTask<f32>, SetupFailure> {
        if let Some(e) = self.error {
            return Err(e);
        }
        let c = self.config.ok_or(failure(SetupError::NoConfig, 0))?;
        if self.next_row != c.path_rows {
            return Err(failure(SetupError::MissingPathRow, self.next_row as usize));
        }
        if self.obstacles.len() != c.obstacles as usize {
            return Err(failure(SetupError::MissingObstacle, self.obstacles.len()));
        }
        if !planner.set_obstacles(c.vehicle.obstacle_settings(c.mu_planner), &self.obstacles) {
            return Err(failure(SetupError::TooManyObstacles, MAX_OBSTACLES));
        }
        planner.reset();
        planner
            .adopt_window(c.path_rows as usize, 0.0, c.closed)
            .map_err(|e| match e {
                PathError::NonFinite { index } | PathError::NegativeWidth { index } => {
                    failure(SetupError::InvalidPathRow, index)
                }
                _ => failure(SetupError::PathRejected, 0),
            })?;
        if planner.stats.obstacle_errors > 0 || planner.stats.blocked_roads > 0 {
            // An obstacle of the first window was refused (the simulator checks every
            // obstacle on the whole track before it starts the ECU, with its reason).
            return Err(failure(SetupError::ObstacleBlocksRoad, 0));
        }
        c.vehicle
            .control_task(c.mu_planner)
            .map_err(|_| failure(SetupError::InvalidConfig, 0))
    }
}
