//! The software-in-the-loop (SITL) plant: a rigid-body Crazyflie CF2X quadrotor in f64.
//!
//! State convention (the paper's): position `p` in the world frame (m, z up), rotation `R`
//! (body → world), linear velocity `v` and angular velocity `ω` in the **body** frame.
//!
//! Equations of motion (body frame, `e₃ = [0,0,1]`):
//!
//! ```text
//! ṗ = R v
//! Ṙ = R ω̂
//! m v̇ = m v × ω + Rᵀ(−m g e₃ + m w) + f e₃ (+ rotor drag)
//! J ω̇ = J ω × ω + τ
//! ```
//!
//! with `w` the world-frame wind as a specific force (m/s²) and `[f; τ]` the wrench of the four
//! rotors. Rotor numbering (as on the Crazyflie): 1 front-right (+x, −y), 2 back-right (−x, −y),
//! 3 back-left (−x, +y), 4 front-left (+x, +y). Rotor `i` at speed `ωᵢ` (rpm) makes thrust
//! `δᵢ kf ωᵢ²` along body z and reaction torque `δᵢ sᵢ km ωᵢ²` about body z with
//! `s = (−, +, −, +)`; `δᵢ` is its efficiency (1 nominal): the disturbance's
//! ([`Disturbance::rotor_efficiency`]) times the vehicle's own ([`VehicleParams::rotor_efficiency`]).
//!
//! Integration: a Runge–Kutta–Munthe-Kaas RK4 step on SE(3) × ℝ⁶ — classical RK4 on
//! `(p, v, ω, rotor speeds)` while the attitude moves by the exponential map `R = R₀ exp(θ̂)` with
//! `θ̇ = dexp⁻¹_{−θ}(ω)`. `R` stays orthonormal to rounding error without any projection.
//! The rotor command is held (zero-order hold) across each call of [`Plant::step`].

use nalgebra::{Matrix3, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Body positions (x, y) in units of the arm offset `a` of rotors 1..4.
pub const ROTOR_XY_SIGN: [[f64; 2]; 4] = [[1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]];
/// Sign of each rotor's reaction torque about body z (rotors 1..4).
pub const ROTOR_YAW_SIGN: [f64; 4] = [-1.0, 1.0, -1.0, 1.0];

/// Physical constants of the vehicle (defaults: the CF2X of gym-pybullet-drones).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VehicleParams {
    /// Mass m (kg).
    pub mass_kg: f64,
    /// Gravitational acceleration g (m/s²).
    pub gravity_m_s2: f64,
    /// Principal moments of inertia diag(J) (kg·m²).
    pub inertia_kg_m2: [f64; 3],
    /// Rotor offset along each body axis in the X layout (m): props at (±a, ±a).
    pub arm_xy_m: f64,
    /// Thrust coefficient kf (N/rpm²).
    pub kf_n_per_rpm2: f64,
    /// Reaction-torque coefficient km (N·m/rpm²).
    pub km_nm_per_rpm2: f64,
    /// Maximum total thrust over weight (dimensionless); sets the rotor speed limit.
    pub thrust_to_weight: f64,
    /// Propeller radius (m), for the ground-effect model.
    pub prop_radius_m: f64,
    /// Rotor drag coefficients (x, y, z) of gym-pybullet-drones, N per (m/s · rad/s).
    pub drag_coeff: [f64; 3],
    /// Ground-effect coefficient of gym-pybullet-drones (dimensionless).
    pub ground_effect_coeff: f64,
    /// The vehicle's own rotor efficiencies (worn or chipped props, a weak motor): rotor i makes
    /// this share of its nominal thrust and reaction torque, at all times, on top of any
    /// [`Disturbance::rotor_efficiency`] (the two multiply). All 1 for the CF2X.
    #[serde(default = "unit_efficiency")]
    pub rotor_efficiency: [f64; 4],
}

fn unit_efficiency() -> [f64; 4] {
    [1.0; 4]
}

impl Default for VehicleParams {
    fn default() -> Self {
        Self::cf2x()
    }
}

impl VehicleParams {
    /// The Crazyflie CF2X constants (docs/design.md, "The vehicle").
    pub fn cf2x() -> Self {
        Self {
            mass_kg: 0.027,
            gravity_m_s2: 9.8,
            inertia_kg_m2: [1.4e-5, 1.4e-5, 2.17e-5],
            arm_xy_m: 0.028,
            kf_n_per_rpm2: 3.16e-10,
            km_nm_per_rpm2: 7.94e-12,
            thrust_to_weight: 2.25,
            prop_radius_m: 2.31348e-2,
            drag_coeff: [9.1785e-7, 9.1785e-7, 10.311e-7],
            ground_effect_coeff: 11.36859,
            rotor_efficiency: [1.0; 4],
        }
    }

