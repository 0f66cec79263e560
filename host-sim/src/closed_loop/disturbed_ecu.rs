//! The modelled ECU behind a run's disturbances: [`DisturbedEcu`] wraps
//! [`SimulatedEcu`] and applies the [`Disturbances`] (noise, delay, dropout,
//! steering rate limit, late obstacle; their meaning is documented in
//! [`crate::world::disturbance`]) at its boundary, so the closed-loop driver runs
//! unchanged.

use std::collections::VecDeque;

use anyhow::{anyhow, bail, Result};
use firmware::obstacles::Obstacle as FwObstacle;
use firmware::plan::Plan;
use firmware::state_estimate::StateEstimate;
use firmware::tasks::CONTROL_PERIOD_US;
use firmware::Real;

use crate::closed_loop::ecu::{ControlOutput, Ecu, SimulatedEcu};
use crate::closed_loop::SimOptions;
use crate::model::vehicle::{vehicle_config, VehicleParams};
use crate::world::disturbance::{
    estimate_biases, Disturbances, DropoutKind, EstimateBias, SplitMix64, ACCEL_NOISE_STREAM,
    LATERAL_NOISE_STREAM, NOISE_STREAM, NOISE_UNIT, WHEEL_NOISE_STREAM,
};
use crate::world::route::Window;
use crate::world::scenario::Scenario;

/// The late obstacle waiting to be given to the planner.
#[derive(Debug)]
struct PendingObstacle<T> {
    /// Every obstacle the planner has once it appears (the late one included).
    all: Vec<FwObstacle<T>>,
    /// Arc length of the late obstacle's centre on the whole track, m.
    s_m: f64,
    appear_m: f64,
    /// Last projection of the car on the whole track, m (a hint for the next).
    s_hint: Option<f64>,
    /// The whole track (the planner holds only a window of it).
    track: crate::world::track::Track,
}

/// [`SimulatedEcu`] behind the [`Disturbances`] (see the module docs).
#[derive(Debug)]
pub struct DisturbedEcu<T: Real> {
    inner: SimulatedEcu<T>,
    d: Disturbances,
    rng: SplitMix64,
    /// The lateral speed's noise, a stream of its own.
    rng_lateral: SplitMix64,
    /// Draws of the wheel speeds' noise (a stream of their own).
    rng_wheels: SplitMix64,
    /// The accelerometer's noise, from a stream of its own.
    rng_accel: SplitMix64,
    /// The run's biases on the lateral speed and the yaw rate.
    bias: EstimateBias,
    history: VecDeque<StateEstimate<T>>,
    last_delivered: Option<StateEstimate<T>>,
    last_delta: Option<T>,
    pending: Option<PendingObstacle<T>>,
    appeared_at_us: Option<u64>,
    obstacle_settings: firmware::obstacles::ObstacleSettings<T>,
}

impl<T: Real> DisturbedEcu<T> {
    /// The modelled ECU for `scenario` (without its late obstacle, if any) and the
    /// car the firmware is told of (`vehicle`), behind `d`.
    pub fn new(
        scenario: &Scenario,
        vehicle: &VehicleParams,
        opts: &SimOptions,
        d: Disturbances,
    ) -> Result<Self> {
        let car = vehicle_config::<T>(vehicle);
        let obstacle_settings = car.obstacle_settings(T::from_f64(opts.mu_planner));
        let (inner, pending) = match d.late_obstacle {
            None => (SimulatedEcu::new(scenario, vehicle, opts)?, None),
            Some(late) => {
                let o = scenario
                    .obstacles
                    .get(late.index)
                    .ok_or_else(|| anyhow!("late obstacle {} does not exist", late.index))?;
                let mut early = scenario.clone();
                early.obstacles.remove(late.index);
                let inner = SimulatedEcu::new(&early, vehicle, opts)?;
                let all = scenario
                    .obstacles
                    .iter()
                    .enumerate()
                    .map(|(k, o)| {
                        let v: Vec<[T; 2]> =
                            o.vertices.iter().map(|p| p.map(T::from_f64)).collect();
                        FwObstacle::from_vertices(k as u32, &v)
                            .map_err(|e| anyhow!("obstacle {:?}: {e:?}", o.id))
                    })
                    .collect::<Result<Vec<_>>>()?;
                let c = centroid(&o.vertices);
                let (s_m, _) = scenario.track.project(c, None);
                if !s_m.is_finite() {
                    bail!("the late obstacle is not near the track");
                }
                let pending = PendingObstacle {
                    all,
                    s_m,
                    appear_m: late.appear_m,
                    s_hint: None,
                    track: scenario.track.clone(),
                };
                (inner, Some(pending))
            }
        };
        Ok(Self {
            inner,
            rng: SplitMix64::new(d.seed ^ NOISE_STREAM),
            rng_lateral: SplitMix64::new(d.seed ^ LATERAL_NOISE_STREAM),
            rng_wheels: SplitMix64::new(d.seed ^ WHEEL_NOISE_STREAM),
            rng_accel: SplitMix64::new(d.seed ^ ACCEL_NOISE_STREAM),
            bias: estimate_biases(d.seed, d.noise_scale),
            d,
            history: VecDeque::new(),
            last_delivered: None,
            last_delta: None,
            pending,
            appeared_at_us: None,
            obstacle_settings,
        })
    }

