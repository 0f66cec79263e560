//! The car's actuators between the firmware's commands and the plant: the front
//! steering angle and the four wheel torques, each a pure delay, a first-order lag
//! and a rate limit, from the vehicle file's `[actuators]` table
//! ([`ActuatorParams`]). By default every actuator is ideal (no delay, no lag, no
//! rate limit: the plant applies the command, as in the paper).
//!
//! # One channel, per plant step of `dt`
//!
//! With the command `u[k]` held over step `k` and the output `y[k]` the plant
//! applies over that step:
//!
//! ```text
//! u_d[k]  = u[k − n],  n = round(delay/dt)         (a ring buffer of n commands)
//! target  = y[k−1] + (1 − e^(−dt/τ))·(u_d[k] − y[k−1])    (τ = 0: u_d[k])
//! y[k]    = y[k−1] + clamp(target − y[k−1], −R·dt, R·dt)   (R = ∞: target)
//! ```
//!
//! The lag is the exact discretisation of `τ·ẏ = u_d − y` over a step with its
//! input held, `y[k]` its value at the step's end; the rate limit `R` caps what the
//! lag asks for in one step. Before the first command has come through the delay,
//! `u_d` is the channel's initial output (the wheels straight, no torque). A step
//! `A` of the command at `t = 0`, with `A > R·τ`, so gives (continuous time, the
//! closed form the tests check it against)
//!
//! ```text
//! y(t) = 0                        t < D
//!      = R·(t − D)                D ≤ t < t₁ = D + (A − R·τ)/R
//!      = A − R·τ·e^(−(t − t₁)/τ)  t ≥ t₁
//! ```
//!
//! and `A·(1 − e^(−(t − D)/τ))` after `D` when `A ≤ R·τ`; the plant step `k`
//! applies its value at `t = (k + 1)·dt`. The steering angle is also held within
//! the mechanical limit `max_steer_rad` (the rack's end stops). Each wheel torque
//! has its own channel, with the same parameters: one lag for the drive and the
//! brakes alike.
//!
//! Everything is computed in whole plant steps: deterministic, no allocation after
//! the plant is built.

use std::fmt;
use std::str::FromStr;

use serde::Deserialize;

use crate::model::vehicle::InvalidField;

/// Largest time constant or delay an actuator may have, s: slower than that it
/// would not be an actuator a 100 Hz controller drives.
pub const MAX_ACTUATOR_TIME_S: f64 = 1.0;

/// The actuators' dynamics (the vehicle file's optional `[actuators]` table; every
/// field optional, ideal when absent). SI units.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ActuatorParams {
    /// Time constant of the steering actuator's first-order lag, s, in `[0, 1]`
    /// (0: none).
    pub steering_time_constant_s: f64,
    /// Pure delay of the steering actuator, s, in `[0, 1]`, rounded to whole plant
    /// steps (0: none).
    pub steering_delay_s: f64,
    /// Largest rate of the front wheels' steering angle, rad/s, > 0 (`inf`: none).
    pub steering_rate_limit_rad_per_s: f64,
    /// Time constant of each wheel torque's first-order lag, s, in `[0, 1]` (0: none).
    pub torque_time_constant_s: f64,
    /// Pure delay of each wheel torque, s, in `[0, 1]`, rounded to whole plant
    /// steps (0: none).
    pub torque_delay_s: f64,
    /// Largest rate of each wheel torque, N·m/s, > 0 (`inf`: none).
    pub torque_rate_limit_nm_per_s: f64,
}

impl Default for ActuatorParams {
    /// Ideal actuators: the plant applies the command as it comes.
    fn default() -> Self {
        Self {
            steering_time_constant_s: 0.0,
            steering_delay_s: 0.0,
            steering_rate_limit_rad_per_s: f64::INFINITY,
            torque_time_constant_s: 0.0,
            torque_delay_s: 0.0,
            torque_rate_limit_nm_per_s: f64::INFINITY,
        }
    }
}

/// The fields of [`ActuatorParams`] by name (as in the vehicle file and
/// `--actuator`), with their unit.
pub const ACTUATOR_FIELDS: [(&str, &str); 6] = [
    ("steering_time_constant_s", "s"),
    ("steering_delay_s", "s"),
    ("steering_rate_limit_rad_per_s", "rad/s"),
    ("torque_time_constant_s", "s"),
    ("torque_delay_s", "s"),
    ("torque_rate_limit_nm_per_s", "N·m/s"),
];

