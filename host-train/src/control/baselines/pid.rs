//! The DSL PID controller of gym-pybullet-drones (`DSLPIDControl`, CF2X), written from its
//! published algorithm: the paper's data-collection controller.
//!
//! Position loop (world frame): a PID on the position error gives a desired force
//! `F = P ⊙ e_p + I ⊙ ∫e_p + D ⊙ e_v + [0, 0, m g]` (N); the collective command is the PWM whose
//! rpm would make `F · R e₃` on four rotors; the desired attitude has body z along `F` and the
//! desired yaw. Attitude loop: `τ = −P ⊙ rot_e + D ⊙ (ṙpy* − ṙpy) + I ⊙ ∫(−rot_e)` in PWM units
//! with `rot_e = (R*ᵀR − RᵀR*)^∨` and roll-pitch-yaw rates from a finite difference of the Euler
//! angles; then `pwm = thrust + MIXER τ`, clipped to [20000, 65535], and
//! `rpm = 0.2685 pwm + 4070.3`.
//!
//! Differences from the Python original, all deliberate:
//! - the mixer rows are ordered and signed for our rotor numbering (1 front-right, 2 back-right,
//!   3 back-left, 4 front-left; yaw reaction −, +, −, +), derived from the plant so that a positive
//!   torque command makes a positive body torque;
//! - the yaw finite difference is wrapped to (−π, π] (the original spikes once when yaw crosses ±π);
//! - the Euler round trip `as_euler('XYZ')` → `from_euler` of the original is the identity on the
//!   desired rotation and is skipped.

use nalgebra::{Matrix3, Vector3};

use crate::control::controller::Controller;

use crate::sim::plant::{rpy_of, PlantState, VehicleParams};
use crate::sim::trajectory::TrajectoryPoint;

/// DSL PID gains and constants (defaults: gym-pybullet-drones' CF2X values).
#[derive(Clone, Debug)]
pub struct DslPidGains {
    /// Position P gains (N/m).
    pub p_for: [f64; 3],
    /// Position I gains (N/(m·s)).
    pub i_for: [f64; 3],
    /// Position D gains (N/(m/s)).
    pub d_for: [f64; 3],
    /// Attitude P gains (PWM per unit of rot_e).
    pub p_tor: [f64; 3],
    /// Attitude I gains (PWM per unit of ∫rot_e).
    pub i_tor: [f64; 3],
    /// Attitude D gains (PWM per rad/s).
    pub d_tor: [f64; 3],
    /// rpm = scale · pwm + const.
    pub pwm2rpm_scale: f64,
    /// rpm = scale · pwm + const.
    pub pwm2rpm_const: f64,
    /// PWM lower limit.
    pub min_pwm: f64,
    /// PWM upper limit.
    pub max_pwm: f64,
}

impl Default for DslPidGains {
    fn default() -> Self {
        Self {
            p_for: [0.4, 0.4, 1.25],
            i_for: [0.05, 0.05, 0.05],
            d_for: [0.2, 0.2, 0.5],
            p_tor: [70000.0, 70000.0, 60000.0],
            i_tor: [0.0, 0.0, 500.0],
            d_tor: [20000.0, 20000.0, 12000.0],
            pwm2rpm_scale: 0.2685,
            pwm2rpm_const: 4070.3,
            min_pwm: 20000.0,
            max_pwm: 65535.0,
        }
    }
}

/// The CF2X mixer for our rotor numbering: rows rotors 1..4, columns roll, pitch, yaw torque.
pub const DSL_MIXER: [[f64; 3]; 4] = [
    [-0.5, -0.5, -1.0],
    [-0.5, 0.5, 1.0],
    [0.5, 0.5, -1.0],
    [0.5, -0.5, 1.0],
];

/// The DSL PID controller.
#[derive(Clone, Debug)]
pub struct DslPid {
    /// Gains and constants.
    pub gains: DslPidGains,
    params: VehicleParams,
    last_rpy: Vector3<f64>,
    integral_pos_e: Vector3<f64>,
    integral_rpy_e: Vector3<f64>,
}

