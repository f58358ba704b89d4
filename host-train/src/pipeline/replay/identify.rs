//! Identification with the loop closed: the plant's torque gains and flapping moment fitted
//! against the closed-loop replay error (output error with the known onboard controller), and,
//! for comparison, the open-loop one-step regression of the logged angular acceleration on the
//! torques of the logged rotor speeds, which noisy speeds bias toward zero.

use super::closed_loop::{airborne, ReplayConfig, Warmed, ERPM_PER_RPM};
use crate::io::LoopFlight;
use crate::sim::plant::{Residual, ROTOR_XY_SIGN, ROTOR_YAW_SIGN};
use crate::sim::scenario::Scenario;
use serde::{Deserialize, Serialize};

pub use super::closed_loop::MAX_ERPM;

/// The plant terms the loop identifies, on top of a base vehicle (the published rigid body).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlantTerms {
    /// Effective gain of each rotor torque (roll, pitch, yaw); 1 = the rigid body.
    pub torque_gain: [f64; 3],
    /// The rotors' flapping moment, rad/s² per m/s: ω̇ₓ = +k v_y, ω̇ᵧ = −k v_x (body frame).
    pub flap_rad_s2_per_m_s: f64,
}

impl PlantTerms {
    /// The rigid body.
    pub const RIGID: Self = Self {
        torque_gain: [1.0; 3],
        flap_rad_s2_per_m_s: 0.0,
    };

    /// `base` with these terms as its residual (any residual it had is replaced).
    pub fn apply(&self, base: &Scenario) -> Scenario {
        let mut s = base.clone();
        let mut apv = [[0.0; 6]; 6];
        apv[3][1] = self.flap_rad_s2_per_m_s;
        apv[4][0] = -self.flap_rad_s2_per_m_s;
        s.spec.effects.residual = Some(Residual {
            thrust_gain: 1.0,
            torque_gain: self.torque_gain,
            torque_lag_s: 0.0,
            accel_per_velocity: apv,
            accel_bias: [0.0; 6],
            thrust_lag_s: 0.0,
            accel_per_tilt: [[0.0; 2]; 3],
        });
        s
    }
}

/// What the closed-loop fit found.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LoopFit {
    /// The identified terms.
    pub terms: PlantTerms,
    /// Its objective (the replay's mean squared errors, each over the rigid body's).
    pub objective: f64,
    /// Objective evaluations used.
    pub evaluations: usize,
}

/// The fit's objective: the closed-loop windows' mean squared attitude and position errors,
/// each relative to the rigid body's (so neither unit dominates).
fn objective(
    warm: &Warmed,
    base: &Scenario,
    cfg: &ReplayConfig,
    norm: (f64, f64),
    t: &PlantTerms,
) -> f64 {
    let e = warm.score(&t.apply(base), cfg);
    let n = e.steps.max(1) as f64;
    e.att_sq_rad2 / n / norm.0 + e.pos_sq_m2 / n / norm.1
}

/// Fits the torque gains and the flapping moment by Nelder–Mead on the closed-loop replay
/// error of `steps`-row windows every `stride` rows, from the rigid body.
pub fn fit_loop(
    flights: &[&LoopFlight],
    base: &Scenario,
    cfg: &ReplayConfig,
    steps: usize,
    stride: usize,
    max_evals: usize,
) -> LoopFit {
    let warm = Warmed::new(flights, cfg, steps, stride);
    let e0 = warm.score(&PlantTerms::RIGID.apply(base), cfg);
    let n0 = e0.steps.max(1) as f64;
    let norm = (
        (e0.att_sq_rad2 / n0).max(1e-12),
        (e0.pos_sq_m2 / n0).max(1e-12),
    );
    // x = (ln g_roll, ln g_pitch, ln g_yaw, k / 5): gains stay positive.
    let terms = |x: &[f64; 4]| PlantTerms {
        torque_gain: [x[0].exp(), x[1].exp(), x[2].exp()],
        flap_rad_s2_per_m_s: 5.0 * x[3],
    };
    let f = |x: &[f64; 4]| objective(&warm, base, cfg, norm, &terms(x));
    let (x, fx, evals) = nelder_mead(f, [0.0; 4], 0.5, max_evals);
    LoopFit {
        terms: terms(&x),
        objective: fx,
        evaluations: evals,
    }
}

