//! Synthetic closed-loop logs: a known plant flown by the onboard controller along a
//! scenario's reference, logged as the benchmark logs are (100 Hz rows of the state, the
//! reference without its acceleration, the motor commands and the measured rotor speeds in
//! eRPM), with noise on the logged rotor speeds. The replay and the fit are tested on them.

use super::closed_loop::{RotorMap, ERPM_PER_RPM};
use crate::control::onboard::{Mellinger, OnboardConfig, OnboardLaw};
use crate::io::{LoopFlight, OnboardSetpoint, OnboardState};
use crate::sim::plant::gaussian;
use crate::sim::scenario::Scenario;
use nalgebra::{UnitQuaternion, Vector3};
use rand::SeedableRng;

/// How the synthetic log is made.
#[derive(Clone, Copy, Debug)]
pub struct SyntheticLog {
    /// Log rows per second.
    pub row_hz: f64,
    /// Controller steps per row.
    pub substeps: usize,
    /// Flight length (s).
    pub duration_s: f64,
    /// White noise on each logged rotor speed, as a fraction of the hover speed.
    pub rpm_noise_frac: f64,
    /// Noise seed.
    pub seed: u64,
}

impl Default for SyntheticLog {
    fn default() -> Self {
        Self {
            row_hz: 100.0,
            substeps: 5,
            duration_s: 20.0,
            rpm_noise_frac: 0.05,
            seed: 0,
        }
    }
}

/// The command → speed map of the benchmark's training flights (`host-train replay` prints
/// the fit: rpm² = 6.64e7 + 3.39e8 · command).
pub const BENCHMARK_MAP: RotorMap = RotorMap {
    offset_rpm2: 6.6397e7,
    rpm2_per_cmd: 3.3927e8,
};

/// `truth` flown from its start by `controller` along its own reference, logged.
pub fn fly_log(
    truth: &Scenario,
    controller: &OnboardConfig,
    map: &RotorMap,
    opt: &SyntheticLog,
) -> LoopFlight {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(opt.seed);
    let mut plant = truth.plant();
    let hover = truth.vehicle.hover_rpm();
    let mut law = Mellinger::new(*controller);
    law.reset();
    let sub = opt.substeps.max(1);
    let dt = 1.0 / (opt.row_hz * sub as f64);
    let rows = (opt.duration_s * opt.row_hz) as usize;
    let mut f = LoopFlight {
        name: truth.name.clone(),
        ..LoopFlight::default()
    };
    let mut t = 0.0;
    for _ in 0..rows {
        let ps = *plant.state();
        let st = OnboardState {
            p_m: ps.p_m,
            v_m_s: ps.rot * ps.v_body_m_s,
            q: UnitQuaternion::from_matrix(&ps.rot),
            w_body_rad_s: ps.w_body_rad_s,
        };
        let r = truth.reference(t);
        let logged_sp = OnboardSetpoint {
            p_m: r.p_m,
            v_m_s: r.v_m_s,
            a_m_s2: Vector3::zeros(),
            yaw_rad: r.yaw_rad,
        };
        let rpm = plant.rotor_rpm();
        f.t_s.push(t);
        f.state.push(st);
        f.setpoint.push(logged_sp);
        f.erpm.push(
            rpm.map(|w| (w + opt.rpm_noise_frac * hover * gaussian(&mut rng)) * ERPM_PER_RPM),
        );
        f.vbat_v.push(4.0);
        // The setpoint is held over the row, as the replay holds the logged one.
        let sp = OnboardSetpoint {
            a_m_s2: r.a_m_s2,
            ..logged_sp
        };
        let mut last = crate::io::MotorCommands::default();
        for _ in 0..sub {
            let ps = *plant.state();
            let st = OnboardState {
                p_m: ps.p_m,
                v_m_s: ps.rot * ps.v_body_m_s,
                q: UnitQuaternion::from_matrix(&ps.rot),
                w_body_rad_s: ps.w_body_rad_s,
            };
            last = law.step(&st, &sp, dt);
            plant.step(map.rpm(&last), dt);
        }
        f.cmd.push(last);
        t += 1.0 / opt.row_hz;
    }
    f
}
