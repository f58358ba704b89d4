//! A state estimator of our own, written from the published error-state extended Kalman filter
//! the Crazyflie flies (Mueller, Hamer and D'Andrea, "Fusing ultra-wideband range measurements
//! with accelerometers and rate gyroscopes for quadrocopter state estimation", ICRA 2015), so that
//! the SITL controller sees what a Crazyflie's controller sees.
//!
//! - **State:** position p (m, world), body velocity v (m/s), and a small attitude error δ
//!   (rad, body) about a reference attitude R (body → world), which is folded into R after every
//!   update (the "reset" step), so δ = 0 between updates. Covariance P ∈ ℝ⁹ˣ⁹.
//! - **Prediction** with the mean gyro ω and accelerometer a_s over the interval since the last
//!   prediction (the Crazyflie predicts at 100 Hz):
//!   ṗ = R v, v̇ = a − ω × v − g Rᵀe₃, Ṙ = R \[ω\]×. **In flight the filter keeps only the
//!   accelerometer's z (thrust-axis) component**, a = (0, 0, a_s,z): the paper's quadrotor model
//!   has no horizontal body force. So a steady horizontal external force, which the
//!   accelerometer does see, is invisible to the filter, and its velocity and position drift
//!   until the pose updates pull them back: a steady bias. The Jacobian blocks, with
//!   ∂(Rv)/∂δ = −R`[v]`×, ∂(−(R exp δ)ᵀ g e₃)/∂δ = −[g Rᵀe₃]× and δ̇ = −ω × δ:
//!   F = I + dt [[0, R, −R`[v]`×], [0, −\[ω\]×, −[g Rᵀe₃]×], [0, 0, −\[ω\]×]].
//! - **Process noise** per prediction: (σ_acc dt)² on v (x/y and z apart) and (σ_gyro dt)² on δ.
//! - **Pose update** (motion capture or a Lighthouse-like source): position with σ_pos, and,
//!   where the source gives attitude, δ_meas = log(Rᵀ R_meas) with σ_att, as scalar updates.
//!   A late measurement is fused as if it were current, as the Crazyflie does.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use crate::sim::plant::{hat, so3_exp, vee};

type M9 = SMatrix<f64, 9, 9>;
type V9 = SVector<f64, 9>;

/// The filter's tuning (the Crazyflie's defaults where it has one).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EkfTuning {
    /// Gravity (m/s²).
    pub gravity_m_s2: f64,
    /// Process noise of the horizontal acceleration σ (m/s²).
    pub acc_xy_m_s2: f64,
    /// Process noise of the vertical acceleration σ (m/s²).
    pub acc_z_m_s2: f64,
    /// Process noise of the body rates σ (rad/s).
    pub gyro_rad_s: f64,
    /// Initial σ of position (m), velocity (m/s) and attitude (rad).
    pub init_pos_m: f64,
    /// Initial velocity σ (m/s).
    pub init_vel_m_s: f64,
    /// Initial attitude σ (rad).
    pub init_att_rad: f64,
}

impl Default for EkfTuning {
    fn default() -> Self {
        Self {
            gravity_m_s2: 9.8,
            acc_xy_m_s2: 0.5,
            acc_z_m_s2: 1.0,
            gyro_rad_s: 0.1,
            init_pos_m: 0.01,
            init_vel_m_s: 0.01,
            init_att_rad: 0.01,
        }
    }
}

/// The error-state EKF (module docs).
#[derive(Clone, Debug)]
pub struct Ekf {
    /// Tuning.
    pub tuning: EkfTuning,
    /// Position (m, world).
    pub p_m: Vector3<f64>,
    /// Velocity (m/s, body).
    pub v_body_m_s: Vector3<f64>,
    /// Reference attitude (body → world).
    pub rot: Matrix3<f64>,
    /// Attitude error δ (rad, body), folded into `rot` after each update.
    delta: Vector3<f64>,
    /// Covariance of (p, v, δ).
    pub cov: M9,
}

