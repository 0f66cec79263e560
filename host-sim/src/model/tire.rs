//! Tyre forces: Pacejka's 2002 Magic Formula (PAC2002), combined slip, camber 0.
//!
//! The equations are those of H. B. Pacejka, *Tire and Vehicle Dynamics*, 2nd ed.
//! (2006), §4.3.2 (pure slip `F_x0`, `F_y0`) and the combined-slip weighting functions
//! `G_xα`, `G_yκ` with the lateral shift `S_Vyκ`. Turn slip is ignored (`ζ_i = 1`),
//! camber is zero. Coefficients are named as in a PAC2002 `.tir` file, in lower case.
//!
//! # Sign conventions
//!
//! `.tir` coefficient sets are written in the ISO (TYDEX W-axis) convention, where a
//! positive slip angle makes a negative lateral force (so `pky1 < 0`). This project
//! uses the opposite slip-angle sign: `α > 0` when the wheel points to the left of its
//! velocity, and then `F_y > 0` (to the left). [`forces`] takes `α` in this project's
//! convention and evaluates the Magic Formula at `α_ISO = −α`; the forces come out in
//! the tyre frame, x forward along the wheel heading, y to its left, which is the same
//! in both conventions. `κ > 0` when the wheel turns faster than it rolls (driving),
//! and then `F_x > 0`.
//!
//! # Deviations from the book, all documented
//!
//! * The book's `α* = tan α` is replaced by `α` itself (they agree within 1 % below
//!   10°; `tan α` diverges at 90°, which a car sliding sideways at a standstill
//!   reaches).
//! * The road friction scales the peaks: `λ_μx = μ·lmux`, `λ_μy = μ·lmuy`, and the
//!   vertical shifts use the same `λ_μ` (the book's `λ'_μ = λ_μ` at constant speed).
//! * Inputs outside any fit are clamped: `κ` to `±100`, `α` to `±π/2`, and the load
//!   used for the load-dependent coefficients (`df_z`) to at most 10× the nominal load.
//!   The combined-slip weights are clamped at 0 so that a force never reverses sign
//!   at extreme combined slip.
//! * The combined force is projected onto the friction ellipse whose half-axes are
//!   the pure-slip peaks `|D_x| + |S_Vx|`, `|D_y| + |S_Vy|` when it falls outside it
//!   (the paper's Equation 5, `‖F_xp + F_yp‖ ≤ μ‖F_z‖`). The book's weights `G_xα`,
//!   `G_yκ` do not depend on `μ`; without this the combined force of the book's tyre
//!   exceeds the pure-slip peaks by up to 25 % at `μ = 0.3` (2 % at `μ = 1`).
//!
//! # Speed and determinism
//!
//! A combined-slip evaluation calls 9 `atan`, 3 `sin` and 4 `cos` (13 `atan` if the
//! weights' curvatures `E` were not 0; they are for the book's tyre, which skips
//! their inner `atan`), and the plant one more `atan` and an `exp` per wheel: the C
//! library's functions are about two thirds of the plant's instructions, and no
//! identity removes one of them exactly (the shape factors `C` are not integers;
//! `cos(atan(x)) = 1/sqrt(1 + x²)` is used where `C = 1`). They form seven
//! independent chains (`atan`, a second `atan` for a curved one, then `sin` or
//! `cos`); [`AtLoad::forces`] calls them in rounds, the first `atan` of every chain,
//! then the second ones, then the sines and cosines, so that the processor overlaps
//! independent calls instead of waiting for each chain to end. The operations and
//! their operands are those of the one-chain-at-a-time formulas, so the forces are
//! the same bit for bit; the plant runs about 1.3× faster for it (300,000 steps of
//! the plant benchmark in 0.64 s of CPU time instead of 0.82 s).
//!
//! The functions are `f64`'s methods, i.e. the platform's C library (glibc on Linux),
//! not the portable `libm` crate that the firmware uses: measured in this plant, the
//! `libm` crate is no faster (0.81 s for both), and it differs in the last bit for
//! about 5 % of `atan` and 3 % of `sin`, `cos` arguments in `[−3, 3]`, which moved the
//! end state of a 10 s trajectory by about 1e-15 (relative). Keeping the C library
//! keeps every recorded result. The price: the plant is deterministic bit for bit on
//! one machine with one C library, but another glibc version (or another of its
//! CPU-dispatched variants, e.g. with or without FMA) may change the last bits; the
//! plant's reference test allows a relative 1e-9 for that
//! (`host-sim/tests/plant_physics.rs`).

use serde::Deserialize;