    /// Weight m·g (N).
    pub fn weight_n(&self) -> f64 {
        self.mass_kg * self.gravity_m_s2
    }

    /// Inertia matrix J (kg·m²).
    pub fn inertia(&self) -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vector3::from(self.inertia_kg_m2))
    }

    /// Maximum rotor speed (rpm), from the thrust-to-weight ratio (≈ 21,700 rpm for the CF2X).
    pub fn max_rpm(&self) -> f64 {
        (self.thrust_to_weight * self.weight_n() / (4.0 * self.kf_n_per_rpm2)).sqrt()
    }

    /// Rotor speed (rpm) at which four nominal rotors carry the weight (≈ 14,470 rpm).
    pub fn hover_rpm(&self) -> f64 {
        (self.weight_n() / (4.0 * self.kf_n_per_rpm2)).sqrt()
    }

    /// Clamp a rotor command to `[0, max_rpm]` (non-finite entries become 0).
    pub fn clamp_rpm(&self, rpm: [f64; 4]) -> [f64; 4] {
        let max = self.max_rpm();
        rpm.map(|r| {
            if r.is_finite() {
                r.clamp(0.0, max)
            } else {
                0.0
            }
        })
    }

    /// Nominal wrench `u = [f; τx; τy; τz]` (N, N·m, N·m, N·m) of a rotor command (rpm),
    /// after clamping, with all efficiencies 1 and no optional effects.
    pub fn nominal_wrench(&self, rpm: [f64; 4]) -> [f64; 4] {
        let rpm = self.clamp_rpm(rpm);
        self.wrench_of_rpm_squared(rpm.map(|r| r * r))
    }

    /// Nominal wrench `u = [f; τx; τy; τz]` of squared rotor speeds (rpm², not clamped): linear
    /// in them, so it also gives the wrench of a time average of ωᵢ².
    pub fn wrench_of_rpm_squared(&self, rpm_sq: [f64; 4]) -> [f64; 4] {
        let a = self.arm_xy_m;
        let mut u = [0.0; 4];
        for (i, &s) in rpm_sq.iter().enumerate() {
            let t = self.kf_n_per_rpm2 * s;
            u[0] += t;
            u[1] += ROTOR_XY_SIGN[i][1] * a * t;
            u[2] -= ROTOR_XY_SIGN[i][0] * a * t;
            u[3] += ROTOR_YAW_SIGN[i] * self.km_nm_per_rpm2 * s;
        }
        u
    }

    /// Unsaturated inverse of [`VehicleParams::nominal_wrench`]: the squared rotor speeds (rpm²)
    /// that produce `u = [f; τx; τy; τz]` exactly (entries may be negative or above the limit).
    pub fn wrench_to_rpm_squared(&self, u: [f64; 4]) -> [f64; 4] {
        let (kf, km, a) = (self.kf_n_per_rpm2, self.km_nm_per_rpm2, self.arm_xy_m);
        let mut s = [0.0; 4];
        for (i, si) in s.iter_mut().enumerate() {
            *si = 0.25
                * (u[0] / kf + ROTOR_XY_SIGN[i][1] * u[1] / (a * kf)
                    - ROTOR_XY_SIGN[i][0] * u[2] / (a * kf)
                    + ROTOR_YAW_SIGN[i] * u[3] / km);
        }
        s
    }

    /// Wrench → rotor speeds (rpm) through the nominal mixer inverse, with saturation that keeps
    /// attitude authority: yaw torque is given up first, then roll/pitch torque is scaled down, and
    /// the collective thrust is shifted last so that every rotor stays in `[0, max_rpm]`.
    /// Exact (equal to the unsaturated inverse) whenever that is feasible.
    pub fn wrench_to_rpm(&self, u: [f64; 4]) -> [f64; 4] {
        let u = u.map(|x| if x.is_finite() { x } else { 0.0 });
        let smax = self.max_rpm().powi(2);
        let base = (u[0] / (4.0 * self.kf_n_per_rpm2)).max(0.0);
        let rp = self.wrench_to_rpm_squared([0.0, u[1], u[2], 0.0]);
        let yw = self.wrench_to_rpm_squared([0.0, 0.0, 0.0, u[3]]);
        let range = |d: &[f64; 4]| {
            let mx = d.iter().cloned().fold(f64::MIN, f64::max);
            let mn = d.iter().cloned().fold(f64::MAX, f64::min);
            mx - mn
        };
        let comb = |k: f64| -> [f64; 4] { core::array::from_fn(|i| rp[i] + k * yw[i]) };
        let d = if range(&rp) > smax {
            let k = smax / range(&rp);
            rp.map(|x| x * k)
        } else if range(&comb(1.0)) > smax {
            // Largest yaw share that fits, by bisection.
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..30 {
                let mid = 0.5 * (lo + hi);
                if range(&comb(mid)) > smax {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            comb(lo)
        } else {
            comb(1.0)
        };
        let mx = d.iter().cloned().fold(f64::MIN, f64::max);
        let mn = d.iter().cloned().fold(f64::MAX, f64::min);
        let lo = -mn;
        let hi = smax - mx;
        let b = if lo <= hi {
            base.clamp(lo, hi)
        } else {
            0.5 * (lo + hi)
        };
        d.map(|x| (b + x).clamp(0.0, smax).sqrt())
    }
}

/// Optional measurement noise: zero-mean Gaussian, standard deviations per quantity. Applied to
/// the state the controller sees, never to the simulated truth.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StateNoise {
    /// Position noise σ (m).
    pub pos_m: f64,
    /// Body linear-velocity noise σ (m/s).
    pub vel_m_s: f64,
    /// Attitude noise σ (rad), applied as a random rotation about each body axis.
    pub att_rad: f64,
    /// Body angular-rate noise σ (rad/s).
    pub rate_rad_s: f64,
    /// Accelerometer noise σ (m/s², per axis), on [`Plant::accelerometer`]'s reading.
    pub acc_m_s2: f64,
}