impl Ekf {
    /// A filter started at the given state.
    pub fn new(
        tuning: EkfTuning,
        p_m: Vector3<f64>,
        v_body_m_s: Vector3<f64>,
        rot: Matrix3<f64>,
    ) -> Self {
        let mut cov = M9::zeros();
        for i in 0..3 {
            cov[(i, i)] = tuning.init_pos_m.powi(2);
            cov[(i + 3, i + 3)] = tuning.init_vel_m_s.powi(2);
            cov[(i + 6, i + 6)] = tuning.init_att_rad.powi(2);
        }
        Self {
            tuning,
            p_m,
            v_body_m_s,
            rot,
            delta: Vector3::zeros(),
            cov,
        }
    }

    /// One prediction over `dt_s` with the mean body rate `w` (rad/s) and specific force `acc`
    /// (m/s², body). `in_flight`: keep only the thrust-axis component of `acc`.
    pub fn predict(&mut self, w: &Vector3<f64>, acc: &Vector3<f64>, dt_s: f64, in_flight: bool) {
        if dt_s.is_nan() || dt_s <= 0.0 {
            return;
        }
        let t = self.tuning;
        let a = if in_flight {
            Vector3::new(0.0, 0.0, acc.z)
        } else {
            *acc
        };
        let r = self.rot;
        let v = self.v_body_m_s;
        let g_body = r.transpose() * Vector3::z() * t.gravity_m_s2;
        let v_dot = a - w.cross(&v) - g_body;
        // Jacobian F = I + A dt (module docs).
        let mut f = M9::identity();
        let wx = hat(w);
        f.fixed_view_mut::<3, 3>(0, 3).copy_from(&(r * dt_s));
        f.fixed_view_mut::<3, 3>(0, 6)
            .copy_from(&(-r * hat(&v) * dt_s));
        f.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(Matrix3::identity() - wx * dt_s));
        f.fixed_view_mut::<3, 3>(3, 6)
            .copy_from(&(-hat(&g_body) * dt_s));
        f.fixed_view_mut::<3, 3>(6, 6)
            .copy_from(&(Matrix3::identity() - wx * dt_s));
        self.p_m += r * (v * dt_s + v_dot * (0.5 * dt_s * dt_s));
        self.v_body_m_s += v_dot * dt_s;
        self.rot = r * so3_exp(&(w * dt_s));
        let mut q = V9::zeros();
        for i in 0..3 {
            let acc_sigma = if i < 2 { t.acc_xy_m_s2 } else { t.acc_z_m_s2 };
            q[3 + i] = (acc_sigma * dt_s).powi(2);
            q[6 + i] = (t.gyro_rad_s * dt_s).powi(2);
        }
        self.cov = f * self.cov * f.transpose() + M9::from_diagonal(&q);
        self.symmetrize();
    }

    /// Fuse a position measurement (m, world) with σ `sigma_m`.
    pub fn update_position(&mut self, p_meas: &Vector3<f64>, sigma_m: f64) {
        for i in 0..3 {
            let mut h = V9::zeros();
            h[i] = 1.0;
            self.scalar_update(&h, p_meas[i] - self.p_m[i], sigma_m * sigma_m);
        }
        self.reset();
    }

    /// Fuse an attitude measurement (body → world) with σ `sigma_rad` per axis.
    pub fn update_attitude(&mut self, rot_meas: &Matrix3<f64>, sigma_rad: f64) {
        let err = log_so3(&(self.rot.transpose() * rot_meas));
        for i in 0..3 {
            let mut h = V9::zeros();
            h[6 + i] = 1.0;
            self.scalar_update(&h, err[i] - self.delta[i], sigma_rad * sigma_rad);
        }
        self.reset();
    }

    fn scalar_update(&mut self, h: &V9, innovation: f64, r: f64) {
        let ph = self.cov * h;
        let s = h.dot(&ph) + r;
        if !(s > 0.0 && s.is_finite() && innovation.is_finite()) {
            return;
        }
        let k = ph / s;
        let dx = k * innovation;
        self.p_m += dx.fixed_rows::<3>(0);
        self.v_body_m_s += dx.fixed_rows::<3>(3);
        self.delta += dx.fixed_rows::<3>(6);
        // Joseph form for a scalar measurement: (I − k hᵀ) P (I − k hᵀ)ᵀ + k r kᵀ.
        let a = M9::identity() - k * h.transpose();
        self.cov = a * self.cov * a.transpose() + k * k.transpose() * r;
        self.symmetrize();
    }

    /// Fold δ into the reference attitude and rotate the covariance with it.
    fn reset(&mut self) {
        if self.delta == Vector3::zeros() {
            return;
        }
        let d = self.delta;
        self.rot *= so3_exp(&d);
        let mut g = M9::identity();
        g.fixed_view_mut::<3, 3>(6, 6)
            .copy_from(&(Matrix3::identity() - hat(&d) * 0.5));
        self.cov = g * self.cov * g.transpose();
        self.symmetrize();
        self.delta = Vector3::zeros();
        // Keep R a rotation against rounding.
        self.rot = nalgebra::Rotation3::from_matrix(&self.rot).into_inner();
    }

    fn symmetrize(&mut self) {
        self.cov = (self.cov + self.cov.transpose()) * 0.5;
    }
}

