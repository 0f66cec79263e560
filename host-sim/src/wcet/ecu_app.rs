//! What the analyses know of the ECU's RTIC application (`firmware/src/bin/ecu.rs`)
//! in its two builds ([`EcuBuild`]): its tasks and the interrupts they run in, the sections bounded apart (the jobs,
//! the plan swap) with their budgets, the schedule, and for the stack bound its
//! priority levels and the functions that run once or with interrupts masked. The
//! numbers come from the firmware's own constants. The targets of its indirect
//! calls are read from the binary ([`super::indirect`]). [`EcuBuild::target`]
//! puts it together as the analyser's target description ([`Target`]).

use super::memory_model::MemoryModel;
use super::rta::{Burst, Slow};
use super::stack::PriorityLevel;
use ::wcet::flash_data::FlashData;
use ::wcet::target::{ClockReport, Target};
pub use ::wcet::target::{ExtraWork, LightActivations, Scheduled};
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

impl EcuBuild {
    /// The build an ELF holds: [`EcuBuild::Board`] when it has the USART link's
    /// functions (`ecu::usart_link::…`), else [`EcuBuild::LockStep`].
    pub fn of_elf(elf: &Path) -> Result<Self, ::wcet::WcetError> {
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

/// The STM32F405 at 168 MHz: the wait states the ECU's clock set-up writes
/// (`firmware::clock_tree::FLASH_LATENCY_WS`, 5), 16-byte lines, flash at
/// 0x0800_0000.
pub const STM32F405: MemoryModel = MemoryModel {
    flash_wait_states: firmware::clock_tree::FLASH_LATENCY_WS,
    flash_line_bytes: 16,
    flash: (0x0800_0000, 0x0810_0000),
    flash_data: FlashData::Anywhere(Vec::new()),
    accelerator_setup: "the ECU's clock set-up, firmware::clock_tree::configure,",
};

impl EcuBuild {
    /// The target description of this build: its tasks, schedule, sections,
    /// stack levels, the STM32F405's memory model, the firmware's constants and
    /// the dependencies' loop bounds, with `clock` as the binary sets it.
    pub fn target(self, clock: ClockReport) -> Target {
        Target {
            id: self.id(),
            name: self.name(),
            tasks: self.tasks().to_vec(),
            interrupts: self.interrupts().to_vec(),
            tick: "systick",
            schedule: self.schedule(),
            light_activations: self.light_activations(),
            sections: ECU_SECTIONS.to_vec(),
            priority_levels: self.priority_levels(),
            masked: self.masked(),
            once: ecu_once(),
            clock_hz: super::CLOCK_HZ,
            clock,
            memory: STM32F405,
            constants: super::ecu_sources::firmware_constants(),
            dependency_facts: super::ecu_sources::dependency_facts_with,
            source_labels: super::ecu_sources::FIRMWARE_CRATE_SOURCES.to_vec(),
        }
    }

    /// [`EcuBuild::target`] with the clock as `elf` sets it.
    pub fn target_of_elf(self, elf: &Path) -> anyhow::Result<Target> {
        Ok(self.target(super::clock::of_elf(elf)?))
    }

    /// Its identifier in `static.json` (`build`).
    pub fn id(self) -> &'static str {
        match self {
            Self::LockStep => "lock-step",
            Self::Board => "board",
        }
    }

    /// The build a `static.json`'s `build` names ([`EcuBuild::id`]).
    pub fn of_id(id: &str) -> Option<Self> {
        [Self::LockStep, Self::Board]
            .into_iter()
            .find(|b| b.id() == id)
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

    fn target(build: EcuBuild) -> Target {
        build.target(super::super::clock::of_firmware(None))
    }

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
        let lock = target(EcuBuild::LockStep);
        let board = target(EcuBuild::Board);
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

    fn task_static(
        name: &str,
        deadline: Option<f64>,
        bound: Option<f64>,
        past: Option<f64>,
    ) -> ::wcet::analysis::TaskStatic {
        ::wcet::analysis::TaskStatic {
            name: name.into(),
            response_time_bound_us: bound,
            response_time_past_deadline_us: past,
            deadline_us: deadline,
            ..Default::default()
        }
    }

    #[test]
    fn the_interrupts_are_the_schedules_hardware_entries_with_their_bounds() {
        let mut link = task_static("link", Some(10.85), Some(4.2), None);
        link.static_bound_cycles = Some(277);
        let tasks = [
            task_static("control", Some(10_000.0), Some(7_437.0), None),
            link,
            task_static("systick", Some(1_000.0), None, Some(2_000.0)),
        ];
        let board = ::wcet::analysis::interrupts_of(&target(EcuBuild::Board), &tasks);
        let names: Vec<&str> = board.iter().map(|i| i.name.as_str()).collect();
        assert_eq!(names, ["systick", "link"]);
        let l = &board[1];
        assert_eq!(l.handler, "USART1");
        assert_eq!(l.static_bound_cycles, Some(277));
        assert_eq!(l.response_time_bound_us, Some(4.2));
        // Two entries a byte's time; the receive budget per control period.
        let byte_us = f64::from(firmware::link::usart::BYTE_TIME_NS) / 1e3;
        assert!(
            (l.min_interarrival_us - byte_us / 2.0).abs() < 1e-3,
            "{l:?}"
        );
        assert_eq!(
            l.per_window,
            Some(firmware::link::usart::ENTRIES_PER_BUDGET)
        );
        assert_eq!(l.window_us, Some(10_000.0));
        assert_eq!(
            l.per_slow_window,
            Some(firmware::link::usart::ENTRIES_PER_PLAN_BUDGET)
        );
        assert_eq!(l.slow_window_us, Some(100_000.0));
        // SysTick missed its deadline here: no bound, not a made-up one.
        assert_eq!(board[0].handler, "SysTick");
        assert_eq!(board[0].response_time_bound_us, None);
        assert_eq!(
            board[0].min_interarrival_us,
            firmware::timing::MONO_TICK_US as f64
        );
        // The lock-step build has no link interrupt.
        let lock = ::wcet::analysis::interrupts_of(&target(EcuBuild::LockStep), &tasks);
        assert_eq!(lock.len(), 1);
        assert_eq!(lock[0].name, "systick");
    }
}
