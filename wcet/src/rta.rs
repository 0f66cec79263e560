//! Response-time analysis of fixed-priority preemptive tasks under RTIC's stack
//! resource policy (Audsley et al., "Applying new scheduling theory to static
//! priority pre-emptive scheduling", 1993; Baker's SRP for the blocking term).
//!
//! For each task `i`, `R = C_i + B_i + Σ_{j ∈ hp(i)} ⌈R / T_j⌉ · C_j` to a fixed
//! point, where `C` is the static worst-case execution time, `B_i` the longest
//! critical section of a lower-priority task that masks priority `i`: a lock on a
//! resource whose ceiling is `≥ i`, or a section with interrupts disabled, which
//! masks every priority (under SRP a task is blocked at most once, before it
//! starts),
//! and `hp(i)` the tasks and interrupts of higher priority, each with its minimum
//! inter-arrival time `T`. Every preemption also costs an exception entry and
//! exit ([`ENTRY_EXIT_CYCLES`]) and the refill of the cache lines the preempting
//! activation can evict ([`Activity::refill_cycles`]), charged to it.
//! The iteration stops at the fixed point or as soon as `R` exceeds the deadline.
//!
//! A task whose activations are not all alike ([`Heavy`]: most are light, a few
//! per window carry more work) interferes as a generalized multiframe task (Baruah
//! et al., "Generalized multiframe tasks", Real-Time Systems 17, 1999): each of its
//! arrivals at the light bound, and each kind of extra work ([`Extra`]) at its
//! cost per unit as often as its units can come,
//! `⌈R / T_j⌉ · C_light + Σ_k n_k(R) · c_k` (never more than every arrival at
//! `C_j`). Its own response time is bounded with `C_j`, the heaviest.

#[cfg(test)]
use super::cache::PREEMPTION_REFILL_CYCLES;
use serde::Serialize;

/// What one preemption costs besides the cache refill, cycles: exception entry
/// and exit on a Cortex-M4F with lazy FPU stacking, 12 each with zero-wait-state
/// stacking (TRM §3.3; the frame is in SRAM), the vector read from flash with its
/// 5 wait states at 168 MHz (the vector table is in flash; the ART's data cache
/// assumed to miss), on return the preempted code's flash line fetched again
/// (5 wait states and the access).
pub const ENTRY_EXIT_CYCLES: f64 = 12.0 + 5.0 + 12.0 + 6.0;

/// A task or interrupt of the schedule.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Activity {
    /// Name in the report.
    pub name: String,
    /// Priority (higher preempts lower; interrupts above the tasks).
    pub priority: u8,
    /// Period or minimum inter-arrival time, µs.
    pub period_us: f64,
    /// Relative deadline, µs.
    pub deadline_us: f64,
    /// Worst-case execution time, cycles (preemption overhead not included).
    pub wcet_cycles: f64,
    /// The cache refill one of its preemptions causes the preempted task, cycles:
    /// the lines it can evict (`wcet::cache::evicting_lines`) at a line fetch
    /// each, at most the whole cache.
    pub refill_cycles: f64,
    /// A cap on its activations besides the minimum inter-arrival `period_us`
    /// (an interrupt the application rate-limits: a link's bytes, at most so many
    /// a control period); `None`: the period alone.
    pub burst: Option<Burst>,
    /// Its critical sections: `(ceiling, cycles)`, the highest priority each masks
    /// (a lock's resource ceiling, to which RTIC raises the running priority;
    /// `u8::MAX` with interrupts disabled) and its bound. Each blocks the
    /// activities of higher priority up to its ceiling.
    pub critical_sections: Vec<(u8, f64)>,
    /// When its activations are not all alike: the bound of its light ones and
    /// how often a heavier one (up to `wcet_cycles`) can come; `None`: every
    /// activation is charged `wcet_cycles`.
    pub heavy: Option<Heavy>,
}

