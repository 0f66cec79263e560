//! What runs the firmware in the closed loop: the [`Ecu`] trait, and
//! [`SimulatedEcu`], the firmware's two tasks run in this process on a modelled
//! timeline.
//!
//! The closed-loop driver ([`run_with`](crate::closed_loop::timeline::run_with)) owns the plant, the
//! measurements and the log; it calls [`Ecu::control`] at every 10 ms control
//! release with the plant's state of that instant and applies the actuation it
//! returns. Everything else (when the `plan` task runs, how long it takes, when its
//! plan is published) is the ECU's business: modelled here by [`SimulatedEcu`],
//! measured on the firmware running under an emulator by another implementation.
//!
//! # The modelled timeline ([`SimulatedEcu`])
//!
//! At each call at `t` (a multiple of 10 ms): a plan activation that has finished
//! by `t` publishes its plan (if optimal), then `control` runs on the estimate and
//! the current plan, its actuation sent at `t` plus its modelled cycles over the
//! clock (control releases are never skipped in this model: a control activation
//! longer than its period shows as a deadline miss); when `t` is a multiple of 100 ms the `plan` task is released
//! after it (lower priority) on the same estimate. The host computes the plan at
//! once, but the activation finishes, and publishes, at
//!
//! ```text
//! finish = release + (plan cycles + cycles of the control activations that preempt it) / f_ECU
//! ```
//!
//! with every activation's instructions from its own work counters through
//! [`CostModel`], failed activations included, and cycles = instructions ×
//! [`SimOptions::cycles_per_instruction`]. A release that falls while the `plan`
//! task is still running is skipped (see the late-plan policy in
//! [`crate::closed_loop::timeline`]). A window of the road is received and adopted
//! by the first activation released after it arrived, instead of planning (as the
//! ECU does: an activation plans or adopts, never both); that activation takes the
//! cost model's window time and publishes nothing.

use anyhow::{anyhow, Result};
use firmware::low_level::Actuation;
use firmware::mpc::MpcReport;
use firmware::obstacles::Obstacle as FwObstacle;
use firmware::plan::Plan;
use firmware::state_estimate::StateEstimate;
use firmware::tasks::{ControlTask, PlanTask, CONTROL_PERIOD_US, MAX_PLAN_AGE_US, PLAN_PERIOD_US};
use firmware::Real;
use serde::{Deserialize, Serialize};

use crate::closed_loop::cost_model::CostModel;
use crate::closed_loop::plan_activation::{mpc_error_name, PlanActivation, WINDOW_STATUS};
use crate::closed_loop::summary::CarEstimate;
use crate::closed_loop::SimOptions;
use crate::model::vehicle::vehicle_config;
use crate::model::vehicle::VehicleParams;
use crate::pil::link_fault::RouteFault;
use crate::world::obstacle_file::Obstacle;
use crate::world::route::HOST_PATH_CAP;
use crate::world::route::{RouteFeeder, Window};
use crate::world::scenario::Scenario;

/// One task's deadline counts as the ECU itself counted them on its own clock
/// (`firmware::deadline`), cumulative.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct EcuTaskCounts {
    /// Releases that ran.
    pub releases: u64,
    /// Late completions plus skipped releases.
    pub deadline_misses: u64,
    /// Releases skipped because the task was still busy.
    pub skipped_releases: u64,
    /// Activations over their cycle budget, counted in the ECU's own clock ticks.
    pub budget_overruns: u64,
    /// Largest response time, µs.
    pub max_response_us: u64,
}

impl From<firmware::link::TaskTimingFrame> for EcuTaskCounts {
    fn from(t: firmware::link::TaskTimingFrame) -> Self {
        Self {
            releases: t.releases.into(),
            deadline_misses: t.deadline_misses.into(),
            skipped_releases: t.skipped_releases.into(),
            budget_overruns: t.budget_overruns.into(),
            max_response_us: t.max_response_us.into(),
        }
    }
}

/// What an ECU that watches its own deadlines reports (processor in the loop).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct EcuCounts {
    /// The `plan` task's counts (as of the last plan event received).
    pub plan: EcuTaskCounts,
    /// The `control` task's counts.
    pub control: EcuTaskCounts,
    /// Times the control task's watchdog saw no new plan for too long.
    pub watchdog_trips: u64,
    /// Frames the ECU refused, by reason (forged, replayed, corrupt), on both
    /// its channels.
    pub frames_refused: firmware::link::RefusalCounts,
}

