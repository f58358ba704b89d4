//! `bitcraze-loop --mellinger-reference FILE`: Bitcraze's own Mellinger (the C, through
//! [`ffi::BcController`]) and hamflight's port (`host_train::control::onboard::Mellinger`) fed
//! the same SYNTHETIC inputs (an analytic aggressive climbing spiral with attitude, rate and
//! position errors, a saturating roll excursion and a free-fall reference; never the
//! benchmark's data), one 500 Hz controller step per row. Writes the inputs and the C's motor
//! commands (PWM counts) as CSV, the fixture `host-train/tests/data/mellinger_c_reference.csv`
//! that host-train's test checks the port against; prints the largest difference.

use crate::ffi::{self, BcController, BcKind, BcSetpoint, BcState};
use anyhow::{Context, Result};
use host_train::control::{Mellinger, OnboardConfig, OnboardLaw};
use host_train::io::{OnboardSetpoint, OnboardState};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::fmt::Write as _;
use std::path::Path;

/// The controller mass both are given (cf21bl's `CF_MASS`).
pub const MASS_KG: f32 = 0.0393;
/// Rows (500 Hz).
pub const ROWS: usize = 600;

/// The fixture's header.
pub const HEADER: &str = "t_s,px_m,py_m,pz_m,vx_m_s,vy_m_s,vz_m_s,qw,qx,qy,qz,wx_rad_s,wy_rad_s,wz_rad_s,\
ref_px_m,ref_py_m,ref_pz_m,ref_vx_m_s,ref_vy_m_s,ref_vz_m_s,ref_ax_m_s2,ref_ay_m_s2,ref_az_m_s2,ref_yaw_rad,\
c_pwm1,c_pwm2,c_pwm3,c_pwm4";

/// One row's inputs, already rounded to f32 (what the C sees).
pub struct Inputs {
    /// Time, s.
    pub t_s: f64,
    /// The state.
    pub state: OnboardState,
    /// The reference.
    pub sp: OnboardSetpoint,
}

fn r32(x: f64) -> f64 {
    x as f32 as f64
}

fn v32(v: Vector3<f64>) -> Vector3<f64> {
    v.map(r32)
}

/// The synthetic inputs of row `k`.
pub fn inputs(k: usize) -> Inputs {
    let t = k as f64 / 500.0;
    // Reference: a climbing spiral, radius 0.5 m at 2.5 rad/s, yaw swinging.
    let (r, w) = (0.5, 2.5);
    let p_ref = Vector3::new(r * (w * t).cos(), r * (w * t).sin(), 1.0 + 0.3 * t);
    let v_ref = Vector3::new(-r * w * (w * t).sin(), r * w * (w * t).cos(), 0.3);
    let mut a_ref = Vector3::new(-r * w * w * (w * t).cos(), -r * w * w * (w * t).sin(), 0.0);
    if (540..570).contains(&k) {
        a_ref.z = -15.0; // thrust below zero: the in-step reset
    }
    let yaw_ref = 0.5 * (1.3 * t).sin();
    // State: the reference with errors.
    let p = p_ref
        + Vector3::new(
            0.1 * (5.0 * t).sin(),
            0.08 * (7.0 * t).cos(),
            0.05 * (3.0 * t).sin(),
        );
    let v = v_ref
        + Vector3::new(
            0.2 * (4.0 * t).cos(),
            -0.2 * (6.0 * t).sin(),
            0.1 * (9.0 * t).cos(),
        );
    // The attitude: near the one the reference needs (tilted toward the spiral's centre),
    // with errors, and a saturating roll excursion.
    let big = if (400..470).contains(&k) { 0.6 } else { 0.0 };
    let a_c = r * w * w / 9.81;
    let roll = -a_c * (w * t).sin() * 0.9 + 0.04 * (6.0 * t).sin() + big;
    let pitch = a_c * (w * t).cos() * 0.9 + 0.03 * (5.0 * t).cos() - 0.01;
    let yaw = yaw_ref + 0.08 * (2.0 * t).sin();
    let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
    let jitter = |a: f64| 0.01 * (a * k as f64).sin();
    let wb = Vector3::new(
        0.3 * (6.0 * t).cos() + jitter(1.7),
        -0.2 * (5.0 * t).sin() + jitter(2.3),
        0.4 * (2.0 * t).cos() + jitter(0.9),
    );
    let qc = q.into_inner().coords.map(r32);
    Inputs {
        t_s: t,
        state: OnboardState {
            p_m: v32(p),
            v_m_s: v32(v),
            q: UnitQuaternion::new_unchecked(Quaternion::new(qc.w, qc.x, qc.y, qc.z)),
            w_body_rad_s: v32(wb),
        },
        sp: OnboardSetpoint {
            p_m: v32(p_ref),
            v_m_s: v32(v_ref),
            a_m_s2: v32(a_ref),
            yaw_rad: r32(yaw_ref),
        },
    }
}

