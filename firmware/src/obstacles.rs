//! Obstacle manager: one forbidden parabola per static obstacle (the paper's
//! Section III-B, after Ziegler et al. 2014).
//!
//! # Frame
//!
//! For an obstacle (a polygon of at most [`MAX_VERTICES`] vertices in the global
//! frame, m) the path point closest to it is found (below), at abscissa `s_o`.
//! At that point the path frame has its origin `o`, `ξ` along the path tangent
//! and `η` along the left normal (m). The parabola's directrix is parallel to the
//! tangent there.
//!
//! *Closest path point*: every vertex is projected on the path (near the
//! projection of the vertices' centroid). If all vertices lie strictly on one
//! side, the projection of the vertex with the smallest `|η|` is used; if the
//! obstacle straddles the centre line, the projection of the centroid is used.
//!
//! # Parabola
//!
//! With `σ = +1` when the car passes on the obstacle's **left** ([`Side::Left`])
//! and `σ = −1` when it passes on its **right**, the forbidden interior is
//!
//! ```text
//! σ·η ≤ A − c·(ξ − ξ0)²
//! ```
//!
//! (opening to the right for `σ = +1`: `η ≤ η_a − c(ξ − ξ0)²`, with the apex
//! `η_a = σ·A`; the mirror image for `σ = −1`). Each vertex `(ξ_v, η_v)` is
//! inflated into the two points `(ξ_v ± m_x, σ·η_v + m_y)` with `m_y` = half the
//! car width + a lateral buffer and `m_x` = half the car length, because the
//! constraint is written on the car's reference point. The apex is minimal:
//!
//! ```text
//! (ξ0, A) = argmin over ξ0 of  F(ξ0) = max_j ( e_j + c·(ξ_j − ξ0)² )
//! ```
//!
//! Every term shares `c·ξ0²`, so `F(ξ0) = c·ξ0² + max_j(a_j + b_j·ξ0)` is strictly
//! convex and its minimiser is either the vertex `ξ0 = ξ_j` of one term or a
//! crossing of two terms, `ξ0 = (a_i − a_k)/(b_k − b_i)`. All those candidates
//! (at most 16 + 120) are evaluated and the best kept (the first in index order
//! on ties): exact, deterministic, a bounded number of operations
//! (about 2200 evaluations of a term per obstacle).
//!
//! # Steepness `c`
//!
//! `c` (1/m) sets how fast the forbidden region widens away from the apex: at the
//! apex the boundary's curvature is `2c`, so a car following it at speed `V`
//! has lateral acceleration `2c·V²`. The default `c = 0.02 1/m` keeps that under
//! `0.5·μ·g ≈ 4.9 m/s²` up to about 11 m/s (a 25 m radius); it is a clearance of
//! 2 m gained back in 10 m of `ξ`. [`ObstacleSettings::steepness_for`] gives the
//! `c` that keeps `2cV² = a_y` for a chosen speed.
//!
//! # Side
//!
//! The car passes on the side with more free road: with the half-widths `w_r`,
//! `w_l` at `s_o` (from the path, or [`ObstacleSettings::default_half_width_m`])
//! the free room is `w_l − max η_v` on the left and `min η_v + w_r` on the right
//! (an obstacle across the centre line goes to whichever is larger; left on a
//! tie). The car needs `m_y + half width` (buffer on the obstacle side, the car's
//! half width on the road-edge side). If neither side has it, the road is
//! blocked: [`ObstacleError::RoadBlocked`] says which obstacle and how much room
//! is missing.
//!
//! # Use in the MPC
//!
//! One linearised inequality per obstacle and prediction node:
//! `g(p̄) + ∇g(p̄)·(p − p̄) ≥ 0` (with a slack) from
//! [`Parabola::constraint_value_and_gradient`], `g = σ·(η − η_a) + c·(ξ − ξ0)²`
//! (m), `g ≥ 0` outside (allowed). Rows are only needed where the forbidden region
//! reaches the road: [`Parabola::is_relevant`] (a point) and
//! [`Parabola::is_relevant_at_s`], [`Parabola::overlaps_s_window`] (path
//! abscissae).

use crate::reference_path::ReferencePath;
use crate::velocity_planner::VelocityPlannerSettings;
use crate::Real;
use heapless::Vec;