impl StateNoise {
    /// True if every σ of the state (not the accelerometer) is zero.
    pub fn is_off(&self) -> bool {
        self.pos_m == 0.0 && self.vel_m_s == 0.0 && self.att_rad == 0.0 && self.rate_rad_s == 0.0
    }
}

/// Optional physical effects; all off by default.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Effects {
    /// Rotor drag of gym-pybullet-drones: body force `−c ⊙ v · Σ ωᵢ` (ωᵢ in rad/s).
    pub rotor_drag: bool,
    /// Ground effect of gym-pybullet-drones: extra thrust `kf ω² C (r_p / 4h)²` per rotor at
    /// height h (clipped below as in gym-pybullet-drones).
    pub ground_effect: bool,
    /// First-order motor time constant (s); 0 turns motor lag off (rotors follow the command).
    pub motor_tau_s: f64,
    /// Measurement noise on the state given to the controller.
    pub noise: StateNoise,
    /// Extra dynamics measured on a real vehicle's flights ([`Residual`]); none by default.
    pub residual: Option<Residual>,
}

/// What a real vehicle's flights show beyond the rigid body with its rotors (the measured-input
/// response that `host-train fit-response` fits on logged flights; the same fields): the rotor
/// wrench acts through first-order lags and with effective gains, and the body gets an
/// acceleration linear in the body velocity, a constant one and an angular one linear in the
/// tilt. A plant with it is the flight check's stand-in for the real vehicle: the rigid body
/// of the vehicle description plus what its logs measured, which is not the blob's model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Residual {
    /// The thrust's effective gain.
    pub thrust_gain: f64,
    /// Each body torque's effective gain (roll, pitch, yaw).
    pub torque_gain: [f64; 3],
    /// The torques' first-order lag (s).
    pub torque_lag_s: f64,
    /// Body acceleration per unit of ζ = (v (m/s), ω (rad/s)), row-major 6×6 (rows v̇, ω̇).
    pub accel_per_velocity: [[f64; 6]; 6],
    /// Constant body acceleration, v̇ (m/s²) then ω̇ (rad/s²).
    pub accel_bias: [f64; 6],
    /// The thrust's first-order lag (s).
    #[serde(default)]
    pub thrust_lag_s: f64,
    /// Body angular acceleration (rad/s²) per unit of the world vertical's body x and y
    /// components, row-major 3×2 (rows ω̇ₓ, ω̇ᵧ, ω̇_z).
    #[serde(default)]
    pub accel_per_tilt: [[f64; 2]; 3],
}

/// External disturbance: world wind force and per-rotor efficiency.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Disturbance {
    /// Wind as a world-frame specific force w (m/s²): the force on the body is m·w.
    pub wind_m_s2: [f64; 3],
    /// Time (s) from which the wind acts.
    pub wind_onset_s: f64,
    /// Rotor efficiencies δ₁..δ₄: rotor i makes δᵢ of its nominal thrust and reaction torque.
    pub rotor_efficiency: [f64; 4],
    /// Time (s) from which the efficiencies apply (before it, all rotors are nominal).
    pub efficiency_onset_s: f64,
}

