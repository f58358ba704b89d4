//! Bitcraze's Mellinger controller (firmware 2025.09) in full-state position mode, followed by
//! the legacy power distribution: our implementation of the published algorithm, with the
//! firmware's conventions kept where they change the numbers (the pitch axis sign flip, the
//! order of the integrator updates, the int16 command clamp, the zero-initialized rate memory).

use super::config::OnboardConfig;
use super::power::{legacy_power_distribution, LegacyControl, PWM_MAX};
use super::{MotorCommands, OnboardLaw, OnboardSetpoint, OnboardState};
use nalgebra::{Matrix3, Vector3};

/// The firmware clamps each moment command to ±32000 counts before the int16 store.
const MOMENT_CLAMP: f64 = 32000.0;

/// One step's full output: the legacy control and the motors in PWM counts.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct MellingerOutput {
    /// The controller's legacy-mode output.
    pub control: LegacyControl,
    /// Capped, floored motor commands, PWM counts (0..65535).
    pub motors_pwm: [f64; 4],
}

/// The Mellinger controller's state: the position and attitude integrators and the previous
/// body rate (for the angular-acceleration damping).
#[derive(Clone, Debug)]
pub struct Mellinger {
    cfg: OnboardConfig,
    i_error_p: Vector3<f64>,
    i_error_m: Vector3<f64>,
    /// Previous roll and pitch rates in the firmware's convention (pitch negated), rad/s.
    prev_omega_rp: [f64; 2],
}

impl Mellinger {
    /// A fresh controller (integrators and rate memory zero, as the firmware's init).
    pub fn new(cfg: OnboardConfig) -> Self {
        Self {
            cfg,
            i_error_p: Vector3::zeros(),
            i_error_m: Vector3::zeros(),
            prev_omega_rp: [0.0; 2],
        }
    }

    /// The configuration it runs with.
    pub fn config(&self) -> &OnboardConfig {
        &self.cfg
    }

    /// The integrators (position, attitude), for tests and diagnostics.
    pub fn integrators(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.i_error_p, self.i_error_m)
    }

    fn reset_integrators(&mut self) {
        self.i_error_p = Vector3::zeros();
        self.i_error_m = Vector3::zeros();
    }

    /// One controller step with the full output.
    pub fn step_full(
        &mut self,
        state: &OnboardState,
        sp: &OnboardSetpoint,
        dt_s: f64,
    ) -> MellingerOutput {
        let g = &self.cfg.gains;
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s
        } else {
            1.0 / self.cfg.rate_hz
        };

        // Position and velocity errors, the clamped position integrals.
        let r_error = sp.p_m - state.p_m;
        let v_error = sp.v_m_s - state.v_m_s;
        let ip = self.i_error_p + r_error * dt;
        self.i_error_p = Vector3::new(
            ip.x.clamp(-g.i_range_xy, g.i_range_xy),
            ip.y.clamp(-g.i_range_xy, g.i_range_xy),
            ip.z.clamp(-g.i_range_z, g.i_range_z),
        );

        // The desired force, N.
        let m = self.cfg.mass_kg;
        let target = Vector3::new(
            m * sp.a_m_s2.x
                + g.kp_xy * r_error.x
                + g.kd_xy * v_error.x
                + g.ki_xy * self.i_error_p.x,
            m * sp.a_m_s2.y
                + g.kp_xy * r_error.y
                + g.kd_xy * v_error.y
                + g.ki_xy * self.i_error_p.y,
            m * (sp.a_m_s2.z + self.cfg.gravity_m_s2)
                + g.kp_z * r_error.z
                + g.kd_z * v_error.z
                + g.ki_z * self.i_error_p.z,
        );

        // The body z axis and the collective force along it.
        let rot: Matrix3<f64> = *state.q.to_rotation_matrix().matrix();
        let z_axis = rot.column(2).into_owned();
        let current_thrust = target.dot(&z_axis);

        // The desired frame from the force direction and the reference yaw.
        let z_des = target.try_normalize(0.0).unwrap_or_else(Vector3::z);
        let x_c = Vector3::new(sp.yaw_rad.cos(), sp.yaw_rad.sin(), 0.0);
        let y_des = z_des
            .cross(&x_c)
            .try_normalize(0.0)
            .unwrap_or_else(Vector3::y);
        let x_des = y_des.cross(&z_des);
        let r_des = Matrix3::from_columns(&[x_des, y_des, z_des]);

        // Rotation error vee(Rdesᵀ R − Rᵀ Rdes) (no ½), then the firmware's pitch flip.
        let e = r_des.transpose() * rot - rot.transpose() * r_des;
        let e_r = Vector3::new(e[(2, 1)], -e[(0, 2)], e[(1, 0)]);

        // Rates in the firmware's convention (pitch negated); the references are zero.
        let w = state.w_body_rad_s;
        let omega = Vector3::new(w.x, -w.y, w.z);
        let ew = -omega;
        let err_d_roll = -(omega.x - self.prev_omega_rp[0]) / dt;
        let err_d_pitch = -(omega.y - self.prev_omega_rp[1]) / dt;
        self.prev_omega_rp = [omega.x, omega.y];

        // Attitude integrals.
        let im = self.i_error_m - e_r * dt;
        self.i_error_m = Vector3::new(
            im.x.clamp(-g.i_range_m_xy, g.i_range_m_xy),
            im.y.clamp(-g.i_range_m_xy, g.i_range_m_xy),
            im.z.clamp(-g.i_range_m_z, g.i_range_m_z),
        );

        // Moments, command counts.
        let mx = -g.kr_xy * e_r.x
            + g.kw_xy * ew.x
            + g.ki_m_xy * self.i_error_m.x
            + g.kd_omega_rp * err_d_roll;
        let my = -g.kr_xy * e_r.y
            + g.kw_xy * ew.y
            + g.ki_m_xy * self.i_error_m.y
            + g.kd_omega_rp * err_d_pitch;
        let mz = -g.kr_z * e_r.z + g.kw_z * ew.z + g.ki_m_z * self.i_error_m.z;

        let thrust = self.cfg.mass_thrust * current_thrust;
        let int = self.cfg.integer_outputs;
        let store = |x: f64| {
            let c = x.clamp(-MOMENT_CLAMP, MOMENT_CLAMP);
            if int {
                c.trunc()
            } else {
                c
            }
        };
        let control = if thrust > 0.0 {
            LegacyControl {
                thrust,
                roll: store(mx) + self.cfg.roll_trim,
                pitch: store(my) + self.cfg.pitch_trim,
                yaw: store(-mz) + self.cfg.yaw_trim,
            }
        } else {
            self.reset_integrators();
            LegacyControl {
                thrust,
                ..LegacyControl::default()
            }
        };
        let idle = (self.cfg.idle_cmd * PWM_MAX).round();
        MellingerOutput {
            control,
            motors_pwm: legacy_power_distribution(&control, idle, int),
        }
    }
}