/// PAC2002 Magic Formula coefficients for longitudinal and lateral force (camber 0).
///
/// In a TOML vehicle file these live in the `[tyre]` table. A coefficient that is not
/// given is 0; a scaling factor (`l…`) that is not given is 1; `fnomin` is required.
/// Coefficients are dimensionless unless stated; their meaning is that of the `.tir`
/// file entry of the same (upper-case) name.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TireParams {
    /// Nominal (rated) load `F_z0`, N.
    pub fnomin: f64,
    /// Shape factor `C_fx`.
    #[serde(default)]
    pub pcx1: f64,
    /// Longitudinal friction `μ_x` at nominal load.
    #[serde(default)]
    pub pdx1: f64,
    /// Variation of friction `μ_x` with load.
    #[serde(default)]
    pub pdx2: f64,
    /// Variation of friction `μ_x` with camber squared (unused: camber 0).
    #[serde(default)]
    pub pdx3: f64,
    /// Longitudinal curvature `E_fx` at nominal load.
    #[serde(default)]
    pub pex1: f64,
    /// Variation of curvature `E_fx` with load.
    #[serde(default)]
    pub pex2: f64,
    /// Variation of curvature `E_fx` with load squared.
    #[serde(default)]
    pub pex3: f64,
    /// Factor in curvature `E_fx` while driving.
    #[serde(default)]
    pub pex4: f64,
    /// Longitudinal slip stiffness `K_fx/F_z` at nominal load.
    #[serde(default)]
    pub pkx1: f64,
    /// Variation of slip stiffness `K_fx/F_z` with load.
    #[serde(default)]
    pub pkx2: f64,
    /// Exponent in slip stiffness `K_fx/F_z` with load.
    #[serde(default)]
    pub pkx3: f64,
    /// Horizontal shift `S_hx` at nominal load.
    #[serde(default)]
    pub phx1: f64,
    /// Variation of shift `S_hx` with load.
    #[serde(default)]
    pub phx2: f64,
    /// Vertical shift `S_vx/F_z` at nominal load.
    #[serde(default)]
    pub pvx1: f64,
    /// Variation of shift `S_vx/F_z` with load.
    #[serde(default)]
    pub pvx2: f64,
    /// Slope factor for combined slip `F_x` reduction.
    #[serde(default)]
    pub rbx1: f64,
    /// Variation of slope `F_x` reduction with `κ`.
    #[serde(default)]
    pub rbx2: f64,
    /// Shape factor for combined slip `F_x` reduction.
    #[serde(default)]
    pub rcx1: f64,
    /// Curvature factor of combined `F_x`.
    #[serde(default)]
    pub rex1: f64,
    /// Curvature factor of combined `F_x` with load.
    #[serde(default)]
    pub rex2: f64,
    /// Shift factor for combined slip `F_x` reduction, rad.
    #[serde(default)]
    pub rhx1: f64,
    /// Shape factor `C_fy`.
    #[serde(default)]
    pub pcy1: f64,
    /// Lateral friction `μ_y` at nominal load.
    #[serde(default)]
    pub pdy1: f64,
    /// Variation of friction `μ_y` with load.
    #[serde(default)]
    pub pdy2: f64,
    /// Variation of friction `μ_y` with camber squared (unused: camber 0).
    #[serde(default)]
    pub pdy3: f64,
    /// Lateral curvature `E_fy` at nominal load.
    #[serde(default)]
    pub pey1: f64,
    /// Variation of curvature `E_fy` with load.
    #[serde(default)]
    pub pey2: f64,
    /// Zero-order camber dependency of curvature `E_fy` (here: asymmetry with the
    /// sign of the slip angle).
    #[serde(default)]
    pub pey3: f64,
    /// Variation of curvature `E_fy` with camber (unused: camber 0).
    #[serde(default)]
    pub pey4: f64,
    /// Maximum value of stiffness `K_fy/F_z0`.
    #[serde(default)]
    pub pky1: f64,
    /// Load at which `K_fy` reaches its maximum, in units of `F_z0`.
    #[serde(default)]
    pub pky2: f64,
    /// Variation of `K_fy/F_z0` with camber (unused: camber 0).
    #[serde(default)]
    pub pky3: f64,
    /// Horizontal shift `S_hy` at nominal load, rad.
    #[serde(default)]
    pub phy1: f64,
    /// Variation of shift `S_hy` with load, rad.
    #[serde(default)]
    pub phy2: f64,
    /// Variation of shift `S_hy` with camber (unused: camber 0).
    #[serde(default)]
    pub phy3: f64,
    /// Vertical shift `S_vy/F_z` at nominal load.
    #[serde(default)]
    pub pvy1: f64,
    /// Variation of shift `S_vy/F_z` with load.
    #[serde(default)]
    pub pvy2: f64,
    /// Variation of shift `S_vy/F_z` with camber (unused: camber 0).
    #[serde(default)]
    pub pvy3: f64,
    /// Variation of shift `S_vy/F_z` with camber and load (unused: camber 0).
    #[serde(default)]
    pub pvy4: f64,
    /// Slope factor for combined `F_y` reduction.
    #[serde(default)]
    pub rby1: f64,
    /// Variation of slope `F_y` reduction with `α`.
    #[serde(default)]
    pub rby2: f64,
    /// Shift term for `α` in slope `F_y` reduction, rad.
    #[serde(default)]
    pub rby3: f64,
    /// Shape factor for combined `F_y` reduction.
    #[serde(default)]
    pub rcy1: f64,
    /// Curvature factor of combined `F_y`.
    #[serde(default)]
    pub rey1: f64,
    /// Curvature factor of combined `F_y` with load.
    #[serde(default)]
    pub rey2: f64,
    /// Shift factor for combined `F_y` reduction.
    #[serde(default)]
    pub rhy1: f64,
    /// Shift factor for combined `F_y` reduction with load.
    #[serde(default)]
    pub rhy2: f64,
    /// `κ`-induced side force `S_vyκ/μ_y/F_z` at nominal load.
    #[serde(default)]
    pub rvy1: f64,
    /// Variation of `S_vyκ/μ_y/F_z` with load.
    #[serde(default)]
    pub rvy2: f64,
    /// Variation of `S_vyκ/μ_y/F_z` with camber (unused: camber 0).
    #[serde(default)]
    pub rvy3: f64,
    /// Variation of `S_vyκ/μ_y/F_z` with `α`.
    #[serde(default)]
    pub rvy4: f64,
    /// Variation of `S_vyκ/μ_y/F_z` with `κ`.
    #[serde(default)]
    pub rvy5: f64,
    /// Variation of `S_vyκ/μ_y/F_z` with `atan(κ)`.
    #[serde(default)]
    pub rvy6: f64,
    /// Scale factor of nominal (rated) load.
    #[serde(default = "one")]
    pub lfzo: f64,
    /// Scale factor of `F_x` shape factor.
    #[serde(default = "one")]
    pub lcx: f64,
    /// Scale factor of `F_x` peak friction coefficient (multiplied by the road `μ`).
    #[serde(default = "one")]
    pub lmux: f64,
    /// Scale factor of `F_x` curvature factor.
    #[serde(default = "one")]
    pub lex: f64,
    /// Scale factor of `F_x` slip stiffness.
    #[serde(default = "one")]
    pub lkx: f64,
    /// Scale factor of `F_x` horizontal shift.
    #[serde(default = "one")]
    pub lhx: f64,
    /// Scale factor of `F_x` vertical shift.
    #[serde(default = "one")]
    pub lvx: f64,
    /// Scale factor of `F_y` shape factor.
    #[serde(default = "one")]
    pub lcy: f64,
    /// Scale factor of `F_y` peak friction coefficient (multiplied by the road `μ`).
    #[serde(default = "one")]
    pub lmuy: f64,
    /// Scale factor of `F_y` curvature factor.
    #[serde(default = "one")]
    pub ley: f64,
    /// Scale factor of `F_y` cornering stiffness.
    #[serde(default = "one")]
    pub lky: f64,
    /// Scale factor of `F_y` horizontal shift.
    #[serde(default = "one")]
    pub lhy: f64,
    /// Scale factor of `F_y` vertical shift.
    #[serde(default = "one")]
    pub lvy: f64,
    /// Scale factor of `α` influence on `F_x` (combined slip).
    #[serde(default = "one")]
    pub lxal: f64,
    /// Scale factor of `κ` influence on `F_y` (combined slip).
    #[serde(default = "one")]
    pub lyka: f64,
    /// Scale factor of `κ`-induced side force `S_vyκ`.
    #[serde(default = "one")]
    pub lvyka: f64,
}