impl ActuatorParams {
    /// The field called `name` (see [`ACTUATOR_FIELDS`]), if there is one.
    pub fn field_mut(&mut self, name: &str) -> Option<&mut f64> {
        Some(match name {
            "steering_time_constant_s" => &mut self.steering_time_constant_s,
            "steering_delay_s" => &mut self.steering_delay_s,
            "steering_rate_limit_rad_per_s" => &mut self.steering_rate_limit_rad_per_s,
            "torque_time_constant_s" => &mut self.torque_time_constant_s,
            "torque_delay_s" => &mut self.torque_delay_s,
            "torque_rate_limit_nm_per_s" => &mut self.torque_rate_limit_nm_per_s,
            _ => return None,
        })
    }

    /// The fields with their names, in the order of [`ACTUATOR_FIELDS`].
    pub fn named_values(&self) -> [(&'static str, f64); 6] {
        [
            (ACTUATOR_FIELDS[0].0, self.steering_time_constant_s),
            (ACTUATOR_FIELDS[1].0, self.steering_delay_s),
            (ACTUATOR_FIELDS[2].0, self.steering_rate_limit_rad_per_s),
            (ACTUATOR_FIELDS[3].0, self.torque_time_constant_s),
            (ACTUATOR_FIELDS[4].0, self.torque_delay_s),
            (ACTUATOR_FIELDS[5].0, self.torque_rate_limit_nm_per_s),
        ]
    }

    /// The fields that differ from the ideal actuators, `name=value` joined by `;`
    /// (empty for ideal ones): what `--actuator` would set to give them.
    pub fn to_settings_string(&self) -> String {
        let ideal = Self::default().named_values();
        self.named_values()
            .iter()
            .zip(ideal)
            .filter(|((_, v), (_, i))| v != i)
            .map(|((n, v), _)| format!("{n}={v}"))
            .collect::<Vec<_>>()
            .join(";")
    }

    /// Checks every field (named `actuators.<field>` in the error): time constants
    /// and delays in `[0, MAX_ACTUATOR_TIME_S]`, rate limits positive (infinite
    /// allowed), nothing NaN.
    pub fn validate(&self) -> Result<(), InvalidField> {
        for (name, v) in self.named_values() {
            let field = format!("actuators.{name}");
            let bad = |reason: String| Err(InvalidField { field, reason });
            if name.contains("rate_limit") {
                if v.is_nan() || v <= 0.0 {
                    return bad(format!(
                        "a rate limit must be positive (inf for none), got {v}"
                    ));
                }
            } else if !(v.is_finite() && (0.0..=MAX_ACTUATOR_TIME_S).contains(&v)) {
                return bad(format!(
                    "must be in [0, {MAX_ACTUATOR_TIME_S}] s (0 for none), got {v}"
                ));
            }
        }
        Ok(())
    }
}

impl ActuatorParams {
    /// These parameters with `settings` applied in order (a later one for the same
    /// field wins).
    pub fn with_settings(&self, settings: &[ActuatorSetting]) -> Self {
        let mut p = *self;
        for s in settings {
            if let Some(f) = p.field_mut(s.field) {
                *f = s.value;
            }
        }
        p
    }
}

/// One actuator parameter given for a run (`--actuator KEY=VALUE`): a field of
/// [`ActuatorParams`] and its value, over the vehicle file's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ActuatorSetting {
    /// The field's name (one of [`ACTUATOR_FIELDS`]).
    pub field: &'static str,
    /// Its value, in the field's unit.
    pub value: f64,
}

impl fmt::Display for ActuatorSetting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}={}", self.field, self.value)
    }
}