/// Maximum number of obstacles the manager holds.
pub const MAX_OBSTACLES: usize = 16;
/// Maximum number of vertices of one obstacle polygon.
pub const MAX_VERTICES: usize = 8;
/// Inflated points per obstacle (two per vertex).
const MAX_POINTS: usize = 2 * MAX_VERTICES;

/// Settings of the obstacle manager (units in each field).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObstacleSettings<T> {
    /// Steepness `c` of the parabolas, 1/m (positive); see the module docs.
    pub steepness_1pm: T,
    /// Half the car's width, m.
    pub half_car_width_m: T,
    /// Extra lateral clearance between the car's side and the obstacle, m.
    pub lateral_buffer_m: T,
    /// Half the car's length (longitudinal inflation of the vertices), m.
    pub half_car_length_m: T,
    /// Road half-width on each side used when the path has no widths, m.
    pub default_half_width_m: T,
    /// Gap the car's front keeps to an obstacle that blocks the road when it
    /// stops before it, m.
    pub stop_clearance_m: T,
}

impl<T: Real> Default for ObstacleSettings<T> {
    /// `c = 0.02 1/m`, half width 0.9 m, buffer 0.3 m, half length 2.3 m,
    /// default road half-width 3.5 m, stop clearance 2 m.
    fn default() -> Self {
        Self {
            steepness_1pm: T::lit(0.02),
            half_car_width_m: T::lit(0.9),
            lateral_buffer_m: T::lit(0.3),
            half_car_length_m: T::lit(2.3),
            default_half_width_m: T::lit(3.5),
            stop_clearance_m: T::TWO,
        }
    }
}

impl<T: Real> ObstacleSettings<T> {
    /// Steepness `c = a_y / (2·V²)`, 1/m, such that following the parabola's apex
    /// at `v_mps` (m/s) takes the lateral acceleration `ay_mps2` (m/s²).
    pub fn steepness_for(ay_mps2: T, v_mps: T) -> T {
        ay_mps2 / (T::TWO * v_mps * v_mps)
    }

    /// Settings for a car `width_m` × `length_m` (m) planned up to `v_max_mps` (m/s)
    /// on a road of friction `mu`: skirting a parabola at `v_max_mps` takes a
    /// quarter of `μ·g` of lateral acceleration (half the validity limit, leaving
    /// the rest for the road's own curvature). Other fields as [`Default`].
    pub fn for_vehicle(width_m: T, length_m: T, mu: T, v_max_mps: T) -> Self {
        let ay = T::lit(0.25) * mu * T::lit(crate::G);
        Self {
            steepness_1pm: Self::steepness_for(ay, v_max_mps.max(T::lit(5.0))),
            half_car_width_m: T::HALF * width_m,
            half_car_length_m: T::HALF * length_m,
            ..Self::default()
        }
    }

    /// Lateral inflation `m_y` = half width + buffer, m.
    pub fn lateral_margin_m(&self) -> T {
        self.half_car_width_m + self.lateral_buffer_m
    }

    /// Free road width the car needs beside an obstacle, m: `m_y` + half width.
    pub fn required_room_m(&self) -> T {
        self.lateral_margin_m() + self.half_car_width_m
    }

    fn valid(&self) -> bool {
        let all = [
            self.steepness_1pm,
            self.half_car_width_m,
            self.lateral_buffer_m,
            self.half_car_length_m,
            self.default_half_width_m,
            self.stop_clearance_m,
        ];
        all.iter().all(|v| v.is_finite() && *v >= T::ZERO) && self.steepness_1pm > T::ZERO
    }
}

/// A static obstacle: a polygon in the global frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Obstacle<T> {
    /// Identifier from the obstacle file (the `id` column).
    pub id: u32,
    /// Vertices `[x, y]`, m, in the global frame (any order).
    pub vertices: Vec<[T; 2], MAX_VERTICES>,
    /// Optional path abscissa near the obstacle, m, to pick the right branch of a
    /// path that crosses itself (`None`: global projection).
    pub s_hint_m: Option<T>,
}

impl<T: Real> Obstacle<T> {
    /// An obstacle from its vertices, m; at most [`MAX_VERTICES`].
    pub fn from_vertices(id: u32, vertices: &[[T; 2]]) -> Result<Self, ObstacleError<T>> {
        let v = Vec::from_slice(vertices).map_err(|()| ObstacleError::TooManyVertices {
            obstacle: 0,
            count: vertices.len(),
            capacity: MAX_VERTICES,
        })?;
        Ok(Self {
            id,
            vertices: v,
            s_hint_m: None,
        })
    }
}