/// A control activation's completion, as the ECU timed it: the instant its
/// answer had left it (its deadline is judged from this).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ControlCompletion {
    /// The control release it answered, µs.
    pub release_us: u64,
    /// Its completion, µs on the same timeline.
    pub completed_us: u64,
}

impl ControlCompletion {
    /// Its response time: completion − release, µs.
    pub fn response_us(&self) -> u64 {
        self.completed_us.saturating_sub(self.release_us)
    }
}

/// What one control activation produced.
#[derive(Clone, Debug, PartialEq)]
pub struct ControlOutput<T> {
    /// The actuation to hold until the next one takes effect.
    pub actuation: Actuation<T>,
    /// The control release this activation ran at, µs (the call's `t_us` unless
    /// the ECU fell behind).
    pub release_us: u64,
    /// When the ECU sent the actuation, µs on the same timeline: the plant applies
    /// it from the plant step containing that instant (see [`crate::closed_loop::timeline`]).
    pub sent_us: u64,
    /// A control activation's completion that became known with this output: this
    /// activation's own for the modelled ECU (no link to write to: it completes
    /// when it sends), the previous one's for the ECU in QEMU (it completes once
    /// its frame has been written, which only its next frame can report; `None`
    /// in the first). The control deadline misses are counted from these.
    pub completion: Option<ControlCompletion>,
    /// Control releases the ECU skipped before this one (it was still busy).
    pub control_skipped_releases: u32,
    /// The ECU's own deadline counts after this activation, `None` when the ECU
    /// does not count them (the modelled ECU).
    pub ecu_counts: Option<EcuCounts>,
    /// Instructions of this control activation.
    pub instructions: f64,
    /// Its cycles (instructions × cycles per instruction), ECU cycles.
    pub cycles: f64,
    /// Plan activations that finished since the previous control activation, in order.
    pub plans: Vec<PlanActivation>,
    /// Plan releases lost since the previous call because the plan task was still
    /// running (each a deadline miss).
    pub skipped_releases: u32,
    /// The control task's friction estimate `μ̂` after this activation
    /// (`firmware::friction`; `+∞`: no slip seen), `None` when the ECU does not
    /// report it (processor in the loop).
    pub friction_mu: Option<f64>,
    /// The plan task's sideslip lag `λ` after this activation, rad per m/s²
    /// (`firmware::sideslip`), `None` when the ECU does not report it (processor
    /// in the loop).
    pub sideslip_lag: Option<f64>,
    /// The control task's estimate of the car after this activation
    /// (`firmware::longitudinal_estimator`), `None` when the ECU does not report
    /// it (processor in the loop).
    pub car_estimate: Option<CarEstimate>,
}

/// The estimate of the car of the control task `control`.
pub fn car_estimate_of<T: Real>(control: &ControlTask<T>) -> CarEstimate {
    let lon = control.longitudinal();
    let cfg = &control.friction_config().longitudinal;
    let [r0, r2] = lon.resistance_terms_mps2();
    CarEstimate {
        mass_ratio: lon.mass_ratio().to_f64(),
        mass_uncertainty: lon.mass_uncertainty(cfg).to_f64(),
        resistance_r0_mps2: r0.to_f64(),
        resistance_r2_mps2: r2.to_f64(),
        brake_gain: lon.brake_gain().to_f64(),
        brake_uncertainty: lon.brake_uncertainty(cfg).to_f64(),
    }
}

/// The firmware side of the closed loop.
pub trait Ecu<T: Real> {
    /// The control activation released at `t_us` (µs) on `est` (the plant's state
    /// at that instant); the ECU also runs everything due by `t_us` (plan releases
    /// at multiples of 100 ms happen right after the control activation of the same
    /// instant, as the priorities order them).
    fn control(&mut self, t_us: u64, est: &StateEstimate<T>) -> Result<ControlOutput<T>>;

    /// The plan the control task is following after the last call (for the
    /// consistency figure and plan traces).
    fn active_plan(&self) -> &Plan<T>;

    /// The next window of the road ([`crate::world::route`]), given before the control
    /// activation of the instant it is due; the plan task's first activation released
    /// from then on (not skipped) receives and adopts it, instead of planning.
    fn set_window(&mut self, w: &Window) -> Result<()>;