impl Default for Disturbance {
    fn default() -> Self {
        Self {
            wind_m_s2: [0.0; 3],
            wind_onset_s: 0.0,
            rotor_efficiency: [1.0; 4],
            efficiency_onset_s: 0.0,
        }
    }
}

impl Disturbance {
    /// Wind specific force active at time `t_s` (m/s², world).
    pub fn wind_at(&self, t_s: f64) -> Vector3<f64> {
        if t_s >= self.wind_onset_s {
            Vector3::from(self.wind_m_s2)
        } else {
            Vector3::zeros()
        }
    }

    /// Rotor efficiencies active at time `t_s`.
    pub fn efficiency_at(&self, t_s: f64) -> [f64; 4] {
        if t_s >= self.efficiency_onset_s {
            self.rotor_efficiency
        } else {
            [1.0; 4]
        }
    }
}

/// One sinusoidal wind component: w(t) += amplitude sin(2π f t + phase).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindSine {
    /// Amplitude per world axis (m/s², specific force).
    pub amplitude_m_s2: [f64; 3],
    /// Frequency f (Hz).
    pub frequency_hz: f64,
    /// Phase (rad).
    #[serde(default)]
    pub phase_rad: f64,
}

/// One wind step: w(t) += wind_m_s2 for from_s ≤ t < until_s.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindStep {
    /// Added wind (m/s², world).
    pub wind_m_s2: [f64; 3],
    /// Start (s).
    pub from_s: f64,
    /// End (s); none: to the end of the flight.
    #[serde(default)]
    pub until_s: Option<f64>,
}

/// Time-varying wind on top of [`Disturbance`]'s constant wind: a sum of sinusoids and steps.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WindVariation {
    /// Sinusoids.
    pub sines: Vec<WindSine>,
    /// Steps.
    pub steps: Vec<WindStep>,
}

impl WindVariation {
    /// The added wind at `t_s` (m/s², world).
    pub fn at(&self, t_s: f64) -> Vector3<f64> {
        let mut w = Vector3::zeros();
        for s in &self.sines {
            let k = (core::f64::consts::TAU * s.frequency_hz * t_s + s.phase_rad).sin();
            w += Vector3::from(s.amplitude_m_s2) * k;
        }
        for s in &self.steps {
            if t_s >= s.from_s && s.until_s.is_none_or(|u| t_s < u) {
                w += Vector3::from(s.wind_m_s2);
            }
        }
        w
    }
}

/// The rigid-body state (f64), in the paper's convention.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantState {
    /// Position p (m, world).
    pub p_m: Vector3<f64>,
    /// Rotation R, body → world.
    pub rot: Matrix3<f64>,
    /// Linear velocity v (m/s, body frame).
    pub v_body_m_s: Vector3<f64>,
    /// Angular velocity ω (rad/s, body frame).
    pub w_body_rad_s: Vector3<f64>,
}

impl Default for PlantState {
    fn default() -> Self {
        Self::at_rest(Vector3::zeros(), 0.0)
    }
}

impl PlantState {
    /// At rest at `p_m`, level, with yaw `yaw_rad`.
    pub fn at_rest(p_m: Vector3<f64>, yaw_rad: f64) -> Self {
        Self {
            p_m,
            rot: rot_z(yaw_rad),
            v_body_m_s: Vector3::zeros(),
            w_body_rad_s: Vector3::zeros(),
        }
    }

    /// Linear velocity in the world frame, R v (m/s).
    pub fn v_world_m_s(&self) -> Vector3<f64> {
        self.rot * self.v_body_m_s
    }

    /// Angular momentum in the world frame, R J ω (kg·m²/s).
    pub fn angular_momentum_world(&self, params: &VehicleParams) -> Vector3<f64> {
        self.rot * (params.inertia() * self.w_body_rad_s)
    }

    /// Kinetic energy ½ m |v|² + ½ ωᵀ J ω (J).
    pub fn kinetic_energy(&self, params: &VehicleParams) -> f64 {
        0.5 * params.mass_kg * self.v_body_m_s.norm_squared()
            + 0.5
                * self
                    .w_body_rad_s
                    .dot(&(params.inertia() * self.w_body_rad_s))
    }

    /// True if every component is finite.
    pub fn is_finite(&self) -> bool {
        self.p_m.iter().all(|x| x.is_finite())
            && self.rot.iter().all(|x| x.is_finite())
            && self.v_body_m_s.iter().all(|x| x.is_finite())
            && self.w_body_rad_s.iter().all(|x| x.is_finite())
    }