/// The side on which the car passes an obstacle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The car passes on the obstacle's left (larger `η`); forbidden region below.
    Left,
    /// The car passes on the obstacle's right (smaller `η`); forbidden region above.
    Right,
}

/// Why obstacles could not all be turned into parabolas. `obstacle` is the
/// index in the slice given to [`ObstacleManager::update`] / [`build_parabola`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ObstacleError<T> {
    /// More obstacles than [`MAX_OBSTACLES`]; the first ones were kept.
    TooManyObstacles {
        /// Number of obstacles given.
        count: usize,
        /// Capacity.
        capacity: usize,
    },
    /// An obstacle has no vertex.
    NoVertices {
        /// Index of the obstacle.
        obstacle: usize,
    },
    /// An obstacle has more than [`MAX_VERTICES`] vertices.
    TooManyVertices {
        /// Index of the obstacle (0 from [`Obstacle::from_vertices`]).
        obstacle: usize,
        /// Number of vertices given.
        count: usize,
        /// Capacity.
        capacity: usize,
    },
    /// A vertex coordinate is NaN or infinite.
    NonFiniteVertex {
        /// Index of the obstacle.
        obstacle: usize,
        /// Index of the vertex in the obstacle.
        vertex: usize,
    },
    /// The reference path is empty.
    PathEmpty,
    /// Settings not finite, negative, or `c ≤ 0`.
    InvalidSettings,
    /// No room for the car on either side of the obstacle.
    RoadBlocked {
        /// Index of the obstacle.
        obstacle: usize,
        /// Free width missing on the roomier side, m (positive).
        missing_m: T,
    },
}

/// The forbidden parabola of one obstacle (all fields read-only in practice).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Parabola<T> {
    /// Index of the obstacle in the slice it was built from.
    pub obstacle: usize,
    /// Identifier of the obstacle.
    pub id: u32,
    /// Path abscissa of the frame origin (closest path point), m, in `[0, L)` on
    /// a closed path.
    pub s_m: T,
    /// Frame origin `o` `[x, y]`, m (global).
    pub origin_m: [T; 2],
    /// Unit tangent `[cos, sin]` of the path heading at `o` (the `ξ` axis).
    pub tangent: [T; 2],
    /// Side on which the car passes.
    pub side: Side,
    /// `ξ` of the apex, m.
    pub xi0_m: T,
    /// `η` of the apex, `η_a`, m (true frame, positive left).
    pub eta_apex_m: T,
    /// Steepness `c`, 1/m.
    pub steepness_1pm: T,
    /// `ξ` range where the forbidden region reaches the road, m (`xi_min ≤ xi_max`).
    pub xi_min_m: T,
    /// Upper end of that range, m.
    pub xi_max_m: T,
    /// False when the forbidden region never reaches the road (the obstacle is off
    /// the road on its side): the MPC can ignore the parabola.
    pub reaches_road: bool,
    /// Largest curvature of the path bending towards the side the car passes on
    /// over the abscissae where the parabola matters ([`Parabola::s_range_m`]),
    /// 1/m, ≥ 0: positive when the obstacle is on the outside of a bend there, where
    /// a car at its lateral limit runs wide towards it (0 on a straight, on the
    /// inside of a bend, or when the parabola does not reach the road). With the
    /// parabola's own `2c` it bounds the curvature of the way round
    /// ([`obstacle_speed_cap`]).
    pub outside_kappa_1pm: T,
    /// True when neither side of the obstacle leaves the car the room it needs
    /// ([`ObstacleError::RoadBlocked`]): the parabola is on the roomier side all
    /// the same, and the car stops before the obstacle ([`obstacle_speed_cap`]).
    pub blocks_road: bool,
    /// `ξ` at which the car's reference point stops before a blocking obstacle, m:
    /// the nearest vertex's `ξ` less half the car's length and
    /// [`ObstacleSettings::stop_clearance_m`]. Meaningful when `blocks_road`.
    pub stop_xi_m: T,
}

impl<T: Real> Parabola<T> {
    /// `σ = +1` ([`Side::Left`]) or `−1` ([`Side::Right`]).
    pub fn sigma(&self) -> T {
        match self.side {
            Side::Left => T::ONE,
            Side::Right => -T::ONE,
        }
    }