impl FromStr for ActuatorSetting {
    type Err = String;
    /// `KEY=VALUE`: a field of [`ACTUATOR_FIELDS`] and a value in its range (see
    /// [`ActuatorParams::validate`]; `inf` for no rate limit).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let keys = ACTUATOR_FIELDS
            .iter()
            .map(|(n, unit)| format!("{n} ({unit})"))
            .collect::<Vec<_>>()
            .join(", ");
        let (key, value) = s
            .split_once('=')
            .ok_or_else(|| format!("--actuator {s:?}: wants KEY=VALUE with KEY one of {keys}"))?;
        let (key, value) = (key.trim(), value.trim());
        let field = ACTUATOR_FIELDS
            .iter()
            .map(|(n, _)| *n)
            .find(|n| *n == key)
            .ok_or_else(|| {
                format!("--actuator {s:?}: no actuator field {key:?}; KEY is one of {keys}")
            })?;
        let value: f64 = value
            .parse()
            .map_err(|_| format!("--actuator {s:?}: VALUE {value:?} is not a number"))?;
        let setting = ActuatorSetting { field, value };
        ActuatorParams::default()
            .with_settings(&[setting])
            .validate()
            .map_err(|e| format!("--actuator {s:?}: {}", e.reason))?;
        Ok(setting)
    }
}

/// `--actuator`'s help: the keys, their units and what the shipped cars have.
pub fn actuator_help() -> String {
    let ideal = ActuatorParams::default().named_values();
    let keys = ACTUATOR_FIELDS
        .iter()
        .zip(ideal)
        .map(|((n, unit), (_, v))| format!("  {n}: {unit} (ideal: {v})"))
        .collect::<Vec<_>>()
        .join("\n");
    format!(
        "An actuator parameter of the plant's car, KEY=VALUE, over the vehicle file's [actuators] table (repeatable; the same in every run of a sweep). The steering angle and each wheel torque go through a pure delay, a first-order lag and a rate limit; the shipped cars' are ideal. Keys:\n{keys}"
    )
}

/// One actuator: its delay line, lag, rate limit, range and output.
#[derive(Clone, Debug)]
struct Channel {
    /// The last `n` commands, oldest at `next` (empty without a delay).
    line: Vec<f64>,
    /// Where the oldest command is, and the next one goes.
    next: usize,
    /// `1 − e^(−dt/τ)`; `None` without a lag.
    lag: Option<f64>,
    /// `R·dt`, the largest change in one step (∞ without a limit).
    max_change: f64,
    /// The output's range `±limit` (∞ without one).
    limit: f64,
    /// The output over the last step.
    y: f64,
}

impl Channel {
    fn new(time_constant_s: f64, delay_s: f64, rate: f64, limit: f64, dt_s: f64) -> Self {
        let n = (delay_s / dt_s).round() as usize;
        Self {
            line: vec![0.0; n],
            next: 0,
            lag: (time_constant_s > 0.0).then(|| -(-dt_s / time_constant_s).exp_m1()),
            max_change: rate * dt_s,
            limit,
            y: 0.0,
        }
    }

    /// The output over the next step for the command `u`, without moving on.
    fn peek(&self, u: f64) -> f64 {
        let delayed = self.line.get(self.next).copied().unwrap_or(u);
        let target = match self.lag {
            Some(a) => self.y + a * (delayed - self.y),
            None => delayed,
        };
        let change = target - self.y;
        let limited = if change.abs() <= self.max_change {
            target
        } else {
            self.y + self.max_change.copysign(change)
        };
        limited.clamp(-self.limit, self.limit)
    }

    /// Moves on one step: `u` enters the delay line, `y` is the new output.
    fn commit(&mut self, u: f64, y: f64) {
        if let Some(slot) = self.line.get_mut(self.next) {
            *slot = u;
            self.next = (self.next + 1) % self.line.len();
        }
        self.y = y;
    }
}

/// The steering actuator and the four wheel-torque actuators of a plant.
#[derive(Clone, Debug)]
pub struct Actuators {
    steering: Channel,
    torque: [Channel; 4],
}

impl Actuators {
    /// Actuators of parameters `p` stepping at `dt_s` (s), the steering within
    /// `±max_steer_rad` (rad), at rest: the wheels straight, no torque.
    pub fn new(p: &ActuatorParams, max_steer_rad: f64, dt_s: f64) -> Self {
        let torque = || {
            Channel::new(
                p.torque_time_constant_s,
                p.torque_delay_s,
                p.torque_rate_limit_nm_per_s,
                f64::INFINITY,
                dt_s,
            )
        };
        Self {
            steering: Channel::new(
                p.steering_time_constant_s,
                p.steering_delay_s,
                p.steering_rate_limit_rad_per_s,
                max_steer_rad,
                dt_s,
            ),
            torque: [torque(), torque(), torque(), torque()],
        }
    }