    /// Roll, pitch, yaw (rad) of R in the Z-Y-X (yaw-pitch-roll) convention.
    pub fn rpy(&self) -> Vector3<f64> {
        rpy_of(&self.rot)
    }
}

/// Roll, pitch, yaw (rad) of a rotation matrix, Z-Y-X convention (as pybullet's Euler angles).
pub fn rpy_of(r: &Matrix3<f64>) -> Vector3<f64> {
    let roll = r[(2, 1)].atan2(r[(2, 2)]);
    let pitch = (-r[(2, 0)]).clamp(-1.0, 1.0).asin();
    let yaw = r[(1, 0)].atan2(r[(0, 0)]);
    Vector3::new(roll, pitch, yaw)
}

/// Rotation from roll, pitch, yaw (rad), Z-Y-X convention: R = Rz(yaw) Ry(pitch) Rx(roll).
pub fn rot_from_rpy(rpy: Vector3<f64>) -> Matrix3<f64> {
    rot_z(rpy.z) * so3_exp(&Vector3::new(0.0, rpy.y, 0.0)) * so3_exp(&Vector3::new(rpy.x, 0.0, 0.0))
}

/// Rotation about world z by `yaw_rad`.
pub fn rot_z(yaw_rad: f64) -> Matrix3<f64> {
    let (s, c) = yaw_rad.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// Skew-symmetric matrix x̂ with x̂ y = x × y.
pub fn hat(x: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -x.z, x.y, x.z, 0.0, -x.x, -x.y, x.x, 0.0)
}

/// Inverse of [`hat`] on the skew part of `m`: vee(m) = ½ (m − mᵀ)^∨.
pub fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    0.5 * Vector3::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    )
}

/// Exponential map so(3) → SO(3) (Rodrigues), accurate for small angles.
pub fn so3_exp(theta: &Vector3<f64>) -> Matrix3<f64> {
    let a2 = theta.norm_squared();
    let (sa, ca) = if a2 < 1e-8 {
        (
            1.0 - a2 / 6.0 + a2 * a2 / 120.0,
            0.5 - a2 / 24.0 + a2 * a2 / 720.0,
        )
    } else {
        let a = a2.sqrt();
        (a.sin() / a, (1.0 - a.cos()) / a2)
    };
    let k = hat(theta);
    Matrix3::identity() + k * sa + k * k * ca
}

/// Forces and torques acting on the body at one instant.
#[derive(Clone, Copy, Debug)]
pub struct Forces {
    /// Thrust of each rotor (N), efficiency and ground effect included.
    pub rotor_thrust_n: [f64; 4],
    /// Total force in the body frame (N): thrust, gravity, wind, drag.
    pub force_body_n: Vector3<f64>,
    /// Total torque in the body frame (N·m).
    pub torque_body_nm: Vector3<f64>,
}

#[derive(Clone, Copy)]
struct Deriv {
    p: Vector3<f64>,
    v: Vector3<f64>,
    w: Vector3<f64>,
    rotor: [f64; 4],
}

/// The quadrotor plant: state, time, disturbance and effects.
#[derive(Clone, Debug)]
pub struct Plant {
    /// Vehicle constants.
    pub params: VehicleParams,
    /// External disturbance.
    pub disturbance: Disturbance,
    /// Optional effects.
    pub effects: Effects,
    /// Time-varying wind added to `disturbance`'s (empty by default).
    pub wind_variation: WindVariation,
    state: PlantState,
    rotor_rpm: [f64; 4],
    /// The rotor wrench [f; τ] through the residual's lags ([`Effects::residual`]).
    residual_wrench: Option<[f64; 4]>,
    t_s: f64,
    j: Matrix3<f64>,
    j_inv: Matrix3<f64>,
}

impl Plant {
    /// A plant at time 0 in `initial`, rotors spinning at hover speed (matters only with motor lag).
    pub fn new(
        params: VehicleParams,
        disturbance: Disturbance,
        effects: Effects,
        initial: PlantState,
    ) -> Self {
        let j = params.inertia();
        let j_inv = Matrix3::from_diagonal(&Vector3::from(params.inertia_kg_m2.map(|x| 1.0 / x)));
        let h = params.hover_rpm();
        Self {
            params,
            disturbance,
            effects,
            wind_variation: WindVariation::default(),
            state: initial,
            rotor_rpm: [h; 4],
            residual_wrench: None,
            t_s: 0.0,
            j,
            j_inv,
        }
    }