    /// Whether [`Self::active_plan`] carries each node's speed and steering (the
    /// plan's lateral acceleration is measured from them), not only its positions.
    fn reports_plan_states(&self) -> bool {
        true
    }
}

/// A plan activation computed on the host, waiting for its modelled finish.
#[derive(Clone, Debug)]
struct InFlight {
    record: PlanActivation,
}

/// The firmware's two tasks in this process, on the modelled timeline (see the
/// module docs).
#[derive(Debug)]
pub struct SimulatedEcu<T: Real> {
    planner: Box<PlanTask<T, HOST_PATH_CAP>>,
    control: ControlTask<T>,
    shared_plan: Plan<T>,
    cost_model: CostModel,
    cycles_per_instruction: f64,
    ecu_clock_hz: f64,
    in_flight: Option<InFlight>,
    busy_until_us: u64,
    releases: u32,
    /// The windows of the road on their way to the plan task, frame by frame.
    route: RouteChannel,
    /// This period's sensor frame is refused (a link fault): the control task
    /// does not learn of the frames of the road sent before it.
    route_unheard: bool,
}

/// A frame of the road: the window it belongs to (an index into
/// [`RouteChannel::windows`]) and its place in it (the `PathChunk`s from 0, then the
/// `Window` frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct RouteFrame {
    window: usize,
    index: usize,
    /// Replaced on the way by a link fault: the ECU refuses it and stages
    /// nothing from it.
    refused: bool,
}

/// The route channel as the ECU sees it: the host sends one frame of the road
/// before the sensor frame of each plan release, the control task learns of it
/// from that sensor frame (not from a refused one: then from the next it
/// accepts), and the plan task reads at most one announced frame per activation,
/// adopting the window its `Window` frame completes instead of planning (the
/// ECU application's `route_job`).
#[derive(Clone, Debug, Default)]
struct RouteChannel {
    /// Every window given so far.
    windows: Vec<Window>,
    /// Frames not yet sent (the newest window's; a newer one replaces them).
    unsent: std::collections::VecDeque<RouteFrame>,
    /// Frames sent, not yet read by the plan task, in order.
    in_channel: std::collections::VecDeque<RouteFrame>,
    /// Frames sent, in all.
    sent: u32,
    /// Frames the control task has learnt of, in all.
    announced: u32,
    /// Frames the plan task has read, in all.
    read: u32,
    /// The window being staged and how many of its frames arrived in order.
    staged: Option<(usize, usize)>,
    /// The frames a link fault replaces on the way (`host-sim pil --link-fault
    /// route-…`), and how many it replaced so far.
    fault: Option<(RouteFault, u32)>,
}

impl RouteChannel {
    /// Frames of a window of `rows` rows: its chunks and its `Window` frame.
    fn frames_of(w: &Window) -> usize {
        firmware::link::route_frames(w.rows.len())
    }

    /// A new window: its frames replace the ones not yet sent.
    fn give(&mut self, w: &Window) {
        let window = self.windows.len();
        self.windows.push(w.clone());
        self.unsent = (0..Self::frames_of(w))
            .map(|index| RouteFrame {
                window,
                index,
                refused: false,
            })
            .collect();
    }

    /// The control period at `t_us`: at a plan release one frame is sent before
    /// the sensor frame; the control task learns of the frames sent so far unless
    /// its sensor frame is refused (`heard`).
    fn period(&mut self, t_us: u64, heard: bool) {
        if t_us.is_multiple_of(PLAN_PERIOD_US) {
            if let Some(mut f) = self.unsent.pop_front() {
                if let Some((fault, replaced)) = &mut self.fault {
                    if fault.replaces(t_us, *replaced) {
                        f.refused = true;
                        *replaced += 1;
                    }
                }
                self.in_channel.push_back(f);
                self.sent += 1;
            }
        }
        if heard {
            self.announced = self.sent;
        }
    }

    /// Whether a plan activation now has an announced frame to read.
    fn has_frame(&self) -> bool {
        self.announced > self.read && !self.in_channel.is_empty()
    }