/// An activity whose activations are not all alike: each costs at most its light
/// bound and the [`Extra`] work it carries, which comes in units (a plan event, a
/// byte of a route frame) at most so many per activation and per window of a
/// producer's period.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Heavy {
    /// The bound of an activation without any extra work, cycles (≤ the
    /// activity's `wcet_cycles`).
    pub light_cycles: f64,
    /// The kinds of extra work.
    pub extras: Vec<Extra>,
}

/// One kind of extra work of a [`Heavy`] activity: at most `per_activation`
/// units in an activation and `per_window · (⌈r / window_us⌉ + extra_windows)`
/// in any window of `r` µs (one window less in a window of the producer's own
/// response), each at most `unit_cycles` more than the light bound.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Extra {
    /// Cycles a unit adds to an activation at most.
    pub unit_cycles: f64,
    /// Units in one activation at most.
    pub per_activation: u64,
    /// Units per window at most.
    pub per_window: u64,
    /// The window, µs (the producer's period).
    pub window_us: f64,
    /// Windows a window of any length can draw on besides one per `window_us`
    /// it spans (the work waiting at its start; one more if the producer
    /// finishes up to its response time after its release).
    pub extra_windows: u64,
    /// The priority of the task that makes the extra work, if one does: a window
    /// of its own response draws on one window less (its next activation's work
    /// comes after it completes).
    pub producer_priority: Option<u8>,
}

impl Extra {
    /// The units among `arrivals` activations in a window of `r` µs of the
    /// response of an activity of priority `victim`.
    pub fn count(&self, arrivals: f64, r: f64, victim: u8) -> f64 {
        let extra = if self.producer_priority == Some(victim) {
            self.extra_windows.saturating_sub(1)
        } else {
            self.extra_windows
        };
        let windows = if self.window_us > 0.0 {
            (r / self.window_us).ceil() + extra as f64
        } else {
            f64::INFINITY
        };
        (arrivals * self.per_activation as f64).min(self.per_window as f64 * windows)
    }
}

/// The response-time bound of one activity.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Response {
    /// Name.
    pub name: String,
    /// Response-time bound, µs; `None` when the iteration passed the deadline.
    pub response_time_bound_us: Option<f64>,
    /// The deadline, µs.
    pub deadline_us: f64,
    /// Blocking term, µs.
    pub blocking_us: f64,
    /// Whether the bound is within the deadline.
    pub meets_deadline: bool,
    /// When the iteration passed the deadline: its fixed point if there is one
    /// within [`PAST_DEADLINE_FACTOR`] deadlines (how far the bound misses), µs.
    pub past_deadline_us: Option<f64>,
    /// The work that falls within a window as long as the deadline, what the
    /// bound is compared with: the activity's own (its bound, preemption
    /// overhead and blocking), then each higher priority's.
    pub demand_at_deadline: Vec<Demand>,
}

/// Work within a window of a response-time analysis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Demand {
    /// The activity it is of.
    pub name: String,
    /// Its activations in the window.
    pub arrivals: f64,
    /// Their cycles, preemption overhead included.
    pub cycles: f64,
}

/// How far past its deadline the iteration goes on to find a missed bound's
/// fixed point, deadlines.
pub const PAST_DEADLINE_FACTOR: f64 = 10.0;

/// A rate limit: at most `per_window · (⌈r / window_us⌉ + extra_windows)`
/// activations in any window of `r` µs, plus as many again by the [`Slow`]
/// budget if there is one, and at most `⌈r / T⌉ + at_once` by the activity's
/// period `T`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Burst {
    /// Activations per budget window at most.
    pub per_window: u64,
    /// The budget window, µs.
    pub window_us: f64,
    /// Budgets a window can draw on besides one per `window_us` it spans (the one
    /// in force at its start; one more if budgets are renewed with jitter).
    pub extra_windows: u64,
    /// The priority of the task that renews the budget at its start, if one
    /// does: a window of its own activation draws on one budget less (the next
    /// renewal comes after it completes).
    pub renewer_priority: Option<u8>,
    /// Activations that may come together besides those the period spaces.
    pub at_once: u64,
    /// A second budget, renewed at a longer period, whose activations add to
    /// the first's (a link's bytes that come once a plan period); `None`: the
    /// first alone.
    pub slow: Option<Slow>,
}