fn one() -> f64 {
    1.0
}

impl Default for TireParams {
    /// The 205/60R15 passenger-car tyre of Pacejka, *Tire and Vehicle Dynamics*,
    /// 2nd ed. (2006), Appendix 3, Table A3.1 (ISO signs, 2.2 bar). Scaling factors 1.
    fn default() -> Self {
        Self {
            fnomin: 4000.0,
            pcx1: 1.685,
            pdx1: 1.210,
            pdx2: -0.037,
            pdx3: 0.0,
            pex1: 0.344,
            pex2: 0.095,
            pex3: -0.020,
            pex4: 0.0,
            pkx1: 21.51,
            pkx2: -0.163,
            pkx3: 0.245,
            phx1: -0.002,
            phx2: 0.002,
            pvx1: 0.0,
            pvx2: 0.0,
            rbx1: 12.35,
            rbx2: -10.77,
            rcx1: 1.092,
            rex1: 0.0,
            rex2: 0.0,
            rhx1: 0.007,
            pcy1: 1.193,
            pdy1: -0.990,
            pdy2: 0.145,
            pdy3: -11.23,
            pey1: -1.003,
            pey2: -0.537,
            pey3: -0.083,
            pey4: -4.787,
            pky1: -14.95,
            pky2: 2.130,
            pky3: -0.028,
            phy1: 0.003,
            phy2: -0.001,
            phy3: 0.0,
            pvy1: 0.045,
            pvy2: -0.024,
            pvy3: -0.532,
            pvy4: 0.039,
            rby1: 6.461,
            rby2: 4.196,
            rby3: -0.015,
            rcy1: 1.081,
            rey1: 0.0,
            rey2: 0.0,
            rhy1: 0.009,
            rhy2: 0.0,
            rvy1: 0.053,
            rvy2: -0.073,
            rvy3: 0.517,
            rvy4: 35.44,
            rvy5: 1.9,
            rvy6: -10.71,
            lfzo: 1.0,
            lcx: 1.0,
            lmux: 1.0,
            lex: 1.0,
            lkx: 1.0,
            lhx: 1.0,
            lvx: 1.0,
            lcy: 1.0,
            lmuy: 1.0,
            ley: 1.0,
            lky: 1.0,
            lhy: 1.0,
            lvy: 1.0,
            lxal: 1.0,
            lyka: 1.0,
            lvyka: 1.0,
        }
    }
}