    /// A plan activation reads one announced frame, if any: the window it
    /// completes, if it does.
    fn read_one(&mut self) -> Option<Window> {
        if !self.has_frame() {
            return None;
        }
        let f = self.in_channel.pop_front()?;
        self.read += 1;
        if f.refused {
            return None;
        }
        let total = self.windows.get(f.window).map_or(0, Self::frames_of);
        // The first chunk restarts the staging; a frame out of order is refused.
        self.staged = match self.staged {
            _ if f.index == 0 => Some((f.window, 1)),
            Some((w, n)) if w == f.window && n == f.index => Some((w, n + 1)),
            _ => None,
        };
        match self.staged {
            Some((w, n)) if n == total => {
                self.staged = None;
                self.windows.get(w).cloned()
            }
            _ => None,
        }
    }
}

impl<T: Real> SimulatedEcu<T> {
    /// The tasks for `scenario`'s track and obstacles and `vehicle`'s car, timed
    /// with `opts`' cost model and ECU clock. Fails, saying why, on a track or an
    /// obstacle the planner refuses or a clock that is not a positive number.
    pub fn new(scenario: &Scenario, vehicle: &VehicleParams, opts: &SimOptions) -> Result<Self> {
        if !(opts.ecu_clock_hz.is_finite() && opts.ecu_clock_hz > 0.0) {
            return Err(anyhow!(
                "ECU clock must be a positive number of Hz, got {}",
                opts.ecu_clock_hz
            ));
        }
        if !(opts.cycles_per_instruction.is_finite() && opts.cycles_per_instruction > 0.0) {
            return Err(anyhow!(
                "cycles per instruction must be a positive number, got {}",
                opts.cycles_per_instruction
            ));
        }
        let track = &scenario.track;
        // The planner: path, obstacles, MPC (boxed: the path is large on the host).
        let car = vehicle_config::<T>(vehicle);
        let mu_planner = T::from_f64(opts.mu_planner);
        let mut planner: Box<PlanTask<T, HOST_PATH_CAP>> =
            Box::new(PlanTask::new(car.mpc_settings(), mu_planner));
        let rows: Vec<[T; 4]> = track.rows().iter().map(|r| r.map(T::from_f64)).collect();
        planner
            .path
            .load_track(&rows, track.closed)
            .map_err(|e| anyhow!("track {}: the planner refused it: {e:?}", track.name))?;
        let fw_obstacles = scenario
            .obstacles
            .iter()
            .enumerate()
            .map(|(k, o)| {
                let v: Vec<[T; 2]> = o.vertices.iter().map(|p| p.map(T::from_f64)).collect();
                FwObstacle::from_vertices(k as u32, &v)
                    .map_err(|e| anyhow!("obstacle {:?}: {e:?}", o.id))
            })
            .collect::<Result<Vec<_>>>()?;
        planner
            .obstacles
            .update(
                &car.obstacle_settings(mu_planner),
                &planner.path,
                &fw_obstacles,
            )
            .map_err(|e| obstacle_error_message(e, &scenario.obstacles))?;
        // Checked on the whole track above; from here the planner holds a window
        // of the road, as the ECU does.
        planner.set_obstacles(car.obstacle_settings(mu_planner), &fw_obstacles);
        let first = RouteFeeder::new(track)?.first();
        load_window(&mut planner, &first)?;
        planner.stats = Default::default();
        let control = car
            .control_task(mu_planner)
            .map_err(|e| anyhow!("low-level controller configuration: {e:?}"))?;
        Ok(Self {
            planner,
            control,
            shared_plan: Plan::zeroed(),
            cost_model: opts.cost_model,
            cycles_per_instruction: opts.cycles_per_instruction,
            ecu_clock_hz: opts.ecu_clock_hz,
            in_flight: None,
            busy_until_us: 0,
            releases: 0,
            route: RouteChannel::default(),
            route_unheard: false,
        })
    }

    /// The plan task (its settings can be changed before the first activation,
    /// e.g. its iteration cap).
    pub fn plan_task_mut(&mut self) -> &mut PlanTask<T, HOST_PATH_CAP> {
        &mut self.planner
    }

    /// The control task (its counters: safe actuations, faults).
    pub fn control_task(&self) -> &ControlTask<T> {
        &self.control
    }

    /// An activation released at `t_us` of `instructions`: its cycles and its
    /// finish, µs (preempted by the control activations meanwhile); the task is
    /// busy until then.
    fn occupy(&mut self, t_us: u64, instructions: f64) -> (f64, u64) {
        let cycles = instructions * self.cycles_per_instruction;
        let control_cycles = self.cost_model.control_instructions() * self.cycles_per_instruction;
        let finish_us = t_us + response_us(cycles, control_cycles, self.ecu_clock_hz).ceil() as u64;
        self.busy_until_us = finish_us;
        (cycles, finish_us)
    }