impl OnboardLaw for Mellinger {
    fn reset(&mut self) {
        self.reset_integrators();
        self.prev_omega_rp = [0.0; 2];
    }

    fn step(&mut self, state: &OnboardState, sp: &OnboardSetpoint, dt_s: f64) -> MotorCommands {
        let out = self.step_full(state, sp, dt_s);
        MotorCommands(out.motors_pwm.map(|m| m / PWM_MAX))
    }

    fn rate_hz(&self) -> f64 {
        self.cfg.rate_hz
    }
}

#[cfg(test)]
mod tests {
    use super::super::MellingerGains;
    use super::*;
    use nalgebra::UnitQuaternion;

    fn hover_state(q: UnitQuaternion<f64>) -> OnboardState {
        OnboardState {
            p_m: Vector3::new(0.0, 0.0, 1.0),
            v_m_s: Vector3::zeros(),
            q,
            w_body_rad_s: Vector3::zeros(),
        }
    }

    fn hover_sp() -> OnboardSetpoint {
        OnboardSetpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0)
    }

    #[test]
    fn hover_at_setpoint_gives_equal_motors_at_the_hover_command() {
        let cfg = OnboardConfig::cf21bl_2025_09();
        let mut c = Mellinger::new(cfg);
        let dt = 1.0 / c.rate_hz();
        let mut last = MotorCommands::default();
        for _ in 0..100 {
            last = c.step(&hover_state(UnitQuaternion::identity()), &hover_sp(), dt);
        }
        let hover_pwm = (cfg.mass_kg * cfg.gravity_m_s2 * cfg.mass_thrust).trunc();
        for m in last.0 {
            assert!(
                (m - hover_pwm / PWM_MAX).abs() < 1e-12,
                "{m} vs {}",
                hover_pwm / PWM_MAX
            );
        }
        // 0.0393 kg · 9.81 · 132000 = 50890.8 counts.
        assert!((hover_pwm - 50890.0).abs() < 1.0);
        let (ip, im) = c.integrators();
        assert!(ip.norm() < 1e-15 && im.norm() < 1e-15);
    }

    #[test]
    fn roll_error_gives_the_right_motor_pattern() {
        // Rolled right wing down (+x about FLU x): the controller must roll back, so the right
        // motors (1, 2) rise and the left (3, 4) fall; pitch and yaw stay balanced.
        let mut c = Mellinger::new(OnboardConfig::cf21bl_2025_09());
        let q = UnitQuaternion::from_euler_angles(0.05, 0.0, 0.0);
        let out = c.step_full(&hover_state(q), &hover_sp(), 0.002);
        assert!(out.control.roll < -1000.0, "roll {}", out.control.roll);
        assert!(
            out.control.pitch.abs() < 50.0,
            "pitch {}",
            out.control.pitch
        );
        let [m1, m2, m3, m4] = out.motors_pwm;
        assert!(m1 > m4 + 1000.0 && m2 > m3 + 1000.0, "{:?}", out.motors_pwm);
        assert!(
            (m1 - m2).abs() < 60.0 && (m3 - m4).abs() < 60.0,
            "{:?}",
            out.motors_pwm
        );

        // Nose up (negative FLU pitch): the front motors (1, 4) fall to bring the nose down.
        let mut c = Mellinger::new(OnboardConfig::cf21bl_2025_09());
        let q = UnitQuaternion::from_euler_angles(0.0, -0.05, 0.0);
        let out = c.step_full(&hover_state(q), &hover_sp(), 0.002);
        let [m1, m2, m3, m4] = out.motors_pwm;
        assert!(m2 > m1 + 1000.0 && m3 > m4 + 1000.0, "{:?}", out.motors_pwm);

        // A positive body roll rate is damped: the right motors rise.
        let mut c = Mellinger::new(OnboardConfig::cf21bl_2025_09());
        let mut s = hover_state(UnitQuaternion::identity());
        s.w_body_rad_s = Vector3::new(1.0, 0.0, 0.0);
        c.step_full(&s, &hover_sp(), 0.002);
        let out = c.step_full(&s, &hover_sp(), 0.002);
        assert!(out.control.roll < 0.0);
        assert!(out.motors_pwm[0] > out.motors_pwm[3]);
    }

    #[test]
    fn capping_subtracts_the_excess_and_floors_at_idle() {
        let idle = 10000.0;
        let c = LegacyControl {
            thrust: 64000.0,
            roll: -8000.0,
            pitch: 0.0,
            yaw: 0.0,
        };
        // Uncapped: right motors 68000, left 60000; the excess 2465 comes off all four.
        let m = legacy_power_distribution(&c, idle, true);
        assert_eq!(m, [65535.0, 65535.0, 57535.0, 57535.0]);
        let low = LegacyControl {
            thrust: 12000.0,
            roll: 0.0,
            pitch: 0.0,
            yaw: 5000.0,
        };
        let m = legacy_power_distribution(&low, idle, true);
        assert_eq!(m, [17000.0, idle, 17000.0, idle]);
        // Integer truncation of r = roll / 2 toward zero.
        let odd = LegacyControl {
            thrust: 30000.0,
            roll: -3.0,
            pitch: 0.0,
            yaw: 0.0,
        };
        assert_eq!(legacy_power_distribution(&odd, 0.0, true)[0], 30001.0);
        assert_eq!(legacy_power_distribution(&odd, 0.0, false)[0], 30001.5);
    }

    #[test]
    fn integrators_accumulate_clamp_and_reset() {
        let cfg = OnboardConfig::cf21bl_2025_09();
        let mut c = Mellinger::new(cfg);
        let mut s = hover_state(UnitQuaternion::identity());
        s.p_m.z = 0.5; // 0.5 m below the setpoint
        for _ in 0..10 {
            c.step(&s, &hover_sp(), 0.002);
        }
        let (ip, _) = c.integrators();
        assert!((ip.z - 0.01).abs() < 1e-12, "{}", ip.z);
        for _ in 0..2000 {
            c.step(&s, &hover_sp(), 0.002);
        }
        assert_eq!(c.integrators().0.z, cfg.gains.i_range_z);
        c.reset();
        assert_eq!(c.integrators().0, Vector3::zeros());
        // A non-positive thrust zeroes the moments and clears the integrators (the firmware's
        // in-step reset), and the motors sit at idle.
        for _ in 0..10 {
            c.step(&s, &hover_sp(), 0.002);
        }
        let mut free_fall = hover_sp();
        free_fall.a_m_s2.z = -30.0;
        let out = c.step_full(&s, &free_fall, 0.002);
        assert_eq!(out.control.roll, 0.0);
        assert_eq!(c.integrators().0, Vector3::zeros());
        assert_eq!(out.motors_pwm, [10000.0; 4]);
    }

    #[test]
    fn config_round_trips_through_json() {
        let mut cfg = OnboardConfig::cf21bl_2025_09();
        cfg.roll_trim = 123.0;
        let dir = std::env::temp_dir().join(format!("onboard-cfg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("onboard.json");
        cfg.save(&path).unwrap();
        assert_eq!(OnboardConfig::load(&path).unwrap(), cfg);
        std::fs::write(&path, r#"{"mass_thrust": 120000.0}"#).unwrap();
        let partial = OnboardConfig::load(&path).unwrap();
        assert_eq!(partial.mass_thrust, 120000.0);
        assert_eq!(partial.gains, MellingerGains::cf21bl_2025_09());
        std::fs::write(&path, r#"{"rate_hz": 0.0}"#).unwrap();
        assert!(OnboardConfig::load(&path).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn axes_invert_the_distribution() {
        let c = LegacyControl {
            thrust: 40000.0,
            roll: 2000.0,
            pitch: -1000.0,
            yaw: 300.0,
        };
        let m = MotorCommands(legacy_power_distribution(&c, 0.0, false).map(|x| x / PWM_MAX));
        let [t, r, p, y] = m.axes();
        assert!((t * PWM_MAX - 40000.0).abs() < 1e-6);
        assert!((r * PWM_MAX - 2000.0).abs() < 1e-6);
        assert!((p * PWM_MAX + 1000.0).abs() < 1e-6);
        assert!((y * PWM_MAX - 300.0).abs() < 1e-6);
    }
}
