//! The closed loop: the plant against the firmware on a deterministic timeline.
//!
//! | module | concept |
//! |---|---|
//! | [`timeline`] | the driver: the plant against an [`Ecu`](ecu::Ecu), the log, budgets, deadlines, stop conditions |
//! | [`summary`] | the run's figures of merit (`summary.json`) |
//! | [`ecu`] | what runs the firmware: the `Ecu` trait, the modelled ECU on the host |
//! | [`disturbed_ecu`] | the modelled ECU behind a run's disturbances (noise, delay, a fault) |
//! | [`plan_activation`] | one activation of the plan task (a row of `plan_activations.csv`), its status names |
//! | [`cost_model`] | the tasks' cost model on the ECU (instructions), fitted on PIL measurements |
//! | [`set_up`] | one run set up from its factors: scenario, cars, options, disturbances |
//! | [`simulate`] | one closed-loop run on the modelled ECU, disturbed or not, in either precision |
//! | [`validity`] | the paper's Figure 3: `δ_a` vs `δ_th` on circles |
//!
//! This module holds what they all share, and nothing that uses them: a run's
//! options ([`SimOptions`]) and the firmware's arithmetic ([`Precision`]).

use serde::Serialize;

use crate::closed_loop::cost_model::CostModel;

pub mod cost_model;
pub mod disturbed_ecu;
pub mod ecu;
pub mod plan_activation;
pub mod set_up;
pub mod simulate;
pub mod summary;
pub mod timeline;
pub mod validity;

/// Scalar the firmware computes in (the simulator can run it in either).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Precision {
    /// Single precision (the ECU's).
    F32,
    /// Double precision.
    F64,
}

impl Precision {
    /// `"f32"` or `"f64"`, as written in the corpus.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
}

/// Cycles-per-instruction bound of the ECU from the timing report (`host-sim
/// wcet`): worst-case cycles of the traced instruction mix over its instructions.
pub const DEFAULT_CPI_BOUND: f64 = 2.53;

/// Options of a closed-loop run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SimOptions {
    /// Plant integration step, s (1 ms; must divide 10 ms).
    pub plant_dt_s: f64,
    /// ECU clock, Hz (168 MHz).
    pub ecu_clock_hz: f64,
    /// Cycles per instruction of the ECU: [`DEFAULT_CPI_BOUND`], the timing
    /// report's bound for a Cortex-M4F at 168 MHz running from flash behind the
    /// ART accelerator (`host-sim wcet`, `wcet.json`'s
    /// `cycles_per_instruction_bound`).
    pub cycles_per_instruction: f64,
    /// Budget of one control activation, cycles (its deadline is its 10 ms period).
    pub control_budget_cycles: f64,
    /// Budget of one plan activation, cycles: 95 ms at 168 MHz (15.96 M), the
    /// 100 ms deadline less 5 ms kept for the control task's preemptions (ten per
    /// period, 0.2 ms in all at the bound) and timer jitter.
    pub plan_budget_cycles: f64,
    /// Cost model, instructions.
    pub cost_model: CostModel,
    /// Friction coefficient of the road (the plant), dimensionless.
    pub mu_road: f64,
    /// Friction coefficient given to the planner, dimensionless.
    pub mu_planner: f64,
    /// Laps to drive (closed tracks) before stopping.
    pub laps: u32,
    /// Simulated time limit, s.
    pub max_duration_s: f64,
    /// Initial speed, m/s.
    pub initial_speed_mps: f64,
}

impl Default for SimOptions {
    fn default() -> Self {
        Self {
            plant_dt_s: 1e-3,
            ecu_clock_hz: firmware::timing::ECU_CLOCK_HZ as f64,
            cycles_per_instruction: DEFAULT_CPI_BOUND,
            control_budget_cycles: firmware::deadline::CONTROL_BUDGET_CYCLES as f64,
            plan_budget_cycles: firmware::deadline::PLAN_BUDGET_CYCLES as f64,
            cost_model: CostModel::default(),
            mu_road: 1.0,
            mu_planner: 1.0,
            laps: 1,
            max_duration_s: 600.0,
            initial_speed_mps: 15.0,
        }
    }
}