    /// The nominal CF2X with no disturbance and no effects, in `initial`.
    pub fn nominal(initial: PlantState) -> Self {
        Self::new(
            VehicleParams::cf2x(),
            Disturbance::default(),
            Effects::default(),
            initial,
        )
    }

    /// The true state.
    pub fn state(&self) -> &PlantState {
        &self.state
    }

    /// Overwrite the state (time and rotor speeds unchanged).
    pub fn set_state(&mut self, s: PlantState) {
        self.state = s;
    }

    /// Simulated time (s).
    pub fn t_s(&self) -> f64 {
        self.t_s
    }

    /// Set the simulated time (s).
    pub fn set_t_s(&mut self, t_s: f64) {
        self.t_s = t_s;
    }

    /// Current rotor speeds (rpm); equal to the last command unless motor lag is on.
    pub fn rotor_rpm(&self) -> [f64; 4] {
        self.rotor_rpm
    }

    /// Set the rotor speeds (rpm), e.g. to start with motor lag at a given speed.
    pub fn set_rotor_rpm(&mut self, rpm: [f64; 4]) {
        self.rotor_rpm = self.params.clamp_rpm(rpm);
    }

    /// The state as measured by the controller: the truth plus the configured noise.
    pub fn measure<R: Rng + ?Sized>(&self, rng: &mut R) -> PlantState {
        let n = &self.effects.noise;
        if n.is_off() {
            return self.state;
        }
        let mut g = || gaussian(rng);
        let mut s = self.state;
        s.p_m += Vector3::new(g(), g(), g()) * n.pos_m;
        s.v_body_m_s += Vector3::new(g(), g(), g()) * n.vel_m_s;
        s.rot *= so3_exp(&(Vector3::new(g(), g(), g()) * n.att_rad));
        s.w_body_rad_s += Vector3::new(g(), g(), g()) * n.rate_rad_s;
        s
    }

    /// The total wind at `t_s`: the disturbance's plus the variation (m/s², world).
    pub fn wind_at(&self, t_s: f64) -> Vector3<f64> {
        self.disturbance.wind_at(t_s) + self.wind_variation.at(t_s)
    }

    /// The accelerometer's ideal reading now: the specific force (every force but gravity, over
    /// m) in the body frame (m/s²), from the rotors' current speeds.
    pub fn accelerometer(&self) -> Vector3<f64> {
        let f = self.forces(self.t_s, &self.state, &self.rotor_rpm);
        let g_body = self.state.rot.transpose()
            * Vector3::new(0.0, 0.0, -self.params.mass_kg * self.params.gravity_m_s2);
        (f.force_body_n - g_body) / self.params.mass_kg
    }

    /// [`Plant::accelerometer`] plus the configured noise σ `effects.noise.acc_m_s2`.
    pub fn measure_accelerometer<R: Rng + ?Sized>(&self, rng: &mut R) -> Vector3<f64> {
        let sigma = self.effects.noise.acc_m_s2;
        let mut a = self.accelerometer();
        if sigma > 0.0 {
            a += Vector3::new(gaussian(rng), gaussian(rng), gaussian(rng)) * sigma;
        }
        a
    }

    /// Forces and torques on the body at time `t_s` in state `s` with rotor speeds `rotor_rpm`
    /// (with the residual's lagged wrench and extra accelerations, [`Effects::residual`]).
    pub fn forces(&self, t_s: f64, s: &PlantState, rotor_rpm: &[f64; 4]) -> Forces {
        let mut fr = self.rotor_forces(t_s, s, rotor_rpm);
        let Some(r) = &self.effects.residual else {
            return fr;
        };
        let raw = Self::rotor_wrench(&fr);
        let lagged = self.residual_wrench.unwrap_or(raw);
        let m = self.params.mass_kg;
        // The rotor wrench replaced by its lagged, scaled self.
        fr.force_body_n.z += r.thrust_gain * lagged[0] - raw[0];
        for i in 0..3 {
            fr.torque_body_nm[i] += r.torque_gain[i] * lagged[i + 1] - raw[i + 1];
        }
        let z = [
            s.v_body_m_s.x,
            s.v_body_m_s.y,
            s.v_body_m_s.z,
            s.w_body_rad_s.x,
            s.w_body_rad_s.y,
            s.w_body_rad_s.z,
        ];
        let up = s.rot.transpose() * Vector3::z();
        let mut acc = [0.0; 6];
        for ((o, row), c) in acc.iter_mut().zip(&r.accel_per_velocity).zip(&r.accel_bias) {
            *o = row.iter().zip(&z).map(|(a, b)| a * b).sum::<f64>() + c;
        }
        for (o, k) in acc[3..].iter_mut().zip(&r.accel_per_tilt) {
            *o += k[0] * up.x + k[1] * up.y;
        }
        fr.force_body_n += Vector3::new(acc[0], acc[1], acc[2]) * m;
        fr.torque_body_nm += self.j * Vector3::new(acc[3], acc[4], acc[5]);
        fr
    }

