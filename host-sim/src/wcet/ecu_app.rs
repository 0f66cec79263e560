//! What the analyses know of the ECU's RTIC application (`firmware/src/bin/ecu.rs`)
//! in its two builds ([`EcuBuild`]): its tasks and the interrupts they run in, the sections bounded apart (the jobs,
//! the plan swap) with their budgets, the schedule, and for the stack bound its
//! priority levels and the functions that run once or with interrupts masked. The
//! numbers come from the firmware's own constants. The targets of its indirect
//! calls are read from the binary ([`super::indirect`]).

use super::rta::{Burst, Slow};
use super::stack::PriorityLevel;
use firmware::link::usart;
use serde::Serialize;
use std::path::Path;

/// The two builds of the ECU application: the same tasks, library calls and
/// frames over two transports (`firmware/src/bin/ecu.rs`, "Two builds, one
/// application"). The analyses tell them apart by the symbols of the ELF.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EcuBuild {
    /// `cargo ecu-lockstep`: frames over semihosting, in
    /// lock-step with the simulator; the processor in the loop runs it. RTIC's
    /// dispatchers are `USART1` (plan) and `USART2` (control).
    LockStep,
    /// `cargo ecu`: the binary you flash, frames over USART1's interrupt;
    /// the dispatchers are `SPI1` (plan) and `SPI2` (control).
    Board,
}

/// The control task's priority (RTIC's logical numbering), in both builds.
const CONTROL_PRIORITY: u8 = 2;
/// The plan task's priority, in both builds.
const PLAN_PRIORITY: u8 = 1;

/// A task whose activations are not all alike: most are *light*, bounded from
/// the same root with some of the firmware's constants bound tighter (the
/// annotations that name them evaluated again); the rest carry [`ExtraWork`] of
/// one kind or more, each charged by its units ([`super::rta::Heavy`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LightActivations {
    /// The task.
    pub task: &'static str,
    /// The kinds of extra work a light activation leaves out.
    pub extras: Vec<ExtraWork>,
}

/// One kind of extra work of [`LightActivations`]: the constants that bound it
/// run from their light values (no unit) to the firmware's own
/// (`per_activation` units), a unit's cost is what one unit adds to the bound at
/// most, and the units come at most `per_window` per window of `window_us`
/// (`extra_windows` more in any window; [`super::rta::Extra`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ExtraWork {
    /// What it is, for the report.
    pub what: &'static str,
    /// The unit it comes in, for the report.
    pub unit: &'static str,
    /// The constants that bound it and their values without it.
    pub constants: Vec<(&'static str, u64)>,
    /// Units an activation carries at most (the constants' full values).
    pub per_activation: u64,
    /// Units per window at most.
    pub per_window: u64,
    /// The window, µs.
    pub window_us: f64,
    /// Windows a window of any length draws on besides one per `window_us`.
    pub extra_windows: u64,
    /// The priority of the task that makes the extra work.
    pub producer_priority: Option<u8>,
}

impl ExtraWork {
    /// The values of its constants with `units` of it (`0..=per_activation`):
    /// from the light value to `full`'s, in proportion, rounded up.
    pub fn constants_at(
        &self,
        units: u64,
        full: &std::collections::BTreeMap<&'static str, u64>,
    ) -> Vec<(&'static str, u64)> {
        let units = units.min(self.per_activation);
        self.constants
            .iter()
            .map(|&(name, light)| {
                let top = full.get(name).copied().unwrap_or(light).max(light);
                let span = top - light;
                let add = if self.per_activation == 0 {
                    span
                } else {
                    (span * units).div_ceil(self.per_activation)
                };
                (name, light + add)
            })
            .collect()
    }

    /// As the response-time analysis charges it, `unit_cycles` a unit.
    pub fn charge(&self, unit_cycles: f64) -> super::rta::Extra {
        super::rta::Extra {
            unit_cycles,
            per_activation: self.per_activation,
            per_window: self.per_window,
            window_us: self.window_us,
            extra_windows: self.extra_windows,
            producer_priority: self.producer_priority,
        }
    }
}

/// One activity of the schedule: a task or an interrupt.
#[derive(Debug, Clone, PartialEq)]
pub struct Scheduled {
    /// Name (a task of [`EcuBuild::tasks`]).
    pub name: &'static str,
    /// RTIC logical priority (higher preempts).
    pub priority: u8,
    /// Period, or minimum inter-arrival time, µs.
    pub period_us: f64,
    /// Relative deadline, µs.
    pub deadline_us: f64,
    /// A cap on its activations in a window besides the period (an interrupt the
    /// application rate-limits).
    pub burst: Option<Burst>,
}

