//! The target description the analyses take: what a timing analysis must know of
//! the program besides its ELF. The tasks and the interrupts they run in, the
//! sections bounded apart, the schedule with its priorities, the stack's priority
//! levels, the core clock, the memory model and its wait states, and the
//! constants the flow facts' annotations may name. The crate reads no program's
//! own sources for these: the caller builds the description (for the ECU,
//! `host-sim`'s `wcet::ecu_app`).

use crate::annotations::Annotation;
use crate::memory_model::MemoryModel;
use crate::rta::{Burst, Extra};
use crate::stack::PriorityLevel;
use serde::Serialize;
use std::collections::BTreeMap;

/// One activity of the schedule: a task or an interrupt.
#[derive(Debug, Clone, PartialEq)]
pub struct Scheduled {
    /// Name (a task of [`Target::tasks`]).
    pub name: &'static str,
    /// Logical priority (higher preempts).
    pub priority: u8,
    /// Period, or minimum inter-arrival time, µs.
    pub period_us: f64,
    /// Relative deadline, µs.
    pub deadline_us: f64,
    /// A cap on its activations in a window besides the period (an interrupt the
    /// application rate-limits).
    pub burst: Option<Burst>,
}

/// A task whose activations are not all alike: most are *light*, bounded from
/// the same root with some of the target's constants bound tighter (the
/// annotations that name them evaluated again); the rest carry [`ExtraWork`] of
/// one kind or more, each charged by its units ([`crate::rta::Heavy`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LightActivations {
    /// The task.
    pub task: &'static str,
    /// The kinds of extra work a light activation leaves out.
    pub extras: Vec<ExtraWork>,
}

/// One kind of extra work of [`LightActivations`]: the constants that bound it
/// run from their light values (no unit) to the target's own
/// (`per_activation` units), a unit's cost is what one unit adds to the bound at
/// most, and the units come at most `per_window` per window of `window_us`
/// (`extra_windows` more in any window; [`crate::rta::Extra`]).
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
        full: &BTreeMap<&'static str, u64>,
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
    pub fn charge(&self, unit_cycles: f64) -> Extra {
        Extra {
            unit_cycles,
            per_activation: self.per_activation,
            per_window: self.per_window,
            window_us: self.window_us,
            extra_windows: self.extra_windows,
            producer_priority: self.producer_priority,
        }
    }
}

/// A section of a task bounded apart: its name, its symbol, the task it runs in,
/// its budget in cycles (`None`: no budget of its own).
pub type Section = (&'static str, &'static str, &'static str, Option<u64>);

/// The core clock and where the binary sets it (`clock` in `static.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClockReport {
    /// SYSCLK = HCLK, the core's clock, in Hz.
    pub sysclk_hz: u64,
    /// What drives it on silicon, e.g. `HSE 25 MHz → PLL (M 25, N 336, P 2, Q 7)`.
    pub source: String,
    /// The function that sets it, when the ELF defines it; `null` when the ELF
    /// has no such function.
    pub configured_in: Option<String>,
    /// What that function does on the emulator the traces come from.
    pub in_qemu: String,
}