/// The second budget of a [`Burst`]: at most `per_window · (⌈r / window_us⌉ +
/// extra_windows)` activations more in any window of `r` µs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Slow {
    /// Activations per budget window at most.
    pub per_window: u64,
    /// The budget window, µs.
    pub window_us: f64,
    /// Budgets a window can draw on besides one per `window_us` it spans.
    pub extra_windows: u64,
    /// The priority of the task that renews this budget at its start, if one
    /// does: a window of its own activation draws on one budget less.
    pub renewer_priority: Option<u8>,
}

/// The most activations, in a window of `r` µs of the response of an activity
/// of priority `victim`, of an activity released no closer than `period_us`
/// (`0`: no such limit) and capped by `burst`: `⌈r / T⌉`, and with a cap at most
/// [`Burst`]'s counts.
pub fn arrivals_in(period_us: f64, burst: Option<Burst>, r: f64, victim: u8) -> f64 {
    let by_period = if period_us > 0.0 {
        (r / period_us).ceil() + burst.map_or(0.0, |b| b.at_once as f64)
    } else {
        f64::INFINITY
    };
    match burst {
        Some(b) if b.window_us > 0.0 => {
            let extra = if b.renewer_priority == Some(victim) {
                b.extra_windows.saturating_sub(1)
            } else {
                b.extra_windows
            };
            let slow = b.slow.filter(|s| s.window_us > 0.0).map_or(0.0, |s| {
                let extra = if s.renewer_priority == Some(victim) {
                    s.extra_windows.saturating_sub(1)
                } else {
                    s.extra_windows
                };
                s.per_window as f64 * ((r / s.window_us).ceil() + extra as f64)
            });
            by_period.min(b.per_window as f64 * ((r / b.window_us).ceil() + extra as f64) + slow)
        }
        _ => by_period,
    }
}

/// The most activations of `h` in a window of `r` µs of `victim`'s response
/// ([`arrivals_in`]).
fn arrivals(h: &Activity, r: f64, victim: &Activity) -> f64 {
    arrivals_in(h.period_us, h.burst, r, victim.priority)
}

/// The cycles `h`'s activations take from a window of `r` µs of `victim`'s
/// response: each arrival its bound and its preemption's overhead, or with
/// [`Heavy`] activations the light bound for each and each extra work's units as
/// often as they can come.
fn interference_cycles(h: &Activity, r: f64, victim: &Activity) -> f64 {
    let n = arrivals(h, r, victim);
    let overhead = ENTRY_EXIT_CYCLES + h.refill_cycles;
    match &h.heavy {
        Some(heavy) => {
            let light = heavy.light_cycles.min(h.wcet_cycles);
            let extra: f64 = heavy
                .extras
                .iter()
                .map(|e| e.count(n, r, victim.priority) * e.unit_cycles)
                .sum();
            // Never more than every arrival at the heaviest.
            (n * (light + overhead) + extra).min(n * (h.wcet_cycles + overhead))
        }
        None => n * (h.wcet_cycles + overhead),
    }
}