/// log: SO(3) → so(3) as a vector (rad), for rotations away from π.
pub fn log_so3(r: &Matrix3<f64>) -> Vector3<f64> {
    let c = ((r.trace() - 1.0) * 0.5).clamp(-1.0, 1.0);
    let th = c.acos();
    // vee of the antisymmetric part: sin θ times the axis.
    let v = vee(r);
    if th < 1e-6 {
        v
    } else {
        v * (th / th.sin())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At rest, level, with exact IMU readings and position updates, the filter stays put.
    #[test]
    fn hover_at_rest_stays_at_rest() {
        let mut ekf = Ekf::new(
            EkfTuning::default(),
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::zeros(),
            Matrix3::identity(),
        );
        for _ in 0..500 {
            ekf.predict(&Vector3::zeros(), &Vector3::new(0.0, 0.0, 9.8), 0.01, true);
            ekf.update_position(&Vector3::new(0.0, 0.0, 1.0), 0.001);
        }
        assert!((ekf.p_m - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-9);
        assert!(ekf.v_body_m_s.norm() < 1e-9);
    }

    /// A steady horizontal specific force the filter ignores biases its velocity, and the
    /// position updates bound it: the bias the module docs describe.
    #[test]
    fn horizontal_force_biases_velocity_in_flight() {
        // The vehicle hovers still, tilted by θ against a wind: thrust and wind together cancel
        // gravity, so the accelerometer reads Rᵀ g e₃, with a body-x part. Truth: at rest.
        let th: f64 = 0.076; // tan θ = 0.75 / 9.8
        let rot = nalgebra::Rotation3::from_euler_angles(0.0, -th, 0.0).into_inner();
        let mut ekf = Ekf::new(
            EkfTuning::default(),
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::zeros(),
            rot,
        );
        let acc = rot.transpose() * Vector3::new(0.0, 0.0, 9.8);
        for _ in 0..2000 {
            ekf.predict(&Vector3::zeros(), &acc, 0.01, true);
            ekf.update_position(&Vector3::new(0.0, 0.0, 1.0), 0.01);
            ekf.update_attitude(&rot, 0.01);
        }
        let v_world = ekf.rot * ekf.v_body_m_s;
        // The thrust-axis-only model reads the tilted thrust as a horizontal acceleration the
        // wind in truth cancels: the estimate carries a steady bias.
        assert!(v_world.x.abs() > 0.05, "velocity bias {v_world}");
        assert!((ekf.p_m.x).abs() > 1e-3, "position bias {}", ekf.p_m.x);
        assert!((ekf.p_m.x).abs() < 0.2, "bounded by the pose updates");
        // With the whole accelerometer (the filter's on-ground model) there is no bias.
        let mut ekf = Ekf::new(
            EkfTuning::default(),
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::zeros(),
            rot,
        );
        for _ in 0..2000 {
            ekf.predict(&Vector3::zeros(), &acc, 0.01, false);
            ekf.update_position(&Vector3::new(0.0, 0.0, 1.0), 0.01);
        }
        assert!((ekf.rot * ekf.v_body_m_s).norm() < 1e-6);
    }
}