/// The port's configuration matching the C build here (idle floor 0: `cf2_defconfig` does not
/// arm, so the firmware's idle thrust is 0).
pub fn port_config() -> OnboardConfig {
    let mut c = OnboardConfig::cf21bl_2025_09();
    c.mass_kg = MASS_KG as f64;
    c.idle_cmd = 0.0;
    c
}

/// Runs both and writes the fixture; returns the largest |C − port| in PWM counts.
pub fn run(path: &Path) -> Result<f64> {
    let platform = ffi::platform();
    let mut c = BcController::new(BcKind::Mellinger, MASS_KG)?;
    let mut port = Mellinger::new(port_config());
    let mut text = String::from(HEADER);
    text.push('\n');
    let mut worst = 0.0f64;
    // Every input is an f32 value; printed as f32 (shortest exact form), it reads back exact.
    let f = |x: f64| x as f32;
    for k in 0..ROWS {
        let inp = inputs(k);
        let (s, sp) = (&inp.state, &inp.sp);
        let q = s.q.into_inner();
        let bs = BcState {
            p_m: s.p_m.map(|x| x as f32).into(),
            v_m_s: s.v_m_s.map(|x| x as f32).into(),
            q_xyzw: [q.i as f32, q.j as f32, q.k as f32, q.w as f32],
            rpy_deg: [0.0; 3],
            acc_g: [0.0; 3],
        };
        let bsp = BcSetpoint {
            p_m: sp.p_m.map(|x| x as f32).into(),
            v_m_s: sp.v_m_s.map(|x| x as f32).into(),
            a_m_s2: sp.a_m_s2.map(|x| x as f32).into(),
            j_m_s3: [0.0; 3],
            yaw_deg: (sp.yaw_rad as f32).to_degrees(),
        };
        let gyro_dps: [f32; 3] = s.w_body_rad_s.map(|x| (x as f32).to_degrees()).into();
        let mut motor_n = [0.0f32; 4];
        // The stabilizer ticks at 1 kHz; Mellinger executes on even ticks (500 Hz).
        c.step(
            &bsp,
            &[0.0; 3],
            &gyro_dps,
            &bs,
            (2 * k) as u32,
            &mut motor_n,
        );
        let c_pwm =
            motor_n.map(|f| (f64::from(f) / f64::from(platform.thrust_max_n) * 65535.0).round());
        let ours = port.step(s, sp, 0.002).0.map(|m| m * 65535.0);
        for i in 0..4 {
            worst = worst.max((c_pwm[i] - ours[i]).abs());
        }
        let _ = writeln!(
            text,
            "{:.4},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            inp.t_s,
            f(s.p_m.x), f(s.p_m.y), f(s.p_m.z), f(s.v_m_s.x), f(s.v_m_s.y), f(s.v_m_s.z),
            f(q.w), f(q.i), f(q.j), f(q.k),
            f(s.w_body_rad_s.x), f(s.w_body_rad_s.y), f(s.w_body_rad_s.z),
            f(sp.p_m.x), f(sp.p_m.y), f(sp.p_m.z), f(sp.v_m_s.x), f(sp.v_m_s.y), f(sp.v_m_s.z),
            f(sp.a_m_s2.x), f(sp.a_m_s2.y), f(sp.a_m_s2.z), f(sp.yaw_rad),
            c_pwm[0], c_pwm[1], c_pwm[2], c_pwm[3]
        );
    }
    host_train::io::write_atomic(path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(worst)
}