    /// Coordinates `(ξ, η)` of the global point `p` in the parabola's frame, m.
    pub fn to_local(&self, p: [T; 2]) -> (T, T) {
        let dx = p[0] - self.origin_m[0];
        let dy = p[1] - self.origin_m[1];
        let t = self.tangent;
        (t[0] * dx + t[1] * dy, -t[1] * dx + t[0] * dy)
    }

    /// `g(p) = σ·(η − η_a) + c·(ξ − ξ0)²`, m, and its gradient
    /// `[∂g/∂X, ∂g/∂Y]` (dimensionless) at the global point `p` (m).
    /// `g ≥ 0` outside the parabola (allowed), `g < 0` inside (forbidden).
    pub fn constraint_value_and_gradient(&self, p: [T; 2]) -> (T, [T; 2]) {
        let (xi, eta) = self.to_local(p);
        let sigma = self.sigma();
        let c = self.steepness_1pm;
        let dxi = xi - self.xi0_m;
        let g = sigma * (eta - self.eta_apex_m) + c * dxi * dxi;
        // ∇ξ = t, ∇η = n = [−t_y, t_x].
        let t = self.tangent;
        let k = T::TWO * c * dxi;
        (g, [k * t[0] - sigma * t[1], k * t[1] + sigma * t[0]])
    }

    /// The constraint linearised at the global point `p_bar` (m), as a half-plane
    /// `n·p ≥ r` in the global position `p = [X, Y]`: returns `(n, r)` with
    /// `n = ∇g(p̄)` (dimensionless) and `r = ∇g(p̄)·p̄ − g(p̄)` (m). The MPC adds
    /// its slack to the left-hand side. `g` is convex in `p`, so the half-plane is
    /// conservative: every point it allows is outside the parabola.
    pub fn linearized_half_plane(&self, p_bar: [T; 2]) -> ([T; 2], T) {
        let (g, n) = self.constraint_value_and_gradient(p_bar);
        (n, n[0] * p_bar[0] + n[1] * p_bar[1] - g)
    }

    /// True when the global point `p` (m) is strictly inside the forbidden region.
    pub fn contains(&self, p: [T; 2]) -> bool {
        self.constraint_value_and_gradient(p).0 < T::ZERO
    }

    /// True when a constraint row is needed at the global point `p` (m): the
    /// forbidden region reaches the road at the `ξ` of `p` and the obstacle does
    /// not block the road.
    pub fn is_relevant(&self, p: [T; 2]) -> bool {
        let (xi, _) = self.to_local(p);
        self.has_rows() && xi >= self.xi_min_m && xi <= self.xi_max_m
    }

    /// True when the parabola adds constraint rows anywhere: it reaches the road
    /// and does not block it (a blocked road has no way round to constrain; the
    /// speed cap stops the car).
    fn has_rows(&self) -> bool {
        self.reaches_road && !self.blocks_road
    }

    /// Path abscissae `[s_begin, s_end]`, m, where the parabola matters
    /// (`s_m + ξ_min .. s_m + ξ_max`, using `ξ ≈ s − s_m`, which holds near the
    /// origin of a gently curved path).
    pub fn s_range_m(&self) -> (T, T) {
        (self.s_m + self.xi_min_m, self.s_m + self.xi_max_m)
    }

    /// True when a node at path abscissa `s_node_m` (m, any lap of a closed path)
    /// needs a constraint row for this parabola: never for one that blocks the
    /// road (there is no way round to constrain; the speed cap stops the car).
    pub fn is_relevant_at_s<const CAP: usize>(
        &self,
        path: &ReferencePath<T, CAP>,
        s_node_m: T,
    ) -> bool {
        self.relevant_s_at(path, s_node_m).is_some()
    }

    /// `Some(path.unwrap_s(s_node_m, self.s_m))` when [`Self::is_relevant_at_s`]
    /// holds (the unwrapped node abscissa, m, from one `unwrap_s`), else `None`.
    pub fn relevant_s_at<const CAP: usize>(
        &self,
        path: &ReferencePath<T, CAP>,
        s_node_m: T,
    ) -> Option<T> {
        if !self.has_rows() {
            return None;
        }
        let s = path.unwrap_s(s_node_m, self.s_m);
        let (a, b) = self.s_range_m();
        if s >= a && s <= b {
            Some(s)
        } else {
            None
        }
    }