    /// The route frames `fault` replaces on the way are refused (a link fault of
    /// the route channel): their windows never complete.
    pub fn refuse_route_frames(&mut self, fault: RouteFault) {
        self.route.fault = Some((fault, 0));
    }

    /// This period's sensor frame is refused (a link fault, before
    /// [`Ecu::control`]): the control task does not learn of the frames of the
    /// road sent with it, until a sensor frame it accepts.
    pub fn refuse_sensor_frame(&mut self) {
        self.route_unheard = true;
    }

    /// Runs the plan task released at `t_us` on `est` on the host, after a frame
    /// of the road that cost `route_instructions`; its record waits in flight
    /// until its modelled finish.
    fn release_plan(&mut self, t_us: u64, est: &StateEstimate<T>, route_instructions: f64) {
        self.planner.set_friction_limit(self.control.friction_mu());
        self.planner.set_tyres_linear(self.control.tyres_linear());
        let outcome = self.planner.run(est);
        // Charged from the activation's own counters, a failed one's included.
        let report = *self.planner.last_report();
        let instructions = self.cost_model.plan_instructions(&report) + route_instructions;
        let (cycles, finish_us) = self.occupy(t_us, instructions);
        // The late-plan policy: published at its finish unless older than
        // MAX_PLAN_AGE_US by then (`PlanTask::publish_at`).
        let fresh = finish_us - t_us <= MAX_PLAN_AGE_US;
        let (status, published) = match &outcome {
            Ok(_) => ("optimal", fresh),
            Err(e) => (mpc_error_name(e), false),
        };
        self.in_flight = Some(InFlight {
            record: activation_record(
                self.releases,
                t_us,
                finish_us,
                instructions,
                cycles,
                &report,
            )
            .with_outcome(status, published)
            .with_route_frames(route_instructions),
        });
    }
}

impl<T: Real> SimulatedEcu<T> {
    /// The activation released at `t_us` adopts the window `w` its frame of the
    /// road (`route_instructions`) completed, instead of planning; the task stays
    /// busy for the adoption's modelled time.
    fn adopt_window(&mut self, t_us: u64, w: &Window, route_instructions: f64) {
        // A path the planner refuses leaves it without one: its steps then fail
        // with `NoPath` and are reported as such.
        let _ = load_window(&mut self.planner, w);
        let instructions = self.cost_model.window_instructions() + route_instructions;
        let (cycles, finish_us) = self.occupy(t_us, instructions);
        let mut record = activation_record(
            self.releases,
            t_us,
            finish_us,
            instructions,
            cycles,
            &MpcReport::<T>::default(),
        )
        .with_outcome(WINDOW_STATUS, false)
        .with_route_frames(route_instructions);
        record.window = true;
        record.window_instructions = instructions;
        self.in_flight = Some(InFlight { record });
    }
}

/// Loads a window of the road into the plan task.
fn load_window<T: Real>(planner: &mut PlanTask<T, HOST_PATH_CAP>, w: &Window) -> Result<()> {
    let rows: Vec<[T; 4]> = w.rows.iter().map(|r| r.map(T::from_f64)).collect();
    planner
        .load_window(&rows, T::from_f64(w.origin_m), w.closed)
        .map_err(|e| anyhow!("a window of the road was refused: {e:?}"))
}

/// Response time of a plan activation of `cycles` preempted every 10 ms by a
/// control activation of `control_cycles`, on a clock of `clock_hz`, µs.
fn response_us(cycles: f64, control_cycles: f64, clock_hz: f64) -> f64 {
    let mut resp_s = cycles / clock_hz;
    for _ in 0..64 {
        let preempting = (resp_s * 1e6 / CONTROL_PERIOD_US as f64).floor();
        let next = (cycles + preempting * control_cycles) / clock_hz;
        if (next - resp_s).abs() < 1e-12 {
            break;
        }
        resp_s = next;
    }
    resp_s * 1e6
}