/// Minimizes `f` from `x0` with initial steps `step`, for at most `max_evals` evaluations:
/// (best point, its value, evaluations).
pub fn nelder_mead<const N: usize>(
    f: impl Fn(&[f64; N]) -> f64,
    x0: [f64; N],
    step: f64,
    max_evals: usize,
) -> ([f64; N], f64, usize) {
    let evals = core::cell::Cell::new(0usize);
    let eval = |x: &[f64; N]| {
        evals.set(evals.get() + 1);
        let v = f(x);
        if v.is_finite() {
            v
        } else {
            f64::MAX
        }
    };
    let mut simplex: Vec<([f64; N], f64)> = Vec::with_capacity(N + 1);
    let v0 = eval(&x0);
    simplex.push((x0, v0));
    for i in 0..N {
        let mut x = x0;
        x[i] += step;
        let v = eval(&x);
        simplex.push((x, v));
    }
    while evals.get() < max_evals {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let (best, worst) = (simplex[0].1, simplex[N].1);
        if (worst - best).abs() <= 1e-6 * best.abs().max(1e-12) {
            break;
        }
        let mut c = [0.0; N];
        for (x, _) in &simplex[..N] {
            for (ci, xi) in c.iter_mut().zip(x) {
                *ci += xi / N as f64;
            }
        }
        let along =
            |t: f64| -> [f64; N] { core::array::from_fn(|i| c[i] + t * (simplex[N].0[i] - c[i])) };
        let xr = along(-1.0);
        let vr = eval(&xr);
        if vr < simplex[0].1 {
            let xe = along(-2.0);
            let ve = eval(&xe);
            simplex[N] = if ve < vr { (xe, ve) } else { (xr, vr) };
        } else if vr < simplex[N - 1].1 {
            simplex[N] = (xr, vr);
        } else {
            let xc = if vr < simplex[N].1 {
                along(-0.5)
            } else {
                along(0.5)
            };
            let vc = eval(&xc);
            if vc < simplex[N].1.min(vr) {
                simplex[N] = (xc, vc);
            } else {
                let x_best = simplex[0].0;
                for s in simplex.iter_mut().skip(1) {
                    s.0 = core::array::from_fn(|i| x_best[i] + 0.5 * (s.0[i] - x_best[i]));
                    s.1 = eval(&s.0);
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    (simplex[0].0, simplex[0].1, evals.get())
}

/// The open-loop estimate of the torque gains: per axis, the least-squares slope of the
/// logged angular acceleration (central difference of the logged rate, less the gyroscopic
/// term) on the rigid torque of the logged rotor speeds, through J⁻¹; with a flapping
/// regressor (body velocity) beside it on roll and pitch. The speeds' noise biases it toward
/// zero (errors in the regressor), which the closed-loop fit does not suffer.
pub fn fit_open_loop(flights: &[&LoopFlight], base: &Scenario) -> PlantTerms {
    let prm = &base.vehicle;
    let j = prm.inertia_kg_m2;
    let a = prm.arm_xy_m;
    // Normal equations per axis: [torque accel, flap regressor].
    let mut ata = [[[0.0; 2]; 2]; 3];
    let mut atb = [[0.0; 2]; 3];
    for f in flights {
        for k in 1..f.len().saturating_sub(1) {
            if !(airborne(f, k - 1) && airborne(f, k) && airborne(f, k + 1)) {
                continue;
            }
            let rpm = f.erpm[k].map(|e| e / ERPM_PER_RPM);
            // Telemetry glitches (far above the 1.45e5 eRPM the motors reach) would dominate
            // the sums.
            if !rpm
                .iter()
                .all(|r| r.is_finite() && *r * ERPM_PER_RPM < MAX_ERPM)
            {
                continue;
            }
            let dt = f.t_s[k + 1] - f.t_s[k - 1];
            if dt <= 0.0 {
                continue;
            }
            let w = f.state[k].w_body_rad_s;
            let wdot = (f.state[k + 1].w_body_rad_s - f.state[k - 1].w_body_rad_s) / dt;
            let jw = nalgebra::Vector3::new(j[0] * w.x, j[1] * w.y, j[2] * w.z);
            let gyro = jw.cross(&w);
            let (mut tx, mut ty, mut tz) = (0.0, 0.0, 0.0);
            for i in 0..4 {
                let t = prm.kf_n_per_rpm2 * rpm[i] * rpm[i];
                tx += ROTOR_XY_SIGN[i][1] * a * t;
                ty -= ROTOR_XY_SIGN[i][0] * a * t;
                tz += ROTOR_YAW_SIGN[i] * prm.km_nm_per_rpm2 * rpm[i] * rpm[i];
            }
            let rot = f.state[k].q.to_rotation_matrix().into_inner();
            let vb = rot.transpose() * f.state[k].v_m_s;
            let rows = [
                (tx / j[0], vb.y, wdot.x - gyro.x / j[0]),
                (ty / j[1], -vb.x, wdot.y - gyro.y / j[1]),
                (tz / j[2], 0.0, wdot.z - gyro.z / j[2]),
            ];
            for (ax, (u, v, y)) in rows.into_iter().enumerate() {
                let x = [u, v];
                for r in 0..2 {
                    for c in 0..2 {
                        ata[ax][r][c] += x[r] * x[c];
                    }
                    atb[ax][r] += x[r] * y;
                }
            }
        }
    }
    let solve = |m: [[f64; 2]; 2], b: [f64; 2], two: bool| -> [f64; 2] {
        if !two {
            return [
                if m[0][0] > 0.0 {
                    b[0] / m[0][0]
                } else {
                    f64::NAN
                },
                0.0,
            ];
        }
        let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
        if det.abs() < 1e-300 {
            return [f64::NAN; 2];
        }
        [
            (b[0] * m[1][1] - m[0][1] * b[1]) / det,
            (m[0][0] * b[1] - m[1][0] * b[0]) / det,
        ]
    };
    let r = solve(ata[0], atb[0], true);
    let p = solve(ata[1], atb[1], true);
    let y = solve(ata[2], atb[2], false);
    PlantTerms {
        torque_gain: [r[0], p[0], y[0]],
        flap_rad_s2_per_m_s: 0.5 * (r[1] + p[1]),
    }
}