    /// What the actuators apply over the next step for the commanded steering
    /// angle (rad) and wheel torques (N·m), without moving on (see
    /// [`Actuators::commit`]).
    pub fn peek(&self, delta_rad: f64, torque_nm: [f64; 4]) -> (f64, [f64; 4]) {
        (
            self.steering.peek(delta_rad),
            std::array::from_fn(|i| self.torque[i].peek(torque_nm[i])),
        )
    }

    /// Moves on one step with the commands given to [`Actuators::peek`] and the
    /// outputs it returned.
    pub fn commit(&mut self, command: (f64, [f64; 4]), applied: (f64, [f64; 4])) {
        self.steering.commit(command.0, applied.0);
        for (i, c) in self.torque.iter_mut().enumerate() {
            c.commit(command.1[i], applied.1[i]);
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn ideal_actuators_apply_the_command_bit_for_bit() {
        let mut a = Actuators::new(&ActuatorParams::default(), 0.6, 1e-3);
        for (k, u) in [0.1, -0.7, 0.3333, 1e-300, -0.0].into_iter().enumerate() {
            let t = [u * 1e3, -u, k as f64, f64::MAX];
            let out = a.peek(u, t);
            assert_eq!(out, (u.clamp(-0.6, 0.6), t));
            a.commit((u, t), out);
        }
    }

    #[test]
    fn a_delay_of_three_steps_replays_the_commands_three_steps_late() {
        let p = ActuatorParams {
            torque_delay_s: 3e-3,
            ..ActuatorParams::default()
        };
        let mut a = Actuators::new(&p, 0.6, 1e-3);
        let mut seen = Vec::new();
        for k in 0..8 {
            let t = [k as f64; 4];
            let out = a.peek(0.0, t);
            seen.push(out.1[2]);
            a.commit((0.0, t), out);
        }
        assert_eq!(seen, vec![0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn settings_parse_apply_and_refuse_nonsense_with_the_reason() {
        let s: ActuatorSetting = "steering_time_constant_s=0.08".parse().unwrap();
        assert_eq!(s.to_string(), "steering_time_constant_s=0.08");
        let r: ActuatorSetting = " torque_rate_limit_nm_per_s = inf ".parse().unwrap();
        assert_eq!(r.value, f64::INFINITY);
        let p = ActuatorParams::default().with_settings(&[s, r]);
        assert_eq!(p.steering_time_constant_s, 0.08);
        assert_eq!(p.to_settings_string(), "steering_time_constant_s=0.08");
        for (bad, says) in [
            ("steering_time_constant_s", "wants KEY=VALUE"),
            ("steering_lag=0.1", "no actuator field \"steering_lag\""),
            ("torque_delay_s=fast", "VALUE \"fast\" is not a number"),
            ("torque_delay_s=1.5", "must be in [0, 1] s"),
            ("steering_rate_limit_rad_per_s=-1", "must be positive"),
        ] {
            let e = bad.parse::<ActuatorSetting>().unwrap_err();
            assert!(
                e.starts_with("--actuator") && e.contains(says),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn bad_parameters_name_the_field() {
        let mut p = ActuatorParams::default();
        *p.field_mut("torque_delay_s").unwrap() = 2.0;
        let e = p.validate().unwrap_err();
        assert_eq!(e.field, "actuators.torque_delay_s");
        assert!(e.reason.contains("[0, 1] s"), "{e}");
        let mut p = ActuatorParams {
            steering_rate_limit_rad_per_s: 0.0,
            ..ActuatorParams::default()
        };
        assert_eq!(
            p.validate().unwrap_err().field,
            "actuators.steering_rate_limit_rad_per_s"
        );
        p.steering_rate_limit_rad_per_s = f64::NAN;
        assert!(p.validate().is_err());
        p.steering_rate_limit_rad_per_s = f64::INFINITY;
        p.steering_time_constant_s = -0.01;
        assert!(p.validate().is_err());
        assert!(ActuatorParams::default().validate().is_ok());
        assert_eq!(ActuatorParams::default().to_settings_string(), "");
        p.steering_time_constant_s = 0.08;
        assert_eq!(p.to_settings_string(), "steering_time_constant_s=0.08");
    }
}