    /// When the late obstacle was given to the planner, µs (`None`: not yet, or none).
    pub fn obstacle_appeared_at_us(&self) -> Option<u64> {
        self.appeared_at_us
    }

    /// The estimate the tasks see at `t_us` given the true one (noise, delay, dropout).
    fn seen(&mut self, t_us: u64, truth: &StateEstimate<T>) -> StateEstimate<T> {
        let mut m = *truth;
        if self.d.noise_scale > 0.0 {
            let k = self.d.noise_scale;
            // The truth plus a bias (m, rad, m/s or rad/s) plus a draw of `sigma`.
            let add = |x: T, bias: f64, sigma: f64, rng: &mut SplitMix64| {
                T::from_f64(x.to_f64() + bias + k * sigma * rng.gaussian())
            };
            let (n, b) = (NOISE_UNIT, self.bias);
            m.x_m = add(m.x_m, 0.0, n.position_m, &mut self.rng);
            m.y_m = add(m.y_m, 0.0, n.position_m, &mut self.rng);
            m.psi_rad = add(m.psi_rad, 0.0, n.heading_rad, &mut self.rng);
            m.vx_mps = add(m.vx_mps, 0.0, n.speed_mps, &mut self.rng);
            m.yaw_rate_radps = add(
                m.yaw_rate_radps,
                b.yaw_rate_radps,
                n.yaw_rate_radps,
                &mut self.rng,
            );
            m.vy_mps = add(
                m.vy_mps,
                b.lateral_speed_mps,
                n.lateral_speed_mps,
                &mut self.rng_lateral,
            );
            for w in m.wheel_speed_mps.iter_mut() {
                *w = add(*w, 0.0, n.wheel_speed_mps, &mut self.rng_wheels);
            }
            m.specific_force_x_mps2 = add(
                m.specific_force_x_mps2,
                b.specific_force_mps2,
                n.specific_force_mps2,
                &mut self.rng_accel,
            );
        }
        let keep = self.d.delay_periods() + 1;
        self.history.push_back(m);
        while self.history.len() > keep {
            self.history.pop_front();
        }
        let delayed = self.history.front().copied().unwrap_or(m);
        let out = match self.d.dropout {
            Some(dr) if dr.covers(t_us) => match dr.kind {
                DropoutKind::Nan => StateEstimate::unavailable(t_us),
                DropoutKind::Hold => self.last_delivered.unwrap_or(delayed),
            },
            _ => delayed,
        };
        if !self.d.dropout.is_some_and(|dr| dr.covers(t_us)) {
            self.last_delivered = Some(out);
        }
        out
    }

    /// Whether the sensor frame of the control instant `t_us` (µs) is refused, so
    /// that the control task does not learn of the frames of the road sent with
    /// it ([`crate::world::disturbance::Dropout::withholds_route`]).
    fn refused(&self, t_us: u64) -> bool {
        self.d
            .dropout
            .is_some_and(|dr| dr.withholds_route && dr.covers(t_us))
    }