impl EcuBuild {
    /// The build an ELF holds: [`EcuBuild::Board`] when it has the USART link's
    /// functions (`ecu::usart_link::…`), else [`EcuBuild::LockStep`].
    pub fn of_elf(elf: &Path) -> Result<Self, super::WcetError> {
        use object::{Object, ObjectSymbol};
        let data = super::read_elf(elf)?;
        let file = super::parse_elf(elf, &data)?;
        let board = file
            .symbols()
            .filter_map(|s| s.name().ok())
            .any(|n| super::demangle(n).starts_with("ecu::usart_link::"));
        Ok(if board { Self::Board } else { Self::LockStep })
    }

    /// Its name in the reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::LockStep => "lock-step (cargo ecu-lockstep: semihosting)",
            Self::Board => "board (cargo ecu: USART1, the binary you flash)",
        }
    }

    /// The tasks and interrupts whose activations the analysis bounds: name and
    /// handler symbol. `plan` runs in the priority-1 dispatcher, `control` in the
    /// priority-2 one, the release clock (`firmware/src/bin/support/release_clock.rs`) in `SysTick`; the flashed
    /// build's link in `USART1`.
    pub fn tasks(self) -> &'static [(&'static str, &'static str)] {
        match self {
            Self::LockStep => &[
                ("control", "USART2"),
                ("plan", "USART1"),
                ("systick", "SysTick"),
            ],
            Self::Board => &[
                ("control", "SPI2"),
                ("plan", "SPI1"),
                ("link", "USART1"),
                ("systick", "SysTick"),
            ],
        }
    }

    /// The activities of [`EcuBuild::schedule`] that are interrupts the hardware
    /// raises (SysTick, and the flashed build's USART1), not software tasks.
    pub fn interrupts(self) -> &'static [&'static str] {
        match self {
            Self::LockStep => &["systick"],
            Self::Board => &["link", "systick"],
        }
    }

    /// The schedule: the tasks at their periods (= deadlines); SysTick, the
    /// monotonic's tick (`firmware::timing::MONO_TICK_US`, one a control period), above them
    /// (the lock-step build leaves it at the hardware's most urgent level; the
    /// flashed build sets [`usart::SYSTICK_PRIORITY`]); in the flashed build,
    /// USART1's interrupt above all ([`usart::LINK_INTERRUPT_PRIORITY`]): an
    /// entry a byte, at most [`usart::ENTRIES_PER_BUDGET`] per control period's
    /// budget and [`usart::ENTRIES_PER_PLAN_BUDGET`] more per plan period's
    /// ([`usart::EXTRA_BUDGETS_PER_WINDOW`] more of each in any window), its
    /// deadline a byte's time (a byte not read by then is overrun by the next).
    pub fn schedule(self) -> Vec<Scheduled> {
        let control = firmware::tasks::CONTROL_PERIOD_US as f64;
        let plan = firmware::tasks::PLAN_PERIOD_US as f64;
        let task = |name, priority, period_us| Scheduled {
            name,
            priority,
            period_us,
            deadline_us: period_us,
            burst: None,
        };
        match self {
            Self::LockStep => vec![
                task("systick", 3, firmware::timing::MONO_TICK_US as f64),
                task("control", CONTROL_PRIORITY, control),
                task("plan", PLAN_PRIORITY, plan),
            ],
            Self::Board => {
                let byte_us = f64::from(usart::BYTE_TIME_NS) / 1e3;
                vec![
                    task(
                        "systick",
                        usart::SYSTICK_PRIORITY,
                        firmware::timing::MONO_TICK_US as f64,
                    ),
                    Scheduled {
                        name: "link",
                        priority: usart::LINK_INTERRUPT_PRIORITY,
                        // Two entries a byte's time on silicon, and a few at once.
                        period_us: f64::from(usart::ENTRY_SPACING_NS) / 1e3,
                        deadline_us: byte_us,
                        burst: Some(Burst {
                            per_window: usart::ENTRIES_PER_BUDGET,
                            window_us: control,
                            extra_windows: usart::EXTRA_BUDGETS_PER_WINDOW,
                            // The control task renews the budget at its release.
                            renewer_priority: Some(CONTROL_PRIORITY),
                            at_once: usart::ENTRIES_AT_ONCE,
                            // The route frame's bytes and a plan event's, once
                            // a plan period.
                            slow: Some(Slow {
                                per_window: usart::ENTRIES_PER_PLAN_BUDGET,
                                window_us: plan,
                                extra_windows: usart::EXTRA_BUDGETS_PER_WINDOW,
                                // The plan task renews it at its start and makes
                                // the event its frames carry.
                                renewer_priority: Some(PLAN_PRIORITY),
                            }),
                        }),
                    },
                    task("control", CONTROL_PRIORITY, control),
                    task("plan", PLAN_PRIORITY, plan),
                ]
            }
        }
    }

    /// The tasks whose activations are not all alike: in both builds the control
    /// task's, with two kinds of extra work (`firmware/src/bin/ecu.rs`).
    ///
    /// * **A plan event in its frame**, at most once per plan activation (the
    ///   plan task leaves one for the control task's next frame, a newer one
    ///   replacing it): the other activations encode and authenticate an
    ///   actuation frame without it, at most `MAX_ACTUATION_FRAME_BYTES` through
    ///   the frame's flavor and `mac_input_bytes(MAX_ACTUATION_PAYLOAD_BYTES)`
    ///   through the MAC. A window holds the events of the plan activations
    ///   released in it, the one waiting at its start and one more, as the link's
    ///   plan budgets ([`usart::EXTRA_BUDGETS_PER_WINDOW`]); the plan task's own
    ///   response holds the one waiting and its own.
    /// * **The route frame's bytes it sorts**, in the flashed build
    ///   (`Port::sort_and_rearm`, at its release): it counts the bytes received
    ///   and renews its receive budget with interrupts off, then sorts exactly
    ///   those, so at most the sensor budget's
    ///   [`usart::SENSOR_RX_BUDGET_BYTES`] of them came from the control
    ///   period's budget (renewed with the last count; a renewal stores, never
    ///   adds), and the rest are the plan budget's
    ///   ([`usart::ROUTE_RX_BUDGET_BYTES`] a plan period, renewed by the plan
    ///   task at its start), never more than the queue holds: the light bound
    ///   sorts the sensor budget's bytes, each route byte is charged apart. (The
    ///   lock-step build reads its route channel in the plan task.)
    pub fn light_activations(self) -> Vec<LightActivations> {
        use firmware::link;
        let plan_period = firmware::tasks::PLAN_PERIOD_US as f64;
        let mut extras = vec![ExtraWork {
            what: "a plan event in its frame",
            unit: "event",
            constants: vec![
                ("MAX_UP_FRAME_BYTES", link::MAX_ACTUATION_FRAME_BYTES as u64),
                (
                    "MAX_UP_MAC_INPUT_BYTES",
                    link::mac_input_bytes(link::MAX_ACTUATION_PAYLOAD_BYTES) as u64,
                ),
            ],
            per_activation: 1,
            per_window: 1,
            window_us: plan_period,
            extra_windows: usart::EXTRA_BUDGETS_PER_WINDOW,
            producer_priority: Some(PLAN_PRIORITY),
        }];
        if self == Self::Board {
            extras.push(ExtraWork {
                what: "a route frame's bytes to sort",
                unit: "byte",
                constants: vec![("RX_BUDGET_BYTES", u64::from(usart::SENSOR_RX_BUDGET_BYTES))],
                per_activation: u64::from(usart::ROUTE_RX_BUDGET_BYTES),
                per_window: u64::from(usart::ROUTE_RX_BUDGET_BYTES),
                window_us: plan_period,
                extra_windows: usart::EXTRA_BUDGETS_PER_WINDOW,
                producer_priority: Some(PLAN_PRIORITY),
            });
        }
        vec![LightActivations {
            task: "control",
            extras,
        }]
    }

    /// Preemptions of one activation of `task` that meets its deadline: the
    /// activations of every higher priority within that deadline (each a chance
    /// for a retry loop to retry once). Faults are not counted: they end the
    /// activation.
    pub fn preemptions_of(self, task: &str) -> u64 {
        self.preemptions_within(task, None)
    }

    /// [`EcuBuild::preemptions_of`] within `window_us` of the activation's
    /// release instead of its deadline (a response-time bound), when given.
    pub fn preemptions_within(self, task: &str, window_us: Option<f64>) -> u64 {
        let schedule = self.schedule();
        let Some(me) = schedule.iter().find(|t| t.name == task) else {
            return 0;
        };
        let window = window_us.map_or(me.deadline_us, |w| w.min(me.deadline_us));
        schedule
            .iter()
            .filter(|t| t.priority > me.priority)
            .map(|t| super::rta::arrivals_in(t.period_us, t.burst, window, me.priority) as u64)
            .sum()
    }

    /// Preemptions of one activation of `task` that meets its deadline by the
    /// monotonic's tick (`systick`) alone.
    pub fn ticks_of(self, task: &str) -> u64 {
        self.ticks_within(task, None)
    }

    /// [`EcuBuild::ticks_of`] within `window_us` of the activation's release
    /// instead of its deadline, when given.
    pub fn ticks_within(self, task: &str, window_us: Option<f64>) -> u64 {
        let schedule = self.schedule();
        let (Some(me), Some(tick)) = (
            schedule.iter().find(|t| t.name == task),
            schedule.iter().find(|t| t.name == "systick"),
        ) else {
            return 0;
        };
        let window = window_us.map_or(me.deadline_us, |w| w.min(me.deadline_us));
        if tick.priority > me.priority {
            super::rta::arrivals_in(tick.period_us, tick.burst, window, me.priority) as u64
        } else {
            0
        }
    }

    /// The priority levels, for [`super::stack::analyse_elf`]: thread mode runs
    /// `main` (init and idle); the priority-1 (`plan`) and priority-2 (`control`)
    /// async tasks run in their dispatchers (RTIC v2 gives the dispatchers listed
    /// in `dispatchers = [..]` to the priorities in increasing order: in the
    /// lock-step disassembly `USART1` calls `Mpc::step_observed`, `USART2`
    /// `Link::receive`); `SysTick`, the monotonic's interrupt, above them; the
    /// flashed build's link interrupt above all.
    pub fn priority_levels(self) -> Vec<PriorityLevel> {
        let level = PriorityLevel::new;
        match self {
            Self::LockStep => vec![
                level("thread (main: init, idle)", &["main"]),
                level("priority 1 (plan, dispatcher USART1)", &["USART1"]),
                level("priority 2 (control, dispatcher USART2)", &["USART2"]),
                level("SysTick (monotonic)", &["SysTick"]),
            ],
            Self::Board => vec![
                level("thread (main: init, idle)", &["main"]),
                level("priority 1 (plan, dispatcher SPI1)", &["SPI1"]),
                level("priority 2 (control, dispatcher SPI2)", &["SPI2"]),
                level("SysTick (monotonic, priority 3)", &["SysTick"]),
                level("priority 4 (link, USART1 interrupt)", &["USART1"]),
            ],
        }
    }

    /// The functions that run only with interrupts disabled: the clock set-up,
    /// the link's opening and the set-up, called from RTIC's `init` before
    /// interrupts are enabled (their frames are gone when the tasks first run).
    pub fn masked(self) -> Vec<String> {
        let open = match self {
            Self::LockStep => "ecu::app::open_link",
            Self::Board => "ecu::app::open_usart_link",
        };
        vec![
            "ecu::app::configure_clock".to_string(),
            "ecu::app::set_up".to_string(),
            open.to_string(),
        ]
    }
}