impl TireParams {
    /// Every coefficient by its `.tir` name (lower case), for validation messages.
    pub fn named_values(&self) -> [(&'static str, f64); 70] {
        [
            ("fnomin", self.fnomin),
            ("pcx1", self.pcx1),
            ("pdx1", self.pdx1),
            ("pdx2", self.pdx2),
            ("pdx3", self.pdx3),
            ("pex1", self.pex1),
            ("pex2", self.pex2),
            ("pex3", self.pex3),
            ("pex4", self.pex4),
            ("pkx1", self.pkx1),
            ("pkx2", self.pkx2),
            ("pkx3", self.pkx3),
            ("phx1", self.phx1),
            ("phx2", self.phx2),
            ("pvx1", self.pvx1),
            ("pvx2", self.pvx2),
            ("rbx1", self.rbx1),
            ("rbx2", self.rbx2),
            ("rcx1", self.rcx1),
            ("rex1", self.rex1),
            ("rex2", self.rex2),
            ("rhx1", self.rhx1),
            ("pcy1", self.pcy1),
            ("pdy1", self.pdy1),
            ("pdy2", self.pdy2),
            ("pdy3", self.pdy3),
            ("pey1", self.pey1),
            ("pey2", self.pey2),
            ("pey3", self.pey3),
            ("pey4", self.pey4),
            ("pky1", self.pky1),
            ("pky2", self.pky2),
            ("pky3", self.pky3),
            ("phy1", self.phy1),
            ("phy2", self.phy2),
            ("phy3", self.phy3),
            ("pvy1", self.pvy1),
            ("pvy2", self.pvy2),
            ("pvy3", self.pvy3),
            ("pvy4", self.pvy4),
            ("rby1", self.rby1),
            ("rby2", self.rby2),
            ("rby3", self.rby3),
            ("rcy1", self.rcy1),
            ("rey1", self.rey1),
            ("rey2", self.rey2),
            ("rhy1", self.rhy1),
            ("rhy2", self.rhy2),
            ("rvy1", self.rvy1),
            ("rvy2", self.rvy2),
            ("rvy3", self.rvy3),
            ("rvy4", self.rvy4),
            ("rvy5", self.rvy5),
            ("rvy6", self.rvy6),
            ("lfzo", self.lfzo),
            ("lcx", self.lcx),
            ("lmux", self.lmux),
            ("lex", self.lex),
            ("lkx", self.lkx),
            ("lhx", self.lhx),
            ("lvx", self.lvx),
            ("lcy", self.lcy),
            ("lmuy", self.lmuy),
            ("ley", self.ley),
            ("lky", self.lky),
            ("lhy", self.lhy),
            ("lvy", self.lvy),
            ("lxal", self.lxal),
            ("lyka", self.lyka),
            ("lvyka", self.lvyka),
        ]
    }

    /// Scaled nominal load `F'_z0 = fnomin·lfzo`, N.
    pub fn nominal_load_n(&self) -> f64 {
        self.fnomin * self.lfzo
    }

    /// Normalised load change `df_z = (F_z − F'_z0)/F'_z0` at load `fz_n` (N), with
    /// the load clamped to `[0, 10·F'_z0]`.
    fn dfz(&self, fz_n: f64) -> f64 {
        let fz0 = self.nominal_load_n();
        (fz_n.clamp(0.0, 10.0 * fz0) - fz0) / fz0
    }

    /// Longitudinal slip stiffness `K_xκ = ∂F_x/∂κ` at `κ = 0` and load `fz_n` (N),
    /// N per unit slip (absolute value).
    pub fn longitudinal_slip_stiffness_n(&self, fz_n: f64) -> f64 {
        if fz_n.is_nan() || fz_n <= 0.0 {
            return 0.0;
        }
        let dfz = self.dfz(fz_n);
        let k = fz_n.min(10.0 * self.nominal_load_n())
            * (self.pkx1 + self.pkx2 * dfz)
            * (self.pkx3 * dfz).exp()
            * self.lkx;
        if k.is_finite() {
            k.abs()
        } else {
            0.0
        }
    }

    /// Largest cornering stiffness `|K_yα|` over all loads, N/rad: `|pky1|·F'_z0·lky`.
    pub fn max_cornering_stiffness_n_per_rad(&self) -> f64 {
        (self.pky1 * self.nominal_load_n() * self.lky).abs()
    }
}

/// Sign with `sgn(0) = 0`.
fn sgn(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// `cos(atan(x))`, exactly `1/sqrt(1 + x²)`.
fn cos_atan(x: f64) -> f64 {
    1.0 / (1.0 + x * x).sqrt()
}

/// `b/d`, or 0 when `d` is too small to divide by.
/// `(F_x, F_y)` projected back onto the friction ellipse whose half-axes are the
/// pure-slip peaks `peak_x`, `peak_y` (N) when it lies outside it; `(0, 0)` if not
/// finite.
fn onto_friction_ellipse(fx: f64, fy: f64, peak_x: f64, peak_y: f64) -> (f64, f64) {
    let (fx, fy) = if peak_x > 0.0 && peak_y > 0.0 {
        let e = (fx / peak_x).powi(2) + (fy / peak_y).powi(2);
        if e > 1.0 {
            let k = 1.0 / e.sqrt();
            (fx * k, fy * k)
        } else {
            (fx, fy)
        }
    } else {
        (fx, fy)
    };
    if fx.is_finite() && fy.is_finite() {
        (fx, fy)
    } else {
        (0.0, 0.0)
    }
}

fn safe_div(b: f64, d: f64) -> f64 {
    if d.abs() > 1e-12 {
        b / d
    } else {
        0.0
    }
}

/// One Magic Formula curve `atan(B·x − E·(B·x − atan(B·x)))` at a given `B·x` and
/// `E`, in two steps (the inner and the outer `atan`) so that the caller can
/// interleave independent curves.
#[derive(Clone, Copy, Debug)]
struct Curve {
    /// `B·x`.
    bx: f64,
    /// Curvature `E`.
    e: f64,
}

impl Curve {
    fn new(bx: f64, e: f64) -> Self {
        Self { bx, e }
    }

    /// With `E = 0` the curve is `B·x` exactly (for a finite `B·x`,
    /// `0·(B·x − atan(B·x))` is a zero), so the inner `atan` is skipped.
    fn straight(&self) -> bool {
        self.e == 0.0 && self.bx.is_finite()
    }

    /// The first `atan` of the curve: `atan(B·x)`, which is the curve's value when
    /// it is straight.
    fn first_atan(&self) -> f64 {
        self.bx.atan()
    }

    /// `atan(B·x − E·(B·x − atan(B·x)))` given `first = atan(B·x)`.
    fn value(&self, first: f64) -> f64 {
        let bx = self.bx;
        if self.straight() {
            first
        } else {
            (bx - self.e * (bx - first)).atan()
        }
    }
}

/// The pure-slip Magic Formulas' arguments.
#[derive(Clone, Copy, Debug)]
struct PureArgs {
    x: Curve,
    svx: f64,
    y: Curve,
    svy: f64,
}

impl PureArgs {
    /// `[F_x0, F_y0, |D_x| + |S_Vx|, |D_y| + |S_Vy|]` given the outer `atan`s: the
    /// Magic Formula `D·sin(C·atan(…)) + S_V`.
    fn forces(&self, at: &AtLoad<'_>, ox: f64, oy: f64) -> [f64; 4] {
        let fx0 = at.dx * (at.cx * ox).sin() + self.svx;
        let fy0 = at.dy * (at.cy * oy).sin() + self.svy;
        [
            fx0,
            fy0,
            at.dx.abs() + self.svx.abs(),
            at.dy.abs() + self.svy.abs(),
        ]
    }
}

/// Combined-slip tyre forces `(F_x, F_y)` in the tyre frame, N.
///
/// * `kappa`: longitudinal slip ratio (positive when driving);
/// * `alpha_rad`: slip angle, rad (positive when the wheel points left of its velocity);
/// * `fz_n`: normal load, N (no force when `≤ 0`);
/// * `mu`: road friction coefficient (1 = the tyre's reference surface).
///
/// Pure function; finite for every input (non-finite inputs give `(0, 0)`).
pub fn forces(kappa: f64, alpha_rad: f64, fz_n: f64, mu: f64, p: &TireParams) -> (f64, f64) {
    forces_with_offset_scale(kappa, alpha_rad, fz_n, mu, 1.0, p)
}

/// [`forces`] with the Magic Formula's offsets (the shifts `S_Hx`, `S_Vx`, `S_Hy`,
/// `S_Vy` and `S_Vyκ`, i.e. conicity, ply steer and rolling offsets) multiplied by
/// `offset_scale` (clamped to `[0, 1]`). The plant fades them out near standstill, so
/// that a tyre at rest with no slip makes exactly no force, N.
pub fn forces_with_offset_scale(
    kappa: f64,
    alpha_rad: f64,
    fz_n: f64,
    mu: f64,
    offset_scale: f64,
    p: &TireParams,
) -> (f64, f64) {
    evaluate(kappa, alpha_rad, fz_n, mu, offset_scale, p, true)
}

/// Pure-slip forces `(F_x0(κ), F_y0(α))`, N: the longitudinal force as if `α = 0`
/// and the lateral force as if `κ = 0`, before the combined-slip weighting. Same
/// arguments and conventions as [`forces`].
pub fn pure_slip_forces(
    kappa: f64,
    alpha_rad: f64,
    fz_n: f64,
    mu: f64,
    p: &TireParams,
) -> (f64, f64) {
    evaluate(kappa, alpha_rad, fz_n, mu, 1.0, p, false)
}

fn evaluate(
    kappa: f64,
    alpha_rad: f64,
    fz_n: f64,
    mu: f64,
    offset_scale: f64,
    p: &TireParams,
    combined: bool,
) -> (f64, f64) {
    match AtLoad::new(fz_n, mu, p) {
        Some(at) if combined => at.forces(kappa, alpha_rad, offset_scale),
        Some(at) => at.pure_slip_forces(kappa, alpha_rad, offset_scale),
        None => (0.0, 0.0),
    }
}

/// The Magic Formula's coefficients at one normal load and road friction: the part
/// of [`forces`] that does not depend on the slips, computed once and shared by the
/// slip-ratio floor ([`AtLoad::slip_stiffness_n`]) and the forces of one evaluation.
/// Splitting it off changes no operation: the forces are bit for bit those of
/// [`forces_with_offset_scale`].
#[derive(Clone, Copy, Debug)]
pub struct AtLoad<'a> {
    p: &'a TireParams,
    /// Normal load `F_z`, N.
    fz: f64,
    /// Normalised load change `df_z`.
    dfz: f64,
    /// `λ_μx = μ·lmux`.
    lmux: f64,
    /// `λ_μy = μ·lmuy`.
    lmuy: f64,
    /// Shape factor `C_x`.
    cx: f64,
    /// Peak `D_x`, N.
    dx: f64,
    /// Slip stiffness `K_xκ`, N.
    kxk: f64,
    /// Stiffness factor `B_x`.
    bx: f64,
    /// Shape factor `C_y`.
    cy: f64,
    /// Friction `μ_y`.
    muy: f64,
    /// Peak `D_y`, N.
    dy: f64,
    /// Stiffness factor `B_y`.
    by: f64,
}

impl<'a> AtLoad<'a> {
    /// The coefficients at load `fz_n` (N) and friction `mu`; `None` when the tyre
    /// makes no force (no load, no friction, or a non-finite input).
    pub fn new(fz_n: f64, mu: f64, p: &'a TireParams) -> Option<Self> {
        let usable = fz_n > 0.0 && mu > 0.0 && fz_n.is_finite() && mu.is_finite();
        if !usable {
            return None;
        }
        let fz0 = p.nominal_load_n();
        let dfz = p.dfz(fz_n);
        let fz_coef = fz_n.min(10.0 * fz0);
        let lmux = mu * p.lmux;
        let lmuy = mu * p.lmuy;
        let cx = p.pcx1 * p.lcx;
        let mux = (p.pdx1 + p.pdx2 * dfz) * lmux;
        let dx = mux * fz_n;
        let kxk = fz_coef * (p.pkx1 + p.pkx2 * dfz) * (p.pkx3 * dfz).exp() * p.lkx;
        let bx = safe_div(kxk, cx * dx) * fz_n / fz_coef;
        let cy = p.pcy1 * p.lcy;
        let muy = (p.pdy1 + p.pdy2 * dfz) * lmuy;
        let dy = muy * fz_n;
        // sin(2·atan(u)) = 2u/(1+u²).
        let u = safe_div(fz_coef, p.pky2 * fz0);
        let kya = p.pky1 * fz0 * (2.0 * u / (1.0 + u * u)) * p.lky;
        let by = safe_div(kya, cy * dy);
        Some(Self {
            p,
            fz: fz_n,
            dfz,
            lmux,
            lmuy,
            cx,
            dx,
            kxk,
            bx,
            cy,
            muy,
            dy,
            by,
        })
    }