/// Response-time bounds of every activity on a core clocked at `clock_hz`.
pub fn response_times(activities: &[Activity], clock_hz: f64) -> Vec<Response> {
    let us = |cycles: f64| cycles / clock_hz * 1e6;
    activities
        .iter()
        .map(|a| {
            let blocking = activities
                .iter()
                .filter(|l| l.priority < a.priority)
                .flat_map(|l| l.critical_sections.iter())
                .filter(|&&(ceiling, _)| ceiling >= a.priority)
                .map(|&(_, cycles)| cycles)
                .fold(0.0, f64::max);
            let higher: Vec<&Activity> = activities
                .iter()
                .filter(|h| h.priority > a.priority)
                .collect();
            let own = a.wcet_cycles + ENTRY_EXIT_CYCLES + a.refill_cycles + blocking;
            let mut r = us(own);
            let mut result = None;
            let mut past = None;
            // Each step adds at least one activity's cost or stops: bounded by the
            // deadline over the smallest cost.
            for _ in 0..1_000_000 {
                let next = us(own)
                    + higher
                        .iter()
                        .map(|h| us(interference_cycles(h, r, a)))
                        .sum::<f64>();
                if next > PAST_DEADLINE_FACTOR * a.deadline_us {
                    break;
                }
                if next <= r {
                    if next <= a.deadline_us {
                        result = Some(next);
                    } else {
                        past = Some(next);
                    }
                    break;
                }
                r = next;
            }
            let demand_at_deadline = std::iter::once(Demand {
                name: a.name.clone(),
                arrivals: 1.0,
                cycles: own,
            })
            .chain(higher.iter().map(|h| Demand {
                name: h.name.clone(),
                arrivals: arrivals(h, a.deadline_us, a),
                cycles: interference_cycles(h, a.deadline_us, a),
            }))
            .collect();
            Response {
                name: a.name.clone(),
                response_time_bound_us: result,
                deadline_us: a.deadline_us,
                blocking_us: us(blocking),
                meets_deadline: result.is_some_and(|r| r <= a.deadline_us),
                past_deadline_us: past,
                demand_at_deadline,
            }
        })
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn schedule(control_cs: f64) -> Vec<Activity> {
        schedule_with(vec![(2, control_cs)])
    }

    fn schedule_with(plan_sections: Vec<(u8, f64)>) -> Vec<Activity> {
        vec![
            Activity {
                name: "systick".into(),
                priority: 3,
                period_us: 1_000.0,
                deadline_us: 1_000.0,
                wcet_cycles: 500.0,
                refill_cycles: PREEMPTION_REFILL_CYCLES,
                burst: None,
                critical_sections: Vec::new(),
                heavy: None,
            },
            Activity {
                name: "control".into(),
                priority: 2,
                period_us: 10_000.0,
                deadline_us: 10_000.0,
                wcet_cycles: 5_000.0,
                refill_cycles: PREEMPTION_REFILL_CYCLES,
                burst: None,
                critical_sections: Vec::new(),
                heavy: None,
            },
            Activity {
                name: "plan".into(),
                priority: 1,
                period_us: 100_000.0,
                deadline_us: 100_000.0,
                wcet_cycles: 10.0e6,
                refill_cycles: PREEMPTION_REFILL_CYCLES,
                burst: None,
                critical_sections: plan_sections,
                heavy: None,
            },
        ]
    }

    #[test]
    fn the_fixed_point_by_hand() {
        let r = response_times(&schedule(1_000.0), 168e6);
        // Entry and exit with the vector read from flash, the preempted line
        // fetched again and both caches refilled: 12 + 5 + 12 + 6 + (64 + 8) × 6
        // cycles.
        assert_eq!(ENTRY_EXIT_CYCLES + PREEMPTION_REFILL_CYCLES, 467.0);
        // control: C + overhead + B = 5467 + 1000 cycles, one SysTick (967).
        let control = r[1].response_time_bound_us.unwrap();
        assert!(
            (control - (5_467.0 + 1_000.0 + 967.0) / 168.0).abs() < 1e-9,
            "{control}"
        );
        // plan: 10 M + 467, preempted by 10 control and ~60 SysTicks.
        let plan = r[2].response_time_bound_us.unwrap();
        assert!(plan > 10.0e6 / 168.0 && plan < 100_000.0);
        assert!(r.iter().all(|x| x.meets_deadline));
    }

    #[test]
    fn interrupts_disabled_block_every_higher_priority_a_lock_only_up_to_its_ceiling() {
        let us = |c: f64| c / 168.0;
        // A lock at ceiling 2 blocks control, not SysTick.
        let lock = response_times(&schedule_with(vec![(2, 3_000.0)]), 168e6);
        assert!((lock[1].blocking_us - us(3_000.0)).abs() < 1e-9);
        assert_eq!(lock[0].blocking_us, 0.0);
        // Interrupts disabled for 1,000 cycles block both; the longest section of a
        // lower priority is the one charged.
        let masked = response_times(
            &schedule_with(vec![(2, 3_000.0), (u8::MAX, 1_000.0)]),
            168e6,
        );
        assert!((masked[0].blocking_us - us(1_000.0)).abs() < 1e-9);
        assert!((masked[1].blocking_us - us(3_000.0)).abs() < 1e-9);
        let systick_before = lock[0].response_time_bound_us.unwrap();
        let systick_after = masked[0].response_time_bound_us.unwrap();
        assert!((systick_after - systick_before - us(1_000.0)).abs() < 1e-9);
    }

    #[test]
    fn a_rate_limited_interrupt_interferes_by_its_cap_not_its_inter_arrival() {
        // A byte interrupt: 400 cycles, a byte every 10.85 µs, at most 100 bytes
        // per 10 ms.
        let mut s = schedule(1_000.0);
        let byte = |burst| Activity {
            name: "link".into(),
            priority: 4,
            period_us: 10.85,
            deadline_us: 10.85,
            wcet_cycles: 400.0,
            refill_cycles: PREEMPTION_REFILL_CYCLES,
            burst,
            critical_sections: Vec::new(),
            heavy: None,
        };
        s.push(byte(None));
        let free = response_times(&s, 168e6);
        // Unlimited, it takes 400 + 419 of every 1,823 cycles, near half the core,
        // and the plan task, at 10 M cycles, misses its 100 ms.
        assert!(!free[2].meets_deadline);
        s.pop();
        s.push(byte(Some(Burst {
            per_window: 100,
            window_us: 10_000.0,
            extra_windows: 0,
            renewer_priority: None,
            at_once: 0,
            slow: None,
        })));
        let capped = response_times(&s, 168e6);
        assert!(capped.iter().all(|x| x.meets_deadline));
        // control's window (< 10 ms) holds at most 100 of them.
        let plain = response_times(&schedule(1_000.0), 168e6);
        let extra =
            capped[1].response_time_bound_us.unwrap() - plain[1].response_time_bound_us.unwrap();
        assert!(
            extra <= 100.0 * (400.0 + ENTRY_EXIT_CYCLES + PREEMPTION_REFILL_CYCLES) / 168.0 + 1e-9,
            "{extra}"
        );
        assert!(extra > 0.0);
    }

    #[test]
    fn a_budget_caps_the_arrivals_of_a_window_with_its_extra_budgets() {
        let b = Burst {
            per_window: 100,
            window_us: 10_000.0,
            extra_windows: 2,
            renewer_priority: Some(2),
            at_once: 4,
            slow: None,
        };
        // No period: the budget alone; 1 µs and 10 ms hold three budgets, 10.001 ms four.
        assert_eq!(arrivals_in(0.0, Some(b), 1.0, 1), 300.0);
        assert_eq!(arrivals_in(0.0, Some(b), 10_000.0, 1), 300.0);
        assert_eq!(arrivals_in(0.0, Some(b), 10_001.0, 1), 400.0);
        // The task that renews the budget sees one less.
        assert_eq!(arrivals_in(0.0, Some(b), 10_000.0, 2), 200.0);
        // A period caps short windows, with what may come at once.
        assert_eq!(arrivals_in(10.0, Some(b), 25.0, 1), 7.0);
        assert_eq!(arrivals_in(10.0, None, 25.0, 1), 3.0);
    }

    #[test]
    fn a_slow_budget_adds_its_own_windows_to_the_first_budgets() {
        let b = Burst {
            per_window: 100,
            window_us: 10_000.0,
            extra_windows: 2,
            renewer_priority: Some(2),
            at_once: 4,
            slow: Some(Slow {
                per_window: 50,
                window_us: 100_000.0,
                extra_windows: 2,
                renewer_priority: Some(1),
            }),
        };
        // 100 ms: 12 fast budgets (10 + 2) and 3 slow ones (1 + 2); the slow
        // budget's renewer (priority 1) sees one slow budget less.
        assert_eq!(arrivals_in(0.0, Some(b), 100_000.0, 3), 1_200.0 + 150.0);
        assert_eq!(arrivals_in(0.0, Some(b), 100_000.0, 1), 1_200.0 + 100.0);
        // 100.001 ms: one more of each.
        assert_eq!(arrivals_in(0.0, Some(b), 100_001.0, 3), 1_300.0 + 200.0);
        assert_eq!(arrivals_in(0.0, Some(b), 100_001.0, 1), 1_300.0 + 150.0);
        // The renewer of the fast budget sees one fast budget less, all slow ones.
        assert_eq!(arrivals_in(0.0, Some(b), 10_000.0, 2), 200.0 + 150.0);
        // Against one budget of the combined size a period, a plan period holds
        // 9 × 50 fewer.
        let one = Burst {
            per_window: 150,
            slow: None,
            ..b
        };
        assert_eq!(
            arrivals_in(0.0, Some(one), 100_000.0, 3) - arrivals_in(0.0, Some(b), 100_000.0, 3),
            9.0 * 50.0
        );
    }

    #[test]
    fn heavy_activations_are_charged_as_often_as_they_come_not_at_every_arrival() {
        let event = Extra {
            unit_cycles: 200_000.0,
            per_activation: 1,
            per_window: 1,
            window_us: 100_000.0,
            extra_windows: 2,
            producer_priority: Some(1),
        };
        let heavy = Heavy {
            light_cycles: 100_000.0,
            extras: vec![event],
        };
        // A window of 100 ms draws on 1 + 2 windows, its producer's own on one less;
        // never more than the arrivals.
        assert_eq!(event.count(10.0, 100_000.0, 3), 3.0);
        assert_eq!(event.count(10.0, 100_000.0, 1), 2.0);
        assert_eq!(event.count(1.0, 100_000.0, 3), 1.0);
        assert_eq!(event.count(11.0, 100_001.0, 1), 3.0);
        // Units that an activation can carry many of (bytes) are capped by the
        // arrivals times that many.
        let bytes = Extra {
            per_activation: 300,
            per_window: 281,
            ..event
        };
        assert_eq!(bytes.count(10.0, 100_000.0, 1), 2.0 * 281.0);
        assert_eq!(bytes.count(1.0, 100_000.0, 1), 300.0);
        // control: 300 k cycles at worst, 100 k without the plan task's event. plan
        // (10 M cycles) sees ten arrivals of control, two of them heavy (no SysTick
        // here: its arrivals would follow the bound).
        let mut s: Vec<Activity> = schedule(0.0).into_iter().skip(1).collect();
        s[0].wcet_cycles = 300_000.0;
        let worst = response_times(&s, 168e6);
        s[0].heavy = Some(heavy.clone());
        let multiframe = response_times(&s, 168e6);
        let (w, m) = (
            worst[1].response_time_bound_us.unwrap(),
            multiframe[1].response_time_bound_us.unwrap(),
        );
        // Each a fixed point: plan's own 10 M and its preemption's overhead, each
        // arrival of control at 300 k, or at 100 k and two of them 200 k more.
        let own = 10.0e6 + ENTRY_EXIT_CYCLES + PREEMPTION_REFILL_CYCLES;
        let overhead = ENTRY_EXIT_CYCLES + PREEMPTION_REFILL_CYCLES;
        let arrivals = |r: f64| (r / 10_000.0).ceil();
        let worst_demand = own + arrivals(w) * (300_000.0 + overhead);
        let light_demand = own + arrivals(m) * (100_000.0 + overhead) + 2.0 * 200_000.0;
        assert!(
            (w * 168.0 - worst_demand).abs() < 1e-3,
            "{w} {worst_demand}"
        );
        assert!(
            (m * 168.0 - light_demand).abs() < 1e-3,
            "{m} {light_demand}"
        );
        assert!(w - m > 6.0 * 200_000.0 / 168.0, "{w} {m}");
        // At the deadline: ten arrivals of control, two of them heavy.
        let at_deadline = &multiframe[1].demand_at_deadline;
        assert_eq!(at_deadline[0].cycles, own);
        assert_eq!(
            (at_deadline[1].name.as_str(), at_deadline[1].arrivals),
            ("control", 10.0)
        );
        assert!(
            (at_deadline[1].cycles - (10.0 * (100_000.0 + overhead) + 2.0 * 200_000.0)).abs()
                < 1e-6
        );
        // control's own bound is its heaviest activation's.
        assert_eq!(
            worst[0].response_time_bound_us,
            multiframe[0].response_time_bound_us
        );
        // A light bound above the worst one is the worst one, and so is extra
        // work that would charge an arrival more than the heaviest.
        s[0].heavy = Some(Heavy {
            light_cycles: 1.0e9,
            ..heavy.clone()
        });
        assert_eq!(
            response_times(&s, 168e6)[1].response_time_bound_us,
            worst[1].response_time_bound_us
        );
        s[0].heavy = Some(Heavy {
            light_cycles: 100_000.0,
            extras: vec![Extra {
                unit_cycles: 1.0e9,
                ..event
            }],
        });
        assert_eq!(
            response_times(&s, 168e6)[1].response_time_bound_us,
            worst[1].response_time_bound_us
        );
    }

    #[test]
    fn a_missed_deadline_reports_how_far_it_misses() {
        let mut s = schedule(1_000.0);
        // control at 20 k cycles a 10 µs period is over any deadline alone.
        s[1].wcet_cycles = 2.0e6;
        s[1].deadline_us = 10_000.0;
        let r = response_times(&s, 168e6);
        assert!(!r[1].meets_deadline);
        assert_eq!(r[1].response_time_bound_us, None);
        let past = r[1].past_deadline_us.unwrap();
        assert!(past > 2.0e6 / 168.0 && past < 2.0 * 2.0e6 / 168.0, "{past}");
        // Within its deadline nothing is past it.
        let ok = response_times(&schedule(1_000.0), 168e6);
        assert!(ok.iter().all(|x| x.past_deadline_us.is_none()));
    }

    #[test]
    fn a_small_preempting_activity_is_charged_the_lines_it_can_evict() {
        let full = response_times(&schedule(1_000.0), 168e6);
        let mut small = schedule(1_000.0);
        // SysTick's code fits 10 lines: it evicts at most 10 of control's.
        small[0].refill_cycles = 60.0;
        let small = response_times(&small, 168e6);
        let saved =
            full[1].response_time_bound_us.unwrap() - small[1].response_time_bound_us.unwrap();
        assert!(
            (saved - (PREEMPTION_REFILL_CYCLES - 60.0) / 168.0).abs() < 1e-9,
            "{saved}"
        );
    }

    #[test]
    fn a_long_critical_section_makes_control_miss() {
        // The plan task holds a lock for 2 M cycles (12 ms): control cannot start
        // for that long.
        let r = response_times(&schedule(2.0e6), 168e6);
        assert!(!r[1].meets_deadline);
        assert_eq!(r[1].response_time_bound_us, None);
        assert!(r[0].meets_deadline);
    }
}