/// The tasks' own work, bounded apart (the ECU app keeps them out of line):
/// section name, symbol, the task it runs in, its budget in cycles (what the ECU's
/// deadline monitor holds it to; `None`: no budget of its own).
pub const ECU_SECTIONS: [(&str, &str, &str, Option<u64>); 5] = [
    (
        "control_job",
        // Its symbol's fixed name (`#[export_name]`: placed first in `.text`).
        "ecu_control_job",
        "control",
        Some(firmware::deadline::CONTROL_BUDGET_CYCLES),
    ),
    (
        "plan_job",
        "ecu::plan_job",
        "plan",
        Some(firmware::deadline::PLAN_BUDGET_CYCLES),
    ),
    // An activation that adopts a window of the road instead of planning.
    (
        "window_job",
        "ecu::window_job",
        "plan",
        Some(firmware::deadline::PLAN_BUDGET_CYCLES),
    ),
    // The plan swap inside the `plan` lock: what blocks the control task.
    ("publish_plan", "ecu::publish_plan", "plan", None),
    // A frame of the road received before the plan or the adoption: part of the
    // activation's budget with either (the report adds it to both jobs).
    ("route_job", "ecu::route_job", "plan", None),
];

/// The ECU's functions counted once in the stack bound: the safe stop's work,
/// entered with interrupts disabled (the panic handler and HardFault disable them
/// in a frame of a few bytes, then call `ecu::safe_stop`; the NMI handler calls it
/// at priority −2, where nothing preempts it), which never returns, and
/// only past `safe_stop`'s static guard (`STOPPING`): a second entry, a fault on
/// the work, exits in the guard's few bytes, so the work's frame is on the stack
/// at most once. Exact name: `ecu::safe_stop` itself, the guard, is counted
/// wherever it is called.
pub fn ecu_once() -> Vec<String> {
    vec!["ecu::safe_stop_work".to_string()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flashed_build_puts_its_link_between_the_tasks_and_the_tick() {
        let board = EcuBuild::Board.schedule();
        let prio = |s: &[Scheduled], n: &str| s.iter().find(|t| t.name == n).map(|t| t.priority);
        assert!(prio(&board, "systick") > prio(&board, "control"));
        assert!(prio(&board, "link") > prio(&board, "systick"));
        assert_eq!(prio(&EcuBuild::LockStep.schedule(), "link"), None);
        // Every task of the schedule has a handler to bound, and back.
        for build in [EcuBuild::LockStep, EcuBuild::Board] {
            let names: Vec<&str> = build.tasks().iter().map(|t| t.0).collect();
            let scheduled: Vec<&str> = build.schedule().iter().map(|t| t.name).collect();
            assert_eq!(names.len(), scheduled.len());
            assert!(scheduled.iter().all(|n| names.contains(n)), "{build:?}");
        }
    }

    #[test]
    fn the_link_preempts_the_control_task_by_its_budgets_not_without_end() {
        let lock = EcuBuild::LockStep;
        let board = EcuBuild::Board;
        // The monotonic ticks once a control period. Lock-step: 1 tick within
        // control's 10 ms, 10 control activations and 10 ticks within plan's
        // 100 ms.
        assert_eq!(firmware::timing::MONO_TICK_US, 10_000);
        assert_eq!(lock.preemptions_of("control"), 1);
        assert_eq!(lock.preemptions_of("plan"), 20);
        assert_eq!(lock.ticks_of("plan"), 10);
        // Flashed: within one control activation two control budgets (the one in
        // force, its own renewal) and three plan budgets (one a plan period, the
        // one in force, one early by the plan task's jitter) would allow more
        // than the line's spacing does (1,844 entries in 10 ms and 11 at once);
        // within a plan period twelve control budgets (one a control period, the
        // one in force, a renewal early by the control task's jitter) and two
        // plan budgets (the one in force and the plan task's own renewal: the
        // next comes after it completes); within SysTick's 10 ms the line's
        // spacing binds too.
        let per = usart::ENTRIES_PER_BUDGET;
        let per_plan = usart::ENTRIES_PER_PLAN_BUDGET;
        assert!(2 * per + 3 * per_plan > 1_844 + usart::ENTRIES_AT_ONCE);
        assert_eq!(
            board.preemptions_of("control"),
            1 + 1_844 + usart::ENTRIES_AT_ONCE
        );
        assert_eq!(board.preemptions_of("plan"), 20 + 12 * per + 2 * per_plan);
        assert_eq!(
            board.preemptions_of("systick"),
            1_844 + usart::ENTRIES_AT_ONCE
        );
        assert_eq!(board.ticks_of("plan"), 10);
        assert_eq!(board.ticks_of("systick"), 0);
        // Within a response-time bound shorter than the deadline, fewer: 5 ms of
        // control hold 1 tick and the line's spacing of 5 ms; a window past the
        // deadline counts the deadline's.
        assert_eq!(board.ticks_within("control", Some(5_000.0)), 1);
        assert_eq!(
            board.preemptions_within("control", Some(5_000.0)),
            1 + 922 + usart::ENTRIES_AT_ONCE
        );
        assert_eq!(
            board.preemptions_within("plan", Some(150_000.0)),
            board.preemptions_of("plan")
        );
        assert_eq!(lock.preemptions_within("plan", None), 20);
    }
}