    /// Longitudinal slip stiffness `|K_xκ|` at this load, N per unit slip: the value
    /// of [`TireParams::longitudinal_slip_stiffness_n`], without a second `exp`.
    pub fn slip_stiffness_n(&self) -> f64 {
        if self.kxk.is_finite() {
            self.kxk.abs()
        } else {
            0.0
        }
    }

    /// The pure-slip Magic Formulas' arguments at the slips `kappa`, `a` (ISO) with
    /// the offset scale `s`.
    fn pure_args(&self, kappa: f64, a: f64, s: f64) -> PureArgs {
        let (p, fz_n, dfz) = (self.p, self.fz, self.dfz);
        // Longitudinal force, pure slip (4.E9-4.E18).
        let shx = (p.phx1 + p.phx2 * dfz) * p.lhx * s;
        let kx = kappa + shx;
        let ex = ((p.pex1 + p.pex2 * dfz + p.pex3 * dfz * dfz) * (1.0 - p.pex4 * sgn(kx)) * p.lex)
            .min(1.0);
        let svx = fz_n * (p.pvx1 + p.pvx2 * dfz) * p.lvx * self.lmux * s;
        // Lateral force, pure slip (4.E19-4.E30), camber 0.
        let shy = (p.phy1 + p.phy2 * dfz) * p.lhy * s;
        let ay = a + shy;
        let ey = ((p.pey1 + p.pey2 * dfz) * (1.0 - p.pey3 * sgn(ay)) * p.ley).min(1.0);
        let svy = fz_n * (p.pvy1 + p.pvy2 * dfz) * p.lvy * self.lmuy * s;
        PureArgs {
            x: Curve::new(self.bx * kx, ex),
            svx,
            y: Curve::new(self.by * ay, ey),
            svy,
        }
    }

