//! The ECU watches its own deadlines: releases, completions, response times,
//! deadline misses, budget overruns and skipped releases of a periodic task,
//! stamped on the ECU's own clock; the control task's consecutive-miss rule and
//! its watchdog on the plan task.
//!
//! No heap, integers only (µs and cycles as `u64`, counts as `u32`, saturating),
//! deterministic: the same stamps give the same counts on the ECU and on the host
//! (`firmware/tests/deadline.rs`).
//!
//! # The timeline
//!
//! Release `k` of a task of period `P` is at `k·P` µs on the ECU's timeline (µs
//! since its start, the first `control` release). Its deadline is the next
//! release, `(k + 1)·P`: the period is the deadline.
//!
//! * **Completion** ([`DeadlineMonitor::complete`]): the instant the activation's
//!   result has left it (`control`: its actuation frame has been written to the
//!   link, the encoding included; `plan`: the plan has been swapped in under the
//!   lock). Response time = completion − release. A `control` frame cannot carry
//!   an instant after its own encoding: it carries the instant it was handed to
//!   the link (`ActuationFrame::sent_us`, from which the plant applies it), and the
//!   next frame carries this completion with the counts that include it. A
//!   response time over the
//!   period is a **deadline miss**. The activation's own execution (its core
//!   clock cycles, preemption excluded) over the budget is a **budget overrun**,
//!   counted apart (it may or may not miss).
//! * **End** ([`DeadlineMonitor::next_release`]): the activation may keep working
//!   after its completion (`control` receives nothing more; `plan` adopts a new
//!   window of the road). The next release is the first one not yet past at the
//!   end (a release exactly at the end is not past); the releases in between fell
//!   while the task was busy and are **skipped**, not queued: each is counted as a
//!   skipped release and as a deadline miss (the host counts alike).
//!
//! # Policies (the ECU application, `bin/ecu.rs`)
//!
//! * `control` (10 ms, budget [`CONTROL_BUDGET_CYCLES`]): an overrun is not
//!   absorbed. The releases that fell during it are skipped and counted; after
//!   [`CONTROL_MISS_LIMIT`] consecutive misses (late completions and skipped
//!   releases alike, reset by an activation that completes in time)
//!   [`DeadlineMonitor::safe_stop`] latches: from the next activation on (an
//!   activation's own completion follows its frame) every activation sends
//!   the safe actuation (zero torque, steering held, as the panic path does) with
//!   the fault [`crate::link::FAULT_DEADLINE`], until the ECU is reset.
//! * `plan` (100 ms, budget [`PLAN_BUDGET_CYCLES`]): the late-plan policy of
//!   [`crate::tasks`]; its misses are counted, no miss limit.
//! * Watchdog ([`PlanWatchdog`], run by `control` every period): more than
//!   [`PLAN_WATCHDOG_PERIODS`] plan periods without a new plan trip it (counted
//!   once per silence, re-armed by the next plan). It changes no command: the
//!   late-plan policy already brings the car to a controlled stop when the plan
//!   being followed runs out.

use crate::low_level::Actuation;
use crate::timing::{CONTROL_PERIOD_US, PLAN_PERIOD_US};
use crate::Real;

/// Budget of one `control` activation, ECU core clock cycles (its own work,
/// preemption excluded; its deadline is its 10 ms period). 6,000: 36 µs at
/// 168 MHz, 0.36 % of the period; the job's static bound (`host-sim wcet`,
/// `control_job`) is held under it with room for the next feature (it was 5,000
/// until the wheel speeds, the brakes' gain and their left/right distribution
/// took the bound past it).
pub const CONTROL_BUDGET_CYCLES: u64 = 6_000;
/// Time of the `plan` period kept for the preempting `control` activations and
/// timer jitter, µs: the plan activation's own work has the rest.
pub const PLAN_RESERVE_US: u64 = 5_000;
/// Budget of one `plan` activation, ECU core clock cycles: the plan period less
/// [`PLAN_RESERVE_US`] at the core clock (95 ms at 168 MHz: 15,960,000).
pub const PLAN_BUDGET_CYCLES: u64 =
    (PLAN_PERIOD_US - PLAN_RESERVE_US) * crate::timing::ECU_CLOCK_HZ as u64 / 1_000_000;
/// Consecutive `control` deadline misses (late completions or skipped releases)
/// after which the control task latches the safe actuation, misses. Three: 30 ms
/// without an actuation computed in time, twice the longest a yaw loop at 100 Hz is
/// meant to go without one and short enough that a car at 25 m/s moves 0.75 m.
pub const CONTROL_MISS_LIMIT: u32 = 3;
/// Plan periods without a new plan after which the control task's watchdog trips,
/// periods. Four (400 ms): a plan task that publishes every plan, however late
/// within the late-plan policy (200 ms), never leaves more than 300 ms between two
/// plans; a trip means plans were dropped, failed, or the task stopped.
pub const PLAN_WATCHDOG_PERIODS: u64 = 4;
/// [`PLAN_WATCHDOG_PERIODS`] in µs.
pub const PLAN_WATCHDOG_US: u64 = PLAN_WATCHDOG_PERIODS * PLAN_PERIOD_US;