impl DslPid {
    /// The controller for a vehicle with `params` (mass, g and kf are used) and default gains.
    pub fn new(params: VehicleParams) -> Self {
        Self {
            gains: DslPidGains::default(),
            params,
            last_rpy: Vector3::zeros(),
            integral_pos_e: Vector3::zeros(),
            integral_rpy_e: Vector3::zeros(),
        }
    }
}

fn wrap_pi(x: f64) -> f64 {
    let t = core::f64::consts::TAU;
    x - t * ((x + core::f64::consts::PI) / t).floor()
}

impl Controller for DslPid {
    fn name(&self) -> &str {
        "pid"
    }

    fn reset(&mut self) {
        self.last_rpy = Vector3::zeros();
        self.integral_pos_e = Vector3::zeros();
        self.integral_rpy_e = Vector3::zeros();
    }

    fn step(&mut self, _t_s: f64, s: &PlantState, r: &TrajectoryPoint, dt: f64) -> [f64; 4] {
        let g = &self.gains;
        let rot = s.rot;
        // Position loop.
        let pos_e = r.p_m - s.p_m;
        let vel_e = r.v_m_s - s.v_world_m_s();
        self.integral_pos_e += pos_e * dt;
        self.integral_pos_e = self.integral_pos_e.map(|x| x.clamp(-2.0, 2.0));
        self.integral_pos_e.z = self.integral_pos_e.z.clamp(-0.15, 0.15);
        let target_thrust = Vector3::from(g.p_for).component_mul(&pos_e)
            + Vector3::from(g.i_for).component_mul(&self.integral_pos_e)
            + Vector3::from(g.d_for).component_mul(&vel_e)
            + Vector3::new(0.0, 0.0, self.params.weight_n());
        let scalar_thrust = target_thrust.dot(&rot.column(2).into_owned()).max(0.0);
        let thrust_pwm = ((scalar_thrust / (4.0 * self.params.kf_n_per_rpm2)).sqrt()
            - g.pwm2rpm_const)
            / g.pwm2rpm_scale;
        let norm = target_thrust.norm();
        let z_ax = if norm > 1e-9 {
            target_thrust / norm
        } else {
            Vector3::z()
        };
        let x_c = Vector3::new(r.yaw_rad.cos(), r.yaw_rad.sin(), 0.0);
        let y_raw = z_ax.cross(&x_c);
        let y_ax = if y_raw.norm() > 1e-9 {
            y_raw.normalize()
        } else {
            Vector3::y()
        };
        let x_ax = y_ax.cross(&z_ax);
        let target_rot = Matrix3::from_columns(&[x_ax, y_ax, z_ax]);

        // Attitude loop.
        let cur_rpy = rpy_of(&rot);
        let e = target_rot.transpose() * rot - rot.transpose() * target_rot;
        let rot_e = Vector3::new(e[(2, 1)], e[(0, 2)], e[(1, 0)]);
        let d_rpy = (cur_rpy - self.last_rpy).map(wrap_pi);
        let rpy_rates_e = Vector3::new(0.0, 0.0, r.yaw_rate_rad_s) - d_rpy / dt;
        self.last_rpy = cur_rpy;
        self.integral_rpy_e -= rot_e * dt;
        self.integral_rpy_e = self.integral_rpy_e.map(|x| x.clamp(-1500.0, 1500.0));
        self.integral_rpy_e.x = self.integral_rpy_e.x.clamp(-1.0, 1.0);
        self.integral_rpy_e.y = self.integral_rpy_e.y.clamp(-1.0, 1.0);
        let torques = (-Vector3::from(g.p_tor).component_mul(&rot_e)
            + Vector3::from(g.d_tor).component_mul(&rpy_rates_e)
            + Vector3::from(g.i_tor).component_mul(&self.integral_rpy_e))
        .map(|x| x.clamp(-3200.0, 3200.0));
        core::array::from_fn(|i| {
            let m = DSL_MIXER[i];
            let pwm = thrust_pwm + m[0] * torques.x + m[1] * torques.y + m[2] * torques.z;
            let pwm = if pwm.is_finite() {
                pwm.clamp(g.min_pwm, g.max_pwm)
            } else {
                g.min_pwm
            };
            g.pwm2rpm_scale * pwm + g.pwm2rpm_const
        })
    }
}