    /// Pure-slip forces `(F_x0, F_y0)` with their peaks `(|D_x| + |S_Vx|, |D_y| + |S_Vy|)`.
    fn pure(&self, kappa: f64, a: f64, s: f64) -> [f64; 4] {
        let q = self.pure_args(kappa, a, s);
        let (ix, iy) = (q.x.first_atan(), q.y.first_atan());
        let (ox, oy) = (q.x.value(ix), q.y.value(iy));
        q.forces(self, ox, oy)
    }

    /// Clamped slips and offset scale, or `None` for a non-finite input.
    fn inputs(kappa: f64, alpha_rad: f64, offset_scale: f64) -> Option<(f64, f64, f64)> {
        if !(kappa.is_finite() && alpha_rad.is_finite() && offset_scale.is_finite()) {
            return None;
        }
        let s = offset_scale.clamp(0.0, 1.0);
        let kappa = kappa.clamp(-100.0, 100.0);
        // ISO slip angle (see the module documentation).
        let a = -alpha_rad.clamp(-core::f64::consts::FRAC_PI_2, core::f64::consts::FRAC_PI_2);
        Some((kappa, a, s))
    }

    /// Pure-slip forces (see [`pure_slip_forces`]), N.
    pub fn pure_slip_forces(&self, kappa: f64, alpha_rad: f64, offset_scale: f64) -> (f64, f64) {
        let Some((kappa, a, s)) = Self::inputs(kappa, alpha_rad, offset_scale) else {
            return (0.0, 0.0);
        };
        let [fx0, fy0, _, _] = self.pure(kappa, a, s);
        if fx0.is_finite() && fy0.is_finite() {
            (fx0, fy0)
        } else {
            (0.0, 0.0)
        }
    }