/// What a [`DeadlineMonitor`] counted so far (all saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DeadlineCounts {
    /// Releases that ran (skipped ones excluded), activations.
    pub releases: u32,
    /// Completions recorded, activations.
    pub completions: u32,
    /// Deadline misses: completions later than the period after their release,
    /// plus skipped releases, misses.
    pub deadline_misses: u32,
    /// Of those, releases skipped because the task was still busy, releases.
    pub skipped_releases: u32,
    /// Activations whose own execution exceeded the budget, activations.
    pub budget_overruns: u32,
    /// Largest response time (completion − release), µs (saturated at `u32::MAX`).
    pub max_response_us: u32,
}

/// One completion, as [`DeadlineMonitor::complete`] judged it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Completion {
    /// Completion − release, µs (0 if the completion is stamped before the release).
    pub response_us: u64,
    /// The response time exceeded the period (the deadline).
    pub missed: bool,
    /// The activation's own cycles exceeded the budget.
    pub overrun: bool,
}

/// The next release, as [`DeadlineMonitor::next_release`] found it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NextRelease {
    /// Index of the next release (release `k` is at `k·period`), releases.
    pub index: u64,
    /// Its instant on the timeline, µs.
    pub release_us: u64,
    /// Releases skipped before it (fell while the task was busy), releases.
    pub skipped: u32,
}

/// Releases, completions and deadlines of one periodic task on the ECU's clock
/// (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DeadlineMonitor {
    /// Period = relative deadline, µs (> 0).
    period_us: u64,
    /// Budget of one activation, cycles.
    budget_cycles: u64,
    /// Consecutive misses that latch [`DeadlineMonitor::safe_stop`], misses (0: never).
    miss_limit: u32,
    /// Index of the current release.
    index: u64,
    /// Consecutive misses so far, misses.
    consecutive: u32,
    /// Latched once `consecutive` reached `miss_limit`.
    safe_stop: bool,
    counts: DeadlineCounts,
}

impl DeadlineMonitor {
    /// A task of period (= deadline) `period_us` µs (0 is taken as 1), a budget of
    /// `budget_cycles` cycles per activation and a limit of `miss_limit`
    /// consecutive misses (0: no limit); its current release is release 0, at 0 µs.
    pub const fn new(period_us: u64, budget_cycles: u64, miss_limit: u32) -> Self {
        Self {
            period_us: if period_us == 0 { 1 } else { period_us },
            budget_cycles,
            miss_limit,
            index: 0,
            consecutive: 0,
            safe_stop: false,
            counts: DeadlineCounts {
                releases: 0,
                completions: 0,
                deadline_misses: 0,
                skipped_releases: 0,
                budget_overruns: 0,
                max_response_us: 0,
            },
        }
    }

    /// The `control` task: 10 ms, [`CONTROL_BUDGET_CYCLES`], [`CONTROL_MISS_LIMIT`].
    pub const fn control() -> Self {
        Self::new(CONTROL_PERIOD_US, CONTROL_BUDGET_CYCLES, CONTROL_MISS_LIMIT)
    }

    /// The `plan` task: 100 ms, [`PLAN_BUDGET_CYCLES`], no miss limit.
    pub const fn plan() -> Self {
        Self::new(PLAN_PERIOD_US, PLAN_BUDGET_CYCLES, 0)
    }

    /// Period (= relative deadline), µs.
    pub const fn period_us(&self) -> u64 {
        self.period_us
    }

    /// Index of the current release (release `k` is at `k·period`), releases.
    pub const fn release_index(&self) -> u64 {
        self.index
    }

    /// Instant of the current release on the timeline, µs.
    pub const fn release_us(&self) -> u64 {
        self.index.saturating_mul(self.period_us)
    }

    /// The current release starts running: counted; returns its instant, µs.
    pub fn start(&mut self) -> u64 {
        self.counts.releases = self.counts.releases.saturating_add(1);
        self.release_us()
    }

    /// The current release completed at `finish_us` (µs on the timeline) after
    /// `cycles` core clock cycles of its own execution: its response time, a miss
    /// when over the period, an overrun when over the budget.
    pub fn complete(&mut self, finish_us: u64, cycles: u64) -> Completion {
        let response_us = finish_us.saturating_sub(self.release_us());
        let missed = response_us > self.period_us;
        let overrun = cycles > self.budget_cycles;
        let c = &mut self.counts;
        c.completions = c.completions.saturating_add(1);
        c.max_response_us = c
            .max_response_us
            .max(response_us.min(u32::MAX as u64) as u32);
        if overrun {
            c.budget_overruns = c.budget_overruns.saturating_add(1);
        }
        if missed {
            c.deadline_misses = c.deadline_misses.saturating_add(1);
            self.miss(1);
        } else {
            self.consecutive = 0;
        }
        Completion {
            response_us,
            missed,
            overrun,
        }
    }