    /// The rotors' own wrench [f; τ] (N, N·m) of `fr` (before the residual).
    fn rotor_wrench(fr: &Forces) -> [f64; 4] {
        let f: f64 = fr.rotor_thrust_n.iter().sum();
        [
            f,
            fr.torque_body_nm.x,
            fr.torque_body_nm.y,
            fr.torque_body_nm.z,
        ]
    }

    /// [`Plant::forces`] without the residual.
    fn rotor_forces(&self, t_s: f64, s: &PlantState, rotor_rpm: &[f64; 4]) -> Forces {
        let prm = &self.params;
        let dist_eff = self.disturbance.efficiency_at(t_s);
        let eff: [f64; 4] = core::array::from_fn(|i| dist_eff[i] * prm.rotor_efficiency[i]);
        let a = prm.arm_xy_m;
        let max = prm.max_rpm();
        let mut thrust = [0.0; 4];
        let mut tz = 0.0;
        let mut sum_rad_s = 0.0;
        // gym-pybullet-drones' GND_EFF_H_CLIP with MAX_THRUST = 4 kf max_rpm².
        let ge_clip = 0.25 * prm.prop_radius_m * (15.0 * prm.ground_effect_coeff / 4.0).sqrt();
        for i in 0..4 {
            let rpm = rotor_rpm[i].clamp(0.0, max);
            let sq = rpm * rpm;
            let mut t = eff[i] * prm.kf_n_per_rpm2 * sq;
            if self.effects.ground_effect && s.rot[(2, 2)] > 0.0 {
                let r_i = Vector3::new(ROTOR_XY_SIGN[i][0] * a, ROTOR_XY_SIGN[i][1] * a, 0.0);
                let h = (s.p_m + s.rot * r_i).z.max(ge_clip);
                t *= 1.0 + prm.ground_effect_coeff * (prm.prop_radius_m / (4.0 * h)).powi(2);
            }
            thrust[i] = t;
            tz += ROTOR_YAW_SIGN[i] * eff[i] * prm.km_nm_per_rpm2 * sq;
            sum_rad_s += rpm * core::f64::consts::TAU / 60.0;
        }
        let f: f64 = thrust.iter().sum();
        let mut tx = 0.0;
        let mut ty = 0.0;
        for i in 0..4 {
            tx += ROTOR_XY_SIGN[i][1] * a * thrust[i];
            ty -= ROTOR_XY_SIGN[i][0] * a * thrust[i];
        }
        let m = prm.mass_kg;
        let ext_world = m * (self.wind_at(t_s) - Vector3::new(0.0, 0.0, prm.gravity_m_s2));
        let mut force = Vector3::new(0.0, 0.0, f) + s.rot.transpose() * ext_world;
        if self.effects.rotor_drag {
            let c = Vector3::from(prm.drag_coeff);
            force -= c.component_mul(&s.v_body_m_s) * sum_rad_s;
        }
        Forces {
            rotor_thrust_n: thrust,
            force_body_n: force,
            torque_body_nm: Vector3::new(tx, ty, tz),
        }
    }

    fn deriv(&self, t_s: f64, s: &PlantState, rotor: &[f64; 4], cmd: &[f64; 4]) -> Deriv {
        let fr = self.forces(t_s, s, rotor);
        let v = &s.v_body_m_s;
        let w = &s.w_body_rad_s;
        let jw = self.j * w;
        let tau = self.effects.motor_tau_s;
        let rotor_dot = if tau > 0.0 {
            core::array::from_fn(|i| (cmd[i] - rotor[i]) / tau)
        } else {
            [0.0; 4]
        };
        Deriv {
            p: s.rot * v,
            v: v.cross(w) + fr.force_body_n / self.params.mass_kg,
            w: self.j_inv * (jw.cross(w) + fr.torque_body_nm),
            rotor: rotor_dot,
        }
    }

