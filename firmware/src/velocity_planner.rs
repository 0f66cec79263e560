//! Local velocity planner: the heuristic speed `V_heur` of the paper's
//! Section III-A (its Equation 3) that the MPC's speed cost tracks.
//!
//! ```text
//! V_heur = min( sqrt(a_y,frac · μ · g / (κ_max + κ_res)),  V_max,  V + ΔV )
//! ```
//!
//! (the paper's `sqrt(a_y,frac · μ · g · R_min)`, `R_min = 1/κ_max`, when the curvature reserve
//! `κ_res` is 0, its default; [`VelocityPlannerSettings::curve_speed_mps`]).
//!
//! * `κ_max` is the largest `|κ|` of the reference path
//!   over the preview distance `d = max(V, V_floor) · T_prev` ahead of the queried
//!   abscissa ([`ReferencePath::max_abs_curvature_between`]); on a straight
//!   (`κ_max = κ_res = 0`) the first term is infinite. `a_y,frac = 0.5` (the paper) keeps
//!   the lateral acceleration in the validity domain of the kinematic model, the
//!   same bound as [`crate::validity`]. `V_floor` keeps a useful preview at low
//!   speed (the car must see a hairpin before it starts).
//! * `V_max = min(V_cap, a_stop · T_H)` with `a_stop = min(a_brake, μ·g)`: the
//!   paper's "maximum speed on straights such that the car can still stop by the
//!   end of the MPC horizon" (`V/a_stop ≤ T_H`). Defaults: `T_H = HORIZON ·
//!   PLAN_DT_S = 3.2 s` and `a_brake = 8 m/s²`, the magnitude of the MPC's hard
//!   deceleration bound (the paper's `u1 ≥ −8 m/s²`), so `V_max = 25.6 m/s` at
//!   `μ = 1`; limiting by `μ·g` lowers it on a slippery road, where the car cannot
//!   brake at 8 m/s². A comfort planner would set `a_brake` to a fraction of 8.
//! * `V + ΔV` lets the MPC accelerate gradually from the current speed `V`.
//!
//! As the paper remarks, `V_heur` is a target for a cost term, not a dynamically
//! feasible profile; the MPC does not have to track it exactly.
//!
//! # Example
//!
//! ```
//! use firmware::reference_path::ReferencePath;
//! use firmware::velocity_planner::{v_heur, VelocityPlannerSettings};
//!
//! let pts: Vec<[f64; 2]> = (0..50).map(|i| [2.0 * i as f64, 0.0]).collect();
//! let mut path: ReferencePath<f64, 64> = ReferencePath::new();
//! path.load(&pts, None, false).unwrap();
//! let settings = VelocityPlannerSettings::default();
//! // Straight: V + ΔV = 13 m/s (below V_max = 25.6 m/s at μ = 1).
//! assert!((v_heur(&settings, &path, 10.0, 10.0, 1.0) - 13.0).abs() < 1e-9);
//! ```

use crate::plan::{HORIZON, PLAN_DT_S};
use crate::reference_path::{CurvatureWindow, PathSample, ReferencePath};
use crate::Real;

/// Settings of the local velocity planner (units in each field).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VelocityPlannerSettings<T> {
    /// Speed increment over the current speed, `ΔV`, m/s.
    pub delta_v_mps: T,
    /// Preview time `T_prev` over which the path's curvature is looked at, s.
    pub preview_time_s: T,
    /// Lowest speed used for the preview distance, `V_floor`, m/s.
    pub preview_speed_floor_mps: T,
    /// Fraction of `μ·g` allowed as lateral acceleration (the paper's 0.5).
    pub ay_fraction: T,
    /// Curvature reserve `κ_res`, 1/m: the curve speed is taken at `|κ| + κ_res`,
    /// so the plan keeps that much curvature (steering) below the validity limit
    /// for bringing the car back to the line (see [`Self::curve_speed_mps`]).
    pub curvature_reserve_1pm: T,
    /// User speed cap `V_cap` (legal limit, track limit), m/s.
    pub v_cap_mps: T,
    /// Deceleration used for "can stop within the horizon", `a_brake`, m/s² (positive).
    pub brake_decel_mps2: T,
    /// The MPC horizon `T_H`, s.
    pub horizon_s: T,
}

impl<T: Real> Default for VelocityPlannerSettings<T> {
    /// `ΔV = 3 m/s`, `T_prev = T_H = 3.2 s`, `V_floor = 5 m/s`, fraction 0.5,
    /// `V_cap = 30 m/s`, `a_brake = 8 m/s²`, `T_H = HORIZON · PLAN_DT_S = 3.2 s`.
    fn default() -> Self {
        let horizon_s = T::from_usize(HORIZON) * T::lit(PLAN_DT_S);
        Self {
            delta_v_mps: T::lit(3.0),
            preview_time_s: horizon_s,
            preview_speed_floor_mps: T::lit(5.0),
            ay_fraction: T::HALF,
            curvature_reserve_1pm: T::ZERO,
            v_cap_mps: T::lit(30.0),
            brake_decel_mps2: T::lit(8.0),
            horizon_s,
        }
    }
}