    /// True when the parabola matters anywhere in the horizon window
    /// `[s0_m, s1_m]` (m, any lap; `s0 ≤ s1`, shorter than a lap).
    pub fn overlaps_s_window<const CAP: usize>(
        &self,
        path: &ReferencePath<T, CAP>,
        s0_m: T,
        s1_m: T,
    ) -> bool {
        if !self.reaches_road {
            return false;
        }
        let (a, b) = self.s_range_m();
        let s0 = path.unwrap_s(s0_m, self.s_m);
        let s1 = s0 + (s1_m - s0_m);
        let l = if path.is_closed() {
            path.length_m()
        } else {
            T::ZERO
        };
        [-l, T::ZERO, l]
            .iter()
            .any(|shift| s0 <= b + *shift && s1 >= a + *shift)
    }
}

/// Speed cap near obstacles on the outside of a bend, m/s (`+∞` when none): the
/// car at path abscissa `s_node_m` (m) and speed `v_now_mps` (m/s) previews the
/// same distance as the velocity planner
/// ([`VelocityPlannerSettings::preview_distance_m`]). A parabola in that window
/// ([`Parabola::overlaps_s_window`]) that pushes the MPC's lateral reference off the
/// centre line (its forbidden side reaches `η = 0` with the reference's buffer
/// `offset_buffer_m`, m) makes the car swerve, towards the inside of the bend when
/// the obstacle is on its outside; that way round bends up to `κ_out + 2c` (the
/// road's sharpest bend towards the passing side, [`Parabola::outside_kappa_1pm`],
/// plus the boundary's own curvature `2c`), and the cap is the speed at which that
/// curvature takes `ay_limit_mps2` (m/s², the validity limit's `a_y,frac·μ·g`):
/// `sqrt(a_y,lim/(κ_out + 2c))`.
///
/// Why: `V_heur` spends most of the lateral budget on the road's curvature and the
/// parabolas' steepness takes another quarter of `μ·g` at `V_max`
/// ([`ObstacleSettings::for_vehicle`]); in a fast bend the two together exceed the
/// validity limit, the plan can swerve only as far as `δ_max(V)` allows, and the
/// car at the edge of its tyres runs wide, into an obstacle on the outside. An
/// obstacle on the inside of a bend is left on the side the car drifts away from;
/// on a straight the cap is above `V_max`; an obstacle that needs no swerve caps
/// nothing.
///
/// An obstacle that blocks the road ([`Parabola::blocks_road`]) has no way round:
/// it caps the speed so that the car stops before it (`stop_curve`).
pub fn obstacle_speed_cap<T: Real, const CAP: usize>(
    velocity: &VelocityPlannerSettings<T>,
    path: &ReferencePath<T, CAP>,
    parabolas: &[Parabola<T>],
    s_node_m: T,
    v_now_mps: T,
    ay_limit_mps2: T,
    offset_buffer_m: T,
) -> T {
    let d = velocity.preview_distance_m(v_now_mps.max(T::ZERO));
    let mut cap = T::INFINITY;
    // WCET: the only caller (the MPC step, from `PlanTask`) passes
    // `ObstacleManager::parabolas()`, a `Vec` of capacity MAX_OBSTACLES.
    // wcet-bound: MAX_OBSTACLES
    for o in parabolas {
        // (One path back to the loop's head, no `continue`: see
        // `PlanTask::rebuild_obstacles`.)
        if o.blocks_road {
            cap = cap.min(stop_curve(path, o, s_node_m, ay_limit_mps2));
        } else {
            let swerve = match o.side {
                Side::Left => o.eta_apex_m + offset_buffer_m > T::ZERO,
                Side::Right => o.eta_apex_m - offset_buffer_m < T::ZERO,
            };
            if swerve && o.overlaps_s_window(path, s_node_m, s_node_m + d) {
                let kappa = o.outside_kappa_1pm + T::TWO * o.steepness_1pm;
                if kappa > T::ZERO {
                    cap = cap.min((ay_limit_mps2.max(T::ZERO) / kappa).sqrt());
                }
            }
        }
    }
    cap
}