/// The loop bounds of code whose sources are not the target's to annotate (its
/// dependencies'), with the target's constants bound as given.
pub type DependencyFacts = fn(&BTreeMap<&'static str, u64>) -> Vec<Annotation>;

/// Everything the analysis knows of a target besides its ELF.
#[derive(Debug, Clone)]
pub struct Target {
    /// Its identifier in `static.json` (`build`).
    pub id: &'static str,
    /// Its name in the reports.
    pub name: &'static str,
    /// The tasks and interrupts whose activations the analysis bounds: name and
    /// handler symbol (the roots).
    pub tasks: Vec<(&'static str, &'static str)>,
    /// The activities of the schedule that are interrupts the hardware raises,
    /// not software tasks.
    pub interrupts: Vec<&'static str>,
    /// The activity of the schedule that is the periodic timer tick (its
    /// preemptions are counted apart, [`Target::ticks_of`]).
    pub tick: &'static str,
    /// The schedule: every task and interrupt with its priority, period and
    /// deadline.
    pub schedule: Vec<Scheduled>,
    /// The tasks whose activations are not all alike.
    pub light_activations: Vec<LightActivations>,
    /// The sections bounded apart.
    pub sections: Vec<Section>,
    /// The priority levels of the stack bound.
    pub priority_levels: Vec<PriorityLevel>,
    /// The functions that run only with interrupts disabled.
    pub masked: Vec<String>,
    /// The functions counted once in the stack bound.
    pub once: Vec<String>,
    /// The core clock, Hz: what converts cycles to time.
    pub clock_hz: u32,
    /// The core clock as the binary sets it, for the report.
    pub clock: ClockReport,
    /// The processor and memory model (wait states, flash lines, the flash's
    /// addresses); the flash data the binary reads is classified from its ELF.
    pub memory: MemoryModel,
    /// The constants an annotation may name, with their values.
    pub constants: BTreeMap<&'static str, u64>,
    /// The loop bounds of the dependencies' code.
    pub dependency_facts: DependencyFacts,
    /// The source folders (from the workspace root) whose files are the target's
    /// own: a source location is reported in the innermost of their frames, and
    /// a loop in none of them is a library's.
    pub source_labels: Vec<&'static str>,
}

impl Target {
    /// Its name in the reports.
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// The tasks: name and handler symbol.
    pub fn tasks(&self) -> &[(&'static str, &'static str)] {
        &self.tasks
    }

    /// The activities of the schedule that are hardware interrupts.
    pub fn interrupts(&self) -> &[&'static str] {
        &self.interrupts
    }

    /// The schedule.
    pub fn schedule(&self) -> Vec<Scheduled> {
        self.schedule.clone()
    }

    /// The tasks whose activations are not all alike.
    pub fn light_activations(&self) -> Vec<LightActivations> {
        self.light_activations.clone()
    }

    /// The sections bounded apart.
    pub fn sections(&self) -> &[Section] {
        &self.sections
    }

    /// Preemptions of one activation of `task` that meets its deadline: the
    /// activations of every higher priority within that deadline (each a chance
    /// for a retry loop to retry once). Faults are not counted: they end the
    /// activation.
    pub fn preemptions_of(&self, task: &str) -> u64 {
        self.preemptions_within(task, None)
    }

    /// [`Target::preemptions_of`] within `window_us` of the activation's
    /// release instead of its deadline (a response-time bound), when given.
    pub fn preemptions_within(&self, task: &str, window_us: Option<f64>) -> u64 {
        let schedule = &self.schedule;
        let Some(me) = schedule.iter().find(|t| t.name == task) else {
            return 0;
        };
        let window = window_us.map_or(me.deadline_us, |w| w.min(me.deadline_us));
        schedule
            .iter()
            .filter(|t| t.priority > me.priority)
            .map(|t| crate::rta::arrivals_in(t.period_us, t.burst, window, me.priority) as u64)
            .sum()
    }

    /// Preemptions of one activation of `task` that meets its deadline by the
    /// timer tick ([`Target::tick`]) alone.
    pub fn ticks_of(&self, task: &str) -> u64 {
        self.ticks_within(task, None)
    }

    /// [`Target::ticks_of`] within `window_us` of the activation's release
    /// instead of its deadline, when given.
    pub fn ticks_within(&self, task: &str, window_us: Option<f64>) -> u64 {
        let schedule = &self.schedule;
        let (Some(me), Some(tick)) = (
            schedule.iter().find(|t| t.name == task),
            schedule.iter().find(|t| t.name == self.tick),
        ) else {
            return 0;
        };
        let window = window_us.map_or(me.deadline_us, |w| w.min(me.deadline_us));
        if tick.priority > me.priority {
            crate::rta::arrivals_in(tick.period_us, tick.burst, window, me.priority) as u64
        } else {
            0
        }
    }
}