    /// The current activation ended at `end_us` (µs): moves to the first release
    /// after the current one that is not yet past (`≥ end_us`); the releases in
    /// between are skipped and counted (each a deadline miss).
    pub fn next_release(&mut self, end_us: u64) -> NextRelease {
        let first = self.index.saturating_add(1);
        // The first index j ≥ first with j·period ≥ end_us: `first` plus the periods
        // the job ended past that release (none if it ended before), in 32 bits (the
        // M4F's `UDIV`; no 64-bit library division, whose long path is a loop).
        // Exact for up to 2³² µs (71 min) late; later still counts as that late, and
        // the next release, then already past, skips the rest.
        let late = end_us.saturating_sub(first.saturating_mul(self.period_us));
        let late = u32::try_from(late).unwrap_or(u32::MAX);
        let period = u32::try_from(self.period_us).unwrap_or(u32::MAX);
        let next = first.saturating_add(late.div_ceil(period) as u64);
        let skipped = (next - first).min(u32::MAX as u64) as u32;
        if skipped > 0 {
            let c = &mut self.counts;
            c.skipped_releases = c.skipped_releases.saturating_add(skipped);
            c.deadline_misses = c.deadline_misses.saturating_add(skipped);
            self.miss(skipped);
        }
        self.index = next;
        NextRelease {
            index: next,
            release_us: self.release_us(),
            skipped,
        }
    }

    fn miss(&mut self, n: u32) {
        self.consecutive = self.consecutive.saturating_add(n);
        if self.miss_limit > 0 && self.consecutive >= self.miss_limit {
            self.safe_stop = true;
        }
    }

    /// Consecutive misses (late completions and skipped releases) since the last
    /// completion in time, misses.
    pub const fn consecutive_misses(&self) -> u32 {
        self.consecutive
    }

    /// Latched once the consecutive misses reached the miss limit: the task must
    /// apply its safe output from now on.
    pub const fn safe_stop(&self) -> bool {
        self.safe_stop
    }

    /// The counts so far.
    pub const fn counts(&self) -> DeadlineCounts {
        self.counts
    }
}

/// The control task's output under the consecutive-miss rule: `computed` while
/// `monitor` has not latched its safe stop; after it has, the safe actuation of
/// the panic path, zero torque on every wheel with the steering held at
/// `held_delta_rad` (rad: the last command sent before the stop), and `true`
/// (send it with [`crate::link::FAULT_DEADLINE`]).
pub fn control_output<T: Real>(
    monitor: &DeadlineMonitor,
    computed: Actuation<T>,
    held_delta_rad: T,
) -> (Actuation<T>, bool) {
    if monitor.safe_stop() {
        (Actuation::safe(held_delta_rad, T::ZERO), true)
    } else {
        (computed, false)
    }
}

/// The control task's watchdog on the plan task: trips when no new plan was seen
/// for more than its limit (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PlanWatchdog {
    /// Longest silence allowed, µs.
    limit_us: u64,
    /// The plan counter at the last new plan.
    last_plans: u32,
    /// When the last new plan was seen (or the timeline's start), µs.
    fed_at_us: u64,
    tripped: bool,
    trips: u32,
}

impl PlanWatchdog {
    /// A watchdog allowing `limit_us` µs without a new plan, fed at the timeline's
    /// start (0 µs) with a plan counter of 0.
    pub const fn new(limit_us: u64) -> Self {
        Self {
            limit_us,
            last_plans: 0,
            fed_at_us: 0,
            tripped: false,
            trips: 0,
        }
    }

    /// [`PLAN_WATCHDOG_US`].
    pub const fn plan() -> Self {
        Self::new(PLAN_WATCHDOG_US)
    }

    /// One control period at `now_us` (µs) with `plans_seen`, a counter that
    /// changes with every new plan the control task follows
    /// (`LowLevelState::plans_seen`): a new plan feeds (and re-arms) the watchdog;
    /// otherwise it trips once the silence exceeds the limit. Returns whether it
    /// is tripped.
    pub fn check(&mut self, now_us: u64, plans_seen: u32) -> bool {
        if plans_seen != self.last_plans {
            self.last_plans = plans_seen;
            self.fed_at_us = now_us;
            self.tripped = false;
        } else if !self.tripped && now_us.saturating_sub(self.fed_at_us) > self.limit_us {
            self.tripped = true;
            self.trips = self.trips.saturating_add(1);
        }
        self.tripped
    }

    /// Tripped (no new plan for more than the limit, none since).
    pub const fn tripped(&self) -> bool {
        self.tripped
    }

    /// Times it tripped so far, trips.
    pub const fn trips(&self) -> u32 {
        self.trips
    }
}
