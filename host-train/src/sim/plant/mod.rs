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

mod effects;
mod params;
mod so3;

pub use effects::{Disturbance, Effects, Residual, StateNoise, WindSine, WindStep, WindVariation};
pub use params::VehicleParams;
pub use so3::{hat, rot_from_rpy, rot_z, rpy_of, so3_exp, vee};

/// Body positions (x, y) in units of the arm offset `a` of rotors 1..4.
pub const ROTOR_XY_SIGN: [[f64; 2]; 4] = [[1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]];
/// Sign of each rotor's reaction torque about body z (rotors 1..4).
pub const ROTOR_YAW_SIGN: [f64; 4] = [-1.0, 1.0, -1.0, 1.0];

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