/// Speed cap before an obstacle that blocks the road, m/s: the speed from which
/// braking at `decel_mps2` (m/s², the validity limit's `a_y,frac·μ·g`, so that
/// braking takes no more of the tyres than cornering may) stops the car at the
/// parabola's [`Parabola::stop_xi_m`], `sqrt(2·a·(s_stop − s))`, and 0 from there to
/// the far end of the parabola's range; `+∞` at a node past that (on a closed
/// path, the node's abscissa is taken on the lap nearest the obstacle).
fn stop_curve<T: Real, const CAP: usize>(
    path: &ReferencePath<T, CAP>,
    o: &Parabola<T>,
    s_node_m: T,
    decel_mps2: T,
) -> T {
    let s = path.unwrap_s(s_node_m, o.s_m);
    if s > o.s_m + o.xi_max_m.max(o.stop_xi_m) {
        return T::INFINITY;
    }
    let gap = (o.s_m + o.stop_xi_m - s).max(T::ZERO);
    (T::TWO * decel_mps2.max(T::ZERO) * gap).sqrt()
}

/// Free-function form of [`Parabola::constraint_value_and_gradient`]: `g` (m,
/// `≥ 0` allowed) and `[∂g/∂X, ∂g/∂Y]` at the global point `p` (m).
pub fn constraint_value_and_gradient<T: Real>(parabola: &Parabola<T>, p: [T; 2]) -> (T, [T; 2]) {
    parabola.constraint_value_and_gradient(p)
}

/// Minimal apex over `ξ0`: returns `(ξ0, A)` minimising
/// `F(ξ0) = max_j (e_j + c·(ξ_j − ξ0)²)` over the points `(ξ_j, e_j)`, exactly
/// (candidates: the vertices of the terms and the crossings of pairs of terms).
/// `None` for no points.
///
/// Not inlined: its pair loop is bounded per call (a triangle of pairs).
#[inline(never)]
pub fn minimal_apex<T: Real>(points: &[(T, T)], c: T) -> Option<(T, T)> {
    let f = |x0: T| {
        let mut m = -T::INFINITY;
        // WCET: `points` is `build_inner`'s `pts` (its only caller), a `Vec` of capacity
        // MAX_POINTS = 2 * MAX_VERTICES; every loop of this function walks it.
        // wcet-bound: 2 * MAX_VERTICES
        for &(xi, e) in points {
            let d = xi - x0;
            m = m.max(e + c * d * d);
        }
        m
    };
    let mut best: Option<(T, T)> = None;
    let mut consider = |x0: T| {
        if !x0.is_finite() {
            return;
        }
        let v = f(x0);
        // WCET: loops the compiler closes on this line walk `points` (<= 2 * MAX_VERTICES).
        // wcet-bound: 2 * MAX_VERTICES
        let better = match best {
            None => true,
            Some((_, bv)) => v < bv,
        };
        if better {
            best = Some((x0, v));
        }
    };
    // wcet-bound: 2 * MAX_VERTICES
    for &(xi, _) in points {
        consider(xi);
    }
    // wcet-bound: 2 * MAX_VERTICES
    for (i, &(xi, ei)) in points.iter().enumerate() {
        // Each pair once: n(n − 1)/2 for n ≤ 2·MAX_VERTICES points, per call.
        // wcet-bound: 2 * MAX_VERTICES * (2 * MAX_VERTICES - 1) / 2 per call
        for &(xk, ek) in points.iter().skip(i + 1) {
            // The compiler makes the path of a zero `dx`, which skips the loop's
            // head, a binary loop of its own nested in it: their back edges
            // together are the loop's iterations.
            // wcet-bound: same loop
            let dx = xi - xk;
            if dx != T::ZERO {
                // e_i + c(ξ_i − x)² = e_k + c(ξ_k − x)²  ⇔  x = ((e_i − e_k) + c(ξ_i² − ξ_k²)) / (2c(ξ_i − ξ_k))
                let num = (ei - ek) + c * (xi * xi - xk * xk);
                consider(num / (T::TWO * c * dx));
            }
        }
    }
    best
}