    /// Gives the late obstacle to the planner once the car is close enough.
    fn maybe_reveal(&mut self, t_us: u64, truth: &StateEstimate<T>) -> Result<()> {
        let Some(p) = self.pending.as_mut() else {
            return Ok(());
        };
        let (s_car, _) = p
            .track
            .project([truth.x_m.to_f64(), truth.y_m.to_f64()], p.s_hint);
        if !s_car.is_finite() {
            return Ok(());
        }
        p.s_hint = Some(s_car);
        let mut ahead = p.s_m - s_car;
        if p.track.closed && ahead < 0.0 {
            ahead += p.track.length();
        }
        if ahead <= p.appear_m {
            // Known from now on (every later window of the road rebuilds it too).
            let task = self.inner.plan_task_mut();
            task.set_obstacles(self.obstacle_settings, &p.all);
            if !task.rebuild_obstacles() {
                bail!("the late obstacle: the obstacle manager refused the obstacles");
            }
            self.pending = None;
            self.appeared_at_us = Some(t_us);
        }
        Ok(())
    }

    /// The actuation after the steering rate limit.
    fn limit_steering(&mut self, c: &mut ControlOutput<T>, truth: &StateEstimate<T>) {
        let Some(rate) = self.d.steer_rate_limit_radps else {
            return;
        };
        let prev = self.last_delta.unwrap_or(truth.delta_rad);
        let step = T::from_f64(rate * CONTROL_PERIOD_US as f64 * 1e-6);
        let cmd = c.actuation.delta_rad;
        let applied = if cmd.is_finite() {
            cmd.clamp(prev - step, prev + step)
        } else {
            prev
        };
        c.actuation.delta_rad = applied;
        self.last_delta = Some(applied);
    }
}

impl<T: Real> Ecu<T> for DisturbedEcu<T> {
    fn control(&mut self, t_us: u64, est: &StateEstimate<T>) -> Result<ControlOutput<T>> {
        self.maybe_reveal(t_us, est)?;
        if self.refused(t_us) {
            self.inner.refuse_sensor_frame();
        }
        let seen = self.seen(t_us, est);
        let mut c = self.inner.control(t_us, &seen)?;
        self.limit_steering(&mut c, est);
        Ok(c)
    }

    fn active_plan(&self) -> &Plan<T> {
        self.inner.active_plan()
    }

    fn set_window(&mut self, w: &Window) -> Result<()> {
        self.inner.set_window(w)
    }
}