    /// Advance the plant by one physics step of `dt_s` seconds with the rotor command `cmd_rpm`
    /// (rpm, rotors 1..4; clamped to `[0, max_rpm]`) held constant. Disturbance switches are
    /// evaluated at the start of the step. Use steps ≤ 1 ms.
    pub fn step(&mut self, cmd_rpm: [f64; 4], dt_s: f64) {
        let cmd = self.params.clamp_rpm(cmd_rpm);
        if self.effects.motor_tau_s <= 0.0 {
            self.rotor_rpm = cmd;
        }
        if let Some(r) = &self.effects.residual {
            // The residual's lags, by backward Euler (as fit-response rolls them out), held
            // over the step.
            let raw =
                Self::rotor_wrench(&self.rotor_forces(self.t_s, &self.state, &self.rotor_rpm));
            let pole = |lag: f64| if lag > 0.0 { lag / (lag + dt_s) } else { 0.0 };
            let (af, at) = (pole(r.thrust_lag_s), pole(r.torque_lag_s));
            let prev = self.residual_wrench.unwrap_or(raw);
            self.residual_wrench = Some(core::array::from_fn(|i| {
                let a = if i == 0 { af } else { at };
                a * prev[i] + (1.0 - a) * raw[i]
            }));
        }
        let t = self.t_s;
        let h = dt_s;
        let s0 = self.state;
        let r0 = s0.rot;
        let dexpinv = |th: &Vector3<f64>, w: &Vector3<f64>| -> Vector3<f64> {
            let c = th.cross(w);
            w + 0.5 * c + th.cross(&c) / 12.0
        };
        let stage = |th: &Vector3<f64>, k: Option<(&Deriv, f64)>| -> (PlantState, [f64; 4]) {
            let mut s = s0;
            let mut rotor = self.rotor_rpm;
            if let Some((d, c)) = k {
                s.p_m += d.p * (c * h);
                s.v_body_m_s += d.v * (c * h);
                s.w_body_rad_s += d.w * (c * h);
                for (r, dr) in rotor.iter_mut().zip(&d.rotor) {
                    *r += dr * c * h;
                }
                s.rot = r0 * so3_exp(th);
            }
            (s, rotor)
        };
        let (s1, q1) = stage(&Vector3::zeros(), None);
        let k1 = self.deriv(t, &s1, &q1, &cmd);
        let th1 = s1.w_body_rad_s * h;
        let (s2, q2) = stage(&(th1 * 0.5), Some((&k1, 0.5)));
        let k2 = self.deriv(t, &s2, &q2, &cmd);
        let th2 = dexpinv(&(th1 * 0.5), &s2.w_body_rad_s) * h;
        let (s3, q3) = stage(&(th2 * 0.5), Some((&k2, 0.5)));
        let k3 = self.deriv(t, &s3, &q3, &cmd);
        let th3 = dexpinv(&(th2 * 0.5), &s3.w_body_rad_s) * h;
        let (s4, q4) = stage(&th3, Some((&k3, 1.0)));
        let k4 = self.deriv(t, &s4, &q4, &cmd);
        let th4 = dexpinv(&th3, &s4.w_body_rad_s) * h;

        let c = h / 6.0;
        let mut s = s0;
        s.p_m += (k1.p + 2.0 * k2.p + 2.0 * k3.p + k4.p) * c;
        s.v_body_m_s += (k1.v + 2.0 * k2.v + 2.0 * k3.v + k4.v) * c;
        s.w_body_rad_s += (k1.w + 2.0 * k2.w + 2.0 * k3.w + k4.w) * c;
        let th = (th1 + 2.0 * th2 + 2.0 * th3 + th4) / 6.0;
        s.rot = r0 * so3_exp(&th);
        if self.effects.motor_tau_s > 0.0 {
            for i in 0..4 {
                self.rotor_rpm[i] +=
                    (k1.rotor[i] + 2.0 * k2.rotor[i] + 2.0 * k3.rotor[i] + k4.rotor[i]) * c;
            }
            self.rotor_rpm = self.params.clamp_rpm(self.rotor_rpm);
        }
        self.state = s;
        self.t_s = t + h;
    }

    /// Advance by `duration_s` with `cmd_rpm` held, in equal physics steps no longer than
    /// `max_dt_s` (at least one step).
    pub fn advance(&mut self, cmd_rpm: [f64; 4], duration_s: f64, max_dt_s: f64) {
        let n = ((duration_s / max_dt_s) - 1e-9).ceil().max(1.0) as usize;
        let dt = duration_s / n as f64;
        for _ in 0..n {
            self.step(cmd_rpm, dt);
        }
    }
}

/// A standard normal sample (Box–Muller).
pub fn gaussian<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    let u1: f64 = rng.gen_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (core::f64::consts::TAU * u2).cos()
}