/// Builds the parabola of one obstacle (index `obstacle` for error reports)
/// against `path`; see the module docs for the construction.
///
/// A blocked road returns [`ObstacleError::RoadBlocked`] together with nothing;
/// use [`ObstacleManager::update`] to keep a best-effort parabola in that case.
pub fn build_parabola<T: Real, const CAP: usize>(
    settings: &ObstacleSettings<T>,
    path: &ReferencePath<T, CAP>,
    obstacle: usize,
    o: &Obstacle<T>,
) -> Result<Parabola<T>, ObstacleError<T>> {
    let (p, blocked) = build_inner(settings, path, obstacle, o)?;
    match blocked {
        Some(missing_m) => Err(ObstacleError::RoadBlocked {
            obstacle,
            missing_m,
        }),
        None => Ok(p),
    }
}

/// The parabola (on the roomier side even when blocked) and the missing room if blocked.
fn build_inner<T: Real, const CAP: usize>(
    settings: &ObstacleSettings<T>,
    path: &ReferencePath<T, CAP>,
    obstacle: usize,
    o: &Obstacle<T>,
) -> Result<(Parabola<T>, Option<T>), ObstacleError<T>> {
    if !settings.valid() {
        return Err(ObstacleError::InvalidSettings);
    }
    if path.is_empty() {
        return Err(ObstacleError::PathEmpty);
    }
    let verts = &o.vertices;
    if verts.is_empty() {
        return Err(ObstacleError::NoVertices { obstacle });
    }
    let mut cx = T::ZERO;
    let mut cy = T::ZERO;
    // WCET: `o.vertices` is a `Vec` of capacity MAX_VERTICES.
    // wcet-bound: MAX_VERTICES
    for (k, v) in verts.iter().enumerate() {
        if !v[0].is_finite() || !v[1].is_finite() {
            return Err(ObstacleError::NonFiniteVertex {
                obstacle,
                vertex: k,
            });
        }
        cx += v[0];
        cy += v[1];
    }
    let nv = T::from_usize(verts.len());
    let centroid = [cx / nv, cy / nv];
    let pc = path
        .project(centroid, o.s_hint_m)
        .ok_or(ObstacleError::PathEmpty)?;
    // Closest path point: the vertex nearest the path if all are on one side.
    let mut s_o = pc.s_m;
    let mut all_left = true;
    let mut all_right = true;
    let mut best_abs = T::INFINITY;
    let mut best_s = pc.s_m;
    // Every vertex on the one search window of the centroid's projection.
    let each: [Option<(T, T)>; MAX_VERTICES] = path.project_each(verts, pc.s_m);
    // wcet-bound: MAX_VERTICES
    for &(s_m, lateral_m) in each.iter().take(verts.len()).flatten() {
        all_left &= lateral_m > T::ZERO;
        all_right &= lateral_m < T::ZERO;
        if lateral_m.abs() < best_abs {
            best_abs = lateral_m.abs();
            best_s = s_m;
        }
    }
    if all_left || all_right {
        s_o = best_s;
    }
    let s_o = path.wrap_s(s_o);
    let origin = path.position_at(s_o);
    let (sh, ch) = path.heading_at(s_o).sin_cos();
    let tangent = [ch, sh];
    let (w_r, w_l) = match path.widths_at(s_o) {
        Some(w) => (w.right_m, w.left_m),
        None => (settings.default_half_width_m, settings.default_half_width_m),
    };
    let mut frame = Parabola {
        obstacle,
        id: o.id,
        s_m: s_o,
        origin_m: origin,
        tangent,
        side: Side::Left,
        xi0_m: T::ZERO,
        eta_apex_m: T::ZERO,
        steepness_1pm: settings.steepness_1pm,
        xi_min_m: T::ZERO,
        xi_max_m: T::ZERO,
        reaches_road: false,
        outside_kappa_1pm: T::ZERO,
        blocks_road: false,
        stop_xi_m: T::ZERO,
    };
    // Local coordinates of the vertices and the lateral extent.
    let mut local: Vec<(T, T), MAX_VERTICES> = Vec::new();
    let mut eta_min = T::INFINITY;
    let mut eta_max = -T::INFINITY;
    // wcet-bound: MAX_VERTICES
    for v in verts.iter() {
        let (xi, eta) = frame.to_local(*v);
        eta_min = eta_min.min(eta);
        eta_max = eta_max.max(eta);
        // Capacity equals the vertex capacity: cannot fail.
        let _ = local.push((xi, eta));
    }
    let room_left = w_l - eta_max;
    let room_right = eta_min + w_r;
    let (side, room) = if room_left >= room_right {
        (Side::Left, room_left)
    } else {
        (Side::Right, room_right)
    };
    let need = settings.required_room_m();
    let blocked = if room < need { Some(need - room) } else { None };
    frame.side = side;
    let sigma = frame.sigma();
    let m_y = settings.lateral_margin_m();
    let m_x = settings.half_car_length_m;
    let mut pts: Vec<(T, T), MAX_POINTS> = Vec::new();
    let mut xi_near = T::INFINITY;
    // WCET: `local` is a `Vec` of capacity MAX_VERTICES.
    // wcet-bound: MAX_VERTICES
    for &(xi, eta) in local.iter() {
        let e = sigma * eta + m_y;
        let _ = pts.push((xi - m_x, e));
        let _ = pts.push((xi + m_x, e));
        xi_near = xi_near.min(xi);
    }
    frame.blocks_road = blocked.is_some();
    frame.stop_xi_m = xi_near - m_x - settings.stop_clearance_m;
    let c = settings.steepness_1pm;
    let (xi0, a) = minimal_apex(&pts, c).ok_or(ObstacleError::NoVertices { obstacle })?;
    frame.xi0_m = xi0;
    frame.eta_apex_m = sigma * a;
    // Where the forbidden region reaches the road edge on the obstacle's side.
    let w_far = match side {
        Side::Left => w_r,
        Side::Right => w_l,
    };
    let depth = a + w_far;
    if depth > T::ZERO {
        let r = (depth / c).sqrt();
        frame.xi_min_m = xi0 - r;
        frame.xi_max_m = xi0 + r;
        frame.reaches_road = true;
        // How sharply the road bends towards the side the car passes on (the
        // obstacle on the outside of the bend) where the parabola matters.
        frame.outside_kappa_1pm = path
            .max_signed_curvature_between(s_o + frame.xi_min_m, s_o + frame.xi_max_m, sigma)
            .max(T::ZERO);
    } else {
        frame.xi_min_m = xi0;
        frame.xi_max_m = xi0;
    }
    Ok((frame, blocked))
}