/// Mean of a polygon's vertices, m.
pub fn centroid(v: &[[f64; 2]]) -> [f64; 2] {
    let n = v.len().max(1) as f64;
    let (x, y) = v.iter().fold((0.0, 0.0), |(x, y), p| (x + p[0], y + p[1]));
    [x / n, y / n]
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::world::disturbance::run_seed;

    /// The estimates the tasks see, `n` of them, for a car standing still at 10 m/s
    /// straight ahead, at noise level `k` with the seed `seed`.
    fn seen_at_level(k: f64, seed: u64, n: usize) -> (StateEstimate<f64>, Vec<StateEstimate<f64>>) {
        let d = Disturbances {
            noise_scale: k,
            seed,
            ..Disturbances::default()
        };
        let mut ecu = DisturbedEcu::<f64>::new(
            &Scenario::paper(false),
            &VehicleParams::default(),
            &SimOptions::default(),
            d,
        )
        .unwrap();
        let truth = StateEstimate {
            vx_mps: 10.0,
            vy_mps: 0.1,
            yaw_rate_radps: 0.05,
            wheel_speed_mps: [10.0, 10.1, 9.9, 10.0],
            specific_force_x_mps2: 0.3,
            ..StateEstimate::zeroed()
        };
        let seen = (0..n)
            .map(|i| ecu.seen(i as u64 * CONTROL_PERIOD_US, &truth))
            .collect();
        (truth, seen)
    }

    fn mean_and_sd(xs: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
        let n = xs.clone().count() as f64;
        let mean = xs.clone().sum::<f64>() / n;
        let var = xs.map(|x| (x - mean).powi(2)).sum::<f64>() / n;
        (mean, var.sqrt())
    }

    #[test]
    fn the_lateral_speed_and_yaw_rate_the_tasks_see_carry_the_runs_bias_and_the_levels_noise() {
        let (k, n) = (4.0, 20_000);
        let seed = run_seed("paper", 3);
        let bias = estimate_biases(seed, k);
        let (truth, seen) = seen_at_level(k, seed, n);
        let (vy_mean, vy_sd) = mean_and_sd(seen.iter().map(|m| m.vy_mps - truth.vy_mps));
        let (r_mean, r_sd) =
            mean_and_sd(seen.iter().map(|m| m.yaw_rate_radps - truth.yaw_rate_radps));
        let (sv, sr) = (
            k * NOISE_UNIT.lateral_speed_mps,
            k * NOISE_UNIT.yaw_rate_radps,
        );
        // The mean is the bias within four standard errors; the spread the level's.
        let se = 4.0 / (n as f64).sqrt();
        assert!(
            (vy_mean - bias.lateral_speed_mps).abs() < se * sv,
            "{vy_mean} vs {bias:?}"
        );
        assert!(
            (r_mean - bias.yaw_rate_radps).abs() < se * sr,
            "{r_mean} vs {bias:?}"
        );
        assert!((vy_sd / sv - 1.0).abs() < 0.03, "σ {vy_sd}");
        assert!((r_sd / sr - 1.0).abs() < 0.03, "σ {r_sd}");
        // This seed's biases are large enough to tell from the noise's mean.
        assert!(bias.lateral_speed_mps.abs() > 10.0 * se * sv, "{bias:?}");
        assert!(bias.yaw_rate_radps.abs() > 10.0 * se * sr, "{bias:?}");
        // Each wheel's speed: unbiased, the level's noise.
        for i in 0..4 {
            let (w_mean, w_sd) = mean_and_sd(
                seen.iter()
                    .map(|m| m.wheel_speed_mps[i] - truth.wheel_speed_mps[i]),
            );
            let sw = k * NOISE_UNIT.wheel_speed_mps;
            assert!(w_mean.abs() < se * sw, "wheel {i}: mean {w_mean}");
            assert!((w_sd / sw - 1.0).abs() < 0.03, "wheel {i}: σ {w_sd}");
        }
        // The accelerometer: the run's bias, the level's noise.
        let (f_mean, f_sd) = mean_and_sd(
            seen.iter()
                .map(|m| m.specific_force_x_mps2 - truth.specific_force_x_mps2),
        );
        let sf = k * NOISE_UNIT.specific_force_mps2;
        assert!(
            (f_mean - bias.specific_force_mps2).abs() < se * sf,
            "{f_mean} vs {bias:?}"
        );
        assert!((f_sd / sf - 1.0).abs() < 0.03, "σ {f_sd}");
        // The same seed, the same draws; level 0, the truth.
        let (_, again) = seen_at_level(k, seed, 100);
        assert_eq!(format!("{:?}", &seen[..100]), format!("{again:?}"));
        let (truth, clean) = seen_at_level(0.0, seed, 100);
        assert!(clean.iter().all(|m| *m
            == StateEstimate {
                stamp_us: m.stamp_us,
                ..truth
            }));
    }

    /// The wheel speeds are delayed and dropped with the rest of the estimate:
    /// 30 ms late, they are those of three periods before; in a NaN dropout not
    /// measured; in a held one, the last delivered.
    #[test]
    fn the_wheel_speeds_are_delayed_and_dropped_with_the_estimate() {
        use crate::world::disturbance::{Dropout, DropoutKind};
        for kind in [DropoutKind::Nan, DropoutKind::Hold] {
            let d = Disturbances {
                delay_ms: 30.0,
                dropout: Some(Dropout {
                    start_us: 10 * CONTROL_PERIOD_US,
                    periods: 3,
                    kind,
                    withholds_route: false,
                }),
                ..Disturbances::default()
            };
            let mut ecu = DisturbedEcu::<f64>::new(
                &Scenario::paper(false),
                &VehicleParams::default(),
                &SimOptions::default(),
                d,
            )
            .unwrap();
            // Each period the truth's wheels turn 1 m/s faster, each its own.
            let wheels = |i: u64| {
                let v = 10.0 + i as f64;
                [v, v + 0.1, v + 0.2, v + 0.3]
            };
            for i in 0..20u64 {
                let t_us = i * CONTROL_PERIOD_US;
                let truth = StateEstimate {
                    stamp_us: t_us,
                    vx_mps: 10.0 + i as f64,
                    wheel_speed_mps: wheels(i),
                    ..StateEstimate::zeroed()
                };
                let seen = ecu.seen(t_us, &truth).wheel_speed_mps;
                let want = match (i, kind) {
                    (10..=12, DropoutKind::Nan) => [f64::NAN; 4],
                    // The last delivered: period 9's, three periods late.
                    (10..=12, DropoutKind::Hold) => wheels(6),
                    _ => wheels(i.saturating_sub(3)),
                };
                assert_eq!(
                    format!("{seen:?}"),
                    format!("{want:?}"),
                    "{kind:?}, period {i}"
                );
            }
        }
    }
}