fn activation_record<T: Real>(
    activation: u32,
    release_us: u64,
    finish_us: u64,
    instructions: f64,
    cycles: f64,
    r: &MpcReport<T>,
) -> PlanActivation {
    PlanActivation {
        activation,
        release_us,
        finish_us,
        instructions,
        cycles,
        status: "optimal",
        published: false,
        deadline_miss: finish_us > release_us + PLAN_PERIOD_US,
        passes: r.passes,
        warm: r.warm,
        qp_iterations: r.qp_iterations,
        qp_added: r.qp_added,
        qp_removed: r.qp_removed,
        qp_refactorizations: r.qp_refactorizations,
        rows: r.rows,
        active_constraints: r.active_constraints,
        window: false,
        window_instructions: 0.0,
        route_frames: 0,
        max_validity_slack_rad: Some(r.max_validity_slack_rad.to_f64()),
    }
}

impl PlanActivation {
    /// The record of an activation that received a frame of the road first (its
    /// cost `route_instructions` > 0).
    fn with_route_frames(mut self, route_instructions: f64) -> Self {
        self.route_frames = u32::from(route_instructions > 0.0);
        self
    }

    fn with_outcome(mut self, status: &'static str, published: bool) -> Self {
        self.status = status;
        self.published = published;
        if !published {
            self.max_validity_slack_rad = Some(0.0);
        }
        self
    }
}

impl<T: Real> Ecu<T> for SimulatedEcu<T> {
    fn control(&mut self, t_us: u64, est: &StateEstimate<T>) -> Result<ControlOutput<T>> {
        let mut plans = Vec::new();
        // A plan activation that has finished by now publishes first.
        if self
            .in_flight
            .as_ref()
            .is_some_and(|f| f.record.finish_us <= t_us)
        {
            if let Some(f) = self.in_flight.take() {
                let published = self
                    .planner
                    .publish_at(&mut self.shared_plan, f.record.finish_us);
                debug_assert_eq!(published, f.record.published);
                plans.push(f.record);
            }
        }
        let actuation = self.control.run(est, &self.shared_plan, t_us);
        let instructions = self.cost_model.control_instructions();
        let cycles = instructions * self.cycles_per_instruction;
        // The actuation leaves when the modelled activation ends.
        let sent_us = t_us + (cycles / self.ecu_clock_hz * 1e6).ceil() as u64;
        let mut skipped_releases = 0;
        self.route
            .period(t_us, !std::mem::take(&mut self.route_unheard));
        if t_us.is_multiple_of(PLAN_PERIOD_US) {
            self.releases += 1;
            if self.busy_until_us > t_us {
                // Still running: this release is lost (RTIC cannot spawn a busy task).
                skipped_releases = 1;
            } else {
                // A frame of the road first (`route_job`), then the adoption of the
                // window it completes or the plan.
                let frame = self.route.has_frame();
                let route_instructions = if frame {
                    self.cost_model.route_frame_instructions()
                } else {
                    0.0
                };
                match self.route.read_one() {
                    Some(w) => self.adopt_window(t_us, &w, route_instructions),
                    None => self.release_plan(t_us, est, route_instructions),
                }
            }
        }
        Ok(ControlOutput {
            actuation,
            release_us: t_us,
            sent_us,
            completion: Some(ControlCompletion {
                release_us: t_us,
                completed_us: sent_us,
            }),
            control_skipped_releases: 0,
            ecu_counts: None,
            instructions,
            cycles,
            plans,
            skipped_releases,
            friction_mu: Some(self.control.friction_mu().to_f64()),
            sideslip_lag: Some(self.planner.sideslip_lag().to_f64()),
            car_estimate: Some(car_estimate_of(&self.control)),
        })
    }

    fn active_plan(&self) -> &Plan<T> {
        &self.shared_plan
    }

    fn set_window(&mut self, w: &Window) -> Result<()> {
        self.route.give(w);
        Ok(())
    }
}

fn obstacle_error_message<T: Real>(
    e: firmware::obstacles::ObstacleError<T>,
    obstacles: &[Obstacle],
) -> anyhow::Error {
    use firmware::obstacles::ObstacleError as E;
    match e {
        E::RoadBlocked {
            obstacle,
            missing_m,
        } => {
            let id = obstacles
                .get(obstacle)
                .map(|o| o.id.as_str())
                .unwrap_or("?");
            anyhow!(
                "obstacle {id:?} blocks the road: the car needs {:.2} m more free width beside it on either side; move it, make it narrower, or widen the track there (to see the car stop before a blocked road, use --fault blocked-road)",
                missing_m.to_f64()
            )
        }
        other => anyhow!("obstacles: {other:?}"),
    }
}