    /// Combined-slip forces (see [`forces_with_offset_scale`]), N.
    pub fn forces(&self, kappa: f64, alpha_rad: f64, offset_scale: f64) -> (f64, f64) {
        let Some((kappa, a, s)) = Self::inputs(kappa, alpha_rad, offset_scale) else {
            return (0.0, 0.0);
        };
        let (p, fz_n, dfz) = (self.p, self.fz, self.dfz);
        let q = self.pure_args(kappa, a, s);

        // Longitudinal force, combined slip (4.E51-4.E57).
        let shxa = p.rhx1;
        let exa = (p.rex1 + p.rex2 * dfz).min(1.0);
        let bxa = p.rbx1 * cos_atan(p.rbx2 * kappa) * p.lxal;
        let wx0 = Curve::new(bxa * shxa, exa);
        let wx = Curve::new(bxa * (a + shxa), exa);

        // Lateral force, combined slip (4.E58-4.E67).
        let dvyk = self.muy * fz_n * (p.rvy1 + p.rvy2 * dfz) * cos_atan(p.rvy4 * a);
        let shyk = p.rhy1 + p.rhy2 * dfz;
        let eyk = (p.rey1 + p.rey2 * dfz).min(1.0);
        let byk = p.rby1 * cos_atan(p.rby2 * (a - p.rby3)) * p.lyka;
        let wy0 = Curve::new(byk * shyk, eyk);
        let wy = Curve::new(byk * (kappa + shyk), eyk);

        // The transcendental functions, independent chains side by side so that the
        // processor can overlap them (the same operations on the same values as one
        // chain after the other: the order of independent calls changes no result).
        let (ix, iy) = (q.x.first_atan(), q.y.first_atan());
        let (ix0, ixa, iy0, iyk) = (
            wx0.first_atan(),
            wx.first_atan(),
            wy0.first_atan(),
            wy.first_atan(),
        );
        // 0·sin(·)·λ·s when dvyk = 0: the same zero without the atan and the sine.
        let tk = if dvyk == 0.0 {
            0.0
        } else {
            (p.rvy6 * kappa).atan()
        };
        let (ox, oy) = (q.x.value(ix), q.y.value(iy));
        let (ox0, oxa, oy0, oyk) = (wx0.value(ix0), wx.value(ixa), wy0.value(iy0), wy.value(iyk));
        let gxa0 = (p.rcx1 * ox0).cos();
        let gxa_num = (p.rcx1 * oxa).cos();
        let gyk0 = (p.rcy1 * oy0).cos();
        let gyk_num = (p.rcy1 * oyk).cos();
        let svyk = if dvyk == 0.0 {
            0.0
        } else {
            dvyk * (p.rvy5 * tk).sin() * p.lvyka * s
        };
        let [fx0, fy0, peak_x, peak_y] = q.forces(self, ox, oy);

        let gxa = safe_div(gxa_num, gxa0).max(0.0);
        let fx = gxa * fx0;
        let gyk = safe_div(gyk_num, gyk0).max(0.0);
        let fy = gyk * fy0 + svyk;

        // Friction ellipse (the paper's Equation 5): the weights G are fitted at μ = 1
        // and do not depend on μ, so on a slippery road the combined force could exceed
        // the pure-slip peaks (by up to 25 % at μ = 0.3 with the book's tyre). Project
        // such a force back onto the ellipse whose half-axes are the pure-slip peaks.
        onto_friction_ellipse(fx, fy, peak_x, peak_y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signs_follow_the_project_convention() {
        let p = TireParams::default();
        let (fx, _) = forces(0.05, 0.0, 4000.0, 1.0, &p);
        assert!(fx > 0.0);
        let (fx, _) = forces(-0.05, 0.0, 4000.0, 1.0, &p);
        assert!(fx < 0.0);
        let (_, fy) = forces(0.0, 0.05, 4000.0, 1.0, &p);
        assert!(fy > 0.0);
        let (_, fy) = forces(0.0, -0.05, 4000.0, 1.0, &p);
        assert!(fy < 0.0);
    }

    #[test]
    fn no_load_or_bad_input_gives_no_force() {
        let p = TireParams::default();
        assert_eq!(forces(0.1, 0.1, 0.0, 1.0, &p), (0.0, 0.0));
        assert_eq!(forces(f64::NAN, 0.1, 4000.0, 1.0, &p), (0.0, 0.0));
        assert_eq!(forces(0.1, 0.1, f64::INFINITY, 1.0, &p), (0.0, 0.0));
        let (fx, fy) = forces(1e300, -1e300, 1e12, 1.0, &p);
        assert!(fx.is_finite() && fy.is_finite());
    }

    /// The Magic Formula one chain at a time, as written before the calls were
    /// interleaved: `D·sin(C·atan(B·x − E·(B·x − atan(B·x))))`.
    fn magic(b: f64, c: f64, d: f64, e: f64, x: f64) -> f64 {
        d * (c * curved(b * x, e).atan()).sin()
    }

    /// `cos(C·atan(B·x − E·(B·x − atan(B·x))))`.
    fn weight(b: f64, c: f64, e: f64, x: f64) -> f64 {
        (c * curved(b * x, e).atan()).cos()
    }

    fn curved(bx: f64, e: f64) -> f64 {
        if e == 0.0 && bx.is_finite() {
            bx
        } else {
            bx - e * (bx - bx.atan())
        }
    }

    /// [`AtLoad::forces`] one chain after the other (the formulas as printed).
    fn forces_one_chain(at: &AtLoad<'_>, kappa: f64, alpha: f64, scale: f64) -> (f64, f64) {
        let Some((kappa, a, s)) = AtLoad::inputs(kappa, alpha, scale) else {
            return (0.0, 0.0);
        };
        let (p, fz_n, dfz) = (at.p, at.fz, at.dfz);
        let shx = (p.phx1 + p.phx2 * dfz) * p.lhx * s;
        let kx = kappa + shx;
        let ex = ((p.pex1 + p.pex2 * dfz + p.pex3 * dfz * dfz) * (1.0 - p.pex4 * sgn(kx)) * p.lex)
            .min(1.0);
        let svx = fz_n * (p.pvx1 + p.pvx2 * dfz) * p.lvx * at.lmux * s;
        let fx0 = magic(at.bx, at.cx, at.dx, ex, kx) + svx;
        let shy = (p.phy1 + p.phy2 * dfz) * p.lhy * s;
        let ay = a + shy;
        let ey = ((p.pey1 + p.pey2 * dfz) * (1.0 - p.pey3 * sgn(ay)) * p.ley).min(1.0);
        let svy = fz_n * (p.pvy1 + p.pvy2 * dfz) * p.lvy * at.lmuy * s;
        let fy0 = magic(at.by, at.cy, at.dy, ey, ay) + svy;
        let (peak_x, peak_y) = (at.dx.abs() + svx.abs(), at.dy.abs() + svy.abs());
        let exa = (p.rex1 + p.rex2 * dfz).min(1.0);
        let bxa = p.rbx1 * cos_atan(p.rbx2 * kappa) * p.lxal;
        let gxa0 = weight(bxa, p.rcx1, exa, p.rhx1);
        let fx = safe_div(weight(bxa, p.rcx1, exa, a + p.rhx1), gxa0).max(0.0) * fx0;
        let dvyk = at.muy * fz_n * (p.rvy1 + p.rvy2 * dfz) * cos_atan(p.rvy4 * a);
        let svyk = if dvyk == 0.0 {
            0.0
        } else {
            dvyk * (p.rvy5 * (p.rvy6 * kappa).atan()).sin() * p.lvyka * s
        };
        let shyk = p.rhy1 + p.rhy2 * dfz;
        let eyk = (p.rey1 + p.rey2 * dfz).min(1.0);
        let byk = p.rby1 * cos_atan(p.rby2 * (a - p.rby3)) * p.lyka;
        let gyk0 = weight(byk, p.rcy1, eyk, shyk);
        let fy = safe_div(weight(byk, p.rcy1, eyk, kappa + shyk), gyk0).max(0.0) * fy0 + svyk;
        onto_friction_ellipse(fx, fy, peak_x, peak_y)
    }

    /// Interleaving the transcendental calls changes no bit of the forces: the book's
    /// tyre (straight weights), one with curved weights (`E ≠ 0`, the inner `atan`
    /// of every curve) and one without the `κ`-induced side force (`D_Vyκ = 0`).
    #[test]
    fn interleaved_calls_give_the_forces_of_one_chain_at_a_time_bit_for_bit() {
        let book = TireParams::default();
        let curved_weights = TireParams {
            rex1: 0.3,
            rex2: -0.1,
            rey1: -0.4,
            rey2: 0.2,
            ..book
        };
        let no_svyk = TireParams {
            rvy1: 0.0,
            rvy2: 0.0,
            ..book
        };
        let mut n = 0;
        for p in [book, curved_weights, no_svyk] {
            for fz in [300.0, 2500.0, 4000.0, 9000.0] {
                for mu in [0.3, 1.0] {
                    let Some(at) = AtLoad::new(fz, mu, &p) else {
                        continue; // never: a loaded tyre on a road (n counts the forces)
                    };
                    for i in 0..=40 {
                        let kappa = -1.0 + 0.05 * f64::from(i);
                        for j in 0..=30 {
                            let alpha = -0.6 + 0.04 * f64::from(j);
                            for scale in [0.0, 0.4, 1.0] {
                                let got = at.forces(kappa, alpha, scale);
                                let want = forces_one_chain(&at, kappa, alpha, scale);
                                assert_eq!(
                                    (got.0.to_bits(), got.1.to_bits()),
                                    (want.0.to_bits(), want.1.to_bits()),
                                    "fz={fz} mu={mu} kappa={kappa} alpha={alpha} s={scale}"
                                );
                                n += usize::from(got.0 != 0.0 || got.1 != 0.0);
                            }
                        }
                    }
                }
            }
        }
        // Forces, not zeros, were compared.
        assert!(n > 20_000, "{n}");
    }

    #[test]
    fn offsets_fade_to_exactly_zero_force() {
        let p = TireParams::default();
        assert_eq!(
            forces_with_offset_scale(0.0, 0.0, 4000.0, 1.0, 0.0, &p),
            (0.0, 0.0)
        );
        let (fx, fy) = forces(0.0, 0.0, 4000.0, 1.0, &p);
        assert!(fx != 0.0 || fy != 0.0, "the book tyre has offsets");
    }
}