/// The parabolas of the current obstacles (fixed capacity [`MAX_OBSTACLES`]).
#[derive(Clone, Debug)]
pub struct ObstacleManager<T> {
    parabolas: Vec<Parabola<T>, MAX_OBSTACLES>,
}

impl<T: Real> Default for ObstacleManager<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> ObstacleManager<T> {
    /// No obstacles; a valid `const` initialiser.
    pub const fn new() -> Self {
        Self {
            parabolas: Vec::new(),
        }
    }

    /// Rebuilds the parabolas of `obstacles` against `path`.
    ///
    /// Every obstacle that can be processed gets a parabola, including a blocked
    /// one (on its roomier side, marked [`Parabola::blocks_road`]: it adds no
    /// constraint row, and caps the speed to stop the car before it). Returns the
    /// first error met (by obstacle index);
    /// obstacles beyond [`MAX_OBSTACLES`] are dropped and reported.
    pub fn update<const CAP: usize>(
        &mut self,
        settings: &ObstacleSettings<T>,
        path: &ReferencePath<T, CAP>,
        obstacles: &[Obstacle<T>],
    ) -> Result<(), ObstacleError<T>> {
        self.parabolas.clear();
        let mut first_err = None;
        if obstacles.len() > MAX_OBSTACLES {
            first_err = Some(ObstacleError::TooManyObstacles {
                count: obstacles.len(),
                capacity: MAX_OBSTACLES,
            });
        }
        // wcet-bound: MAX_OBSTACLES
        for (k, o) in obstacles.iter().enumerate().take(MAX_OBSTACLES) {
            match build_inner(settings, path, k, o) {
                Ok((p, blocked)) => {
                    let _ = self.parabolas.push(p);
                    if let (Some(missing_m), None) = (blocked, first_err) {
                        first_err = Some(ObstacleError::RoadBlocked {
                            obstacle: k,
                            missing_m,
                        });
                    }
                }
                Err(e) => {
                    if first_err.is_none() {
                        first_err = Some(e);
                    }
                }
            }
        }
        match first_err {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// The parabolas built by the last [`Self::update`].
    pub fn parabolas(&self) -> &[Parabola<T>] {
        &self.parabolas
    }

    /// Removes every parabola.
    pub fn clear(&mut self) {
        self.parabolas.clear();
    }
}