impl<T: Real> VelocityPlannerSettings<T> {
    /// `V_max = min(V_cap, min(a_brake, μ·g) · T_H)`, m/s, for friction `mu`
    /// (dimensionless; negative or NaN counts as 0).
    pub fn v_max_mps(&self, mu: T) -> T {
        let mu = mu.max(T::ZERO);
        let a_stop = self
            .brake_decel_mps2
            .min(mu * T::lit(crate::G))
            .max(T::ZERO);
        self.v_cap_mps.min(a_stop * self.horizon_s).max(T::ZERO)
    }

    /// Speed at which a turn of curvature `kappa_1pm` (1/m, either sign) plus the
    /// reserve `κ_res` reaches the lateral limit `ay_fraction·μ·g`:
    /// `sqrt(ay_fraction·μ·g/(|κ| + κ_res))`, m/s (`+∞` when `|κ| + κ_res` is 0).
    ///
    /// The reserve is what the plan keeps for corrections: bringing the car back
    /// from a lateral error `e` over a distance `d` takes a curvature of about
    /// `2·e/d²` on top of the path's. The kinematic steering is about `l·κ` and
    /// `δ_max(V)` about `l·a_y,lim/V²`, so a fixed curvature reserve is a fixed
    /// steering reserve, which is a larger share of `δ_max` the faster the car:
    /// it slows fast curves (where the car, turning less than the kinematic model
    /// says, needs that steering most) and leaves hairpins almost as they were.
    pub fn curve_speed_mps(&self, kappa_1pm: T, mu: T) -> T {
        let k = kappa_1pm.abs() + self.curvature_reserve_1pm.max(T::ZERO);
        let ay = self.ay_fraction * mu.max(T::ZERO) * T::lit(crate::G);
        if k <= T::ZERO {
            return T::INFINITY;
        }
        (ay.max(T::ZERO) / k).sqrt()
    }

    /// Preview distance `max(V, V_floor) · T_prev` ahead of the query, m.
    pub fn preview_distance_m(&self, v_now_mps: T) -> T {
        v_now_mps.max(self.preview_speed_floor_mps).max(T::ZERO) * self.preview_time_s.max(T::ZERO)
    }
}

/// `V_heur`, m/s, at the path abscissa `s_node_m` (m; any value, wrapped on a
/// closed path) for the current speed `v_now_mps` (m/s; negative counts as 0)
/// and friction `mu`: `min(sqrt(a_y,frac·μ·g/(κ_max + κ_res)), V_max, V + ΔV)` with
/// `κ_max` over `[s_node, s_node + preview distance]`. Never negative. An empty
/// path has no curvature: the result is then `min(V_max, V + ΔV)`.
///
/// The MPC calls it once per prediction node (one curvature scan of the preview
/// window each, `O(vertices in the window)`, one `sqrt`).
pub fn v_heur<T: Real, const CAP: usize>(
    settings: &VelocityPlannerSettings<T>,
    path: &ReferencePath<T, CAP>,
    s_node_m: T,
    v_now_mps: T,
    mu: T,
) -> T {
    v_heur_with(settings, v_now_mps, mu, |d| {
        path.max_abs_curvature_between(s_node_m, s_node_m + d)
    })
}

/// [`v_heur`] at the abscissa `s_node_m` that `at` was sampled at
/// ([`ReferencePath::sample_at`]), for one of a sequence of nodes along the
/// horizon: the preview window slides with `window`
/// ([`ReferencePath::max_abs_curvature_window`]; the same value up to the
/// rounding of vertex positions), and its start is not looked up again.
pub fn v_heur_at<T: Real, const CAP: usize>(
    settings: &VelocityPlannerSettings<T>,
    path: &ReferencePath<T, CAP>,
    window: &mut CurvatureWindow<T>,
    at: &PathSample<T>,
    s_node_m: T,
    v_now_mps: T,
    mu: T,
) -> T {
    v_heur_with(settings, v_now_mps, mu, |d| {
        path.max_abs_curvature_window(window, at, s_node_m, s_node_m + d)
    })
}

/// `V_heur` from the largest `|κ|` over the preview distance `d` (m), which
/// `kappa_over(d)` gives (1/m): the formula [`v_heur`] and [`v_heur_at`] share.
fn v_heur_with<T: Real>(
    settings: &VelocityPlannerSettings<T>,
    v_now_mps: T,
    mu: T,
    kappa_over: impl FnOnce(T) -> T,
) -> T {
    let v = v_now_mps.max(T::ZERO);
    let kappa = kappa_over(settings.preview_distance_m(v));
    let curve = settings.curve_speed_mps(kappa, mu);
    let v_max = settings.v_max_mps(mu);
    let v_inc = v + settings.delta_v_mps.max(T::ZERO);
    curve.min(v_max).min(v_inc).max(T::ZERO)
}
