//! The Crazyflie's sensor chain and estimator in the SITL loop (a scenario's `[sensors]` table):
//! what a real vehicle gives the controller instead of the true state.
//!
//! - **IMU** sampled at the physics rate (1 kHz by default, as the Crazyflie's sensor task): body
//!   rates and specific force with white noise and a constant bias (defaults near the BMI088's
//!   noise densities, 0.014 °/s/√Hz and 175 µg/√Hz, over a 500 Hz band).
//! - **Filters as the firmware configures them:** a 2-pole Butterworth low-pass on each gyro
//!   axis at 80 Hz and on each accelerometer axis at 30 Hz, at the IMU rate ([`Lpf2p`]; about
//!   2.8 ms of group delay at low frequency for the gyro's).
//! - **A pose source** (motion capture, or Lighthouse-like with more noise and no attitude) at a
//!   configurable rate and latency.
//! - **The state estimator:** our error-state EKF ([`crate::sim::ekf`]), predicting at 100 Hz with the
//!   mean filtered IMU, in-flight model (thrust-axis specific force only), pose updates as they
//!   arrive. `estimator = "truth"` keeps the true p, v, R and leaves only the IMU chain on the
//!   body rates.
//! - **What the controller gets:** p, v, R from the estimate, ω from the filtered gyro, the
//!   filtered accelerometer for the composite law, all as they were `delay_samples` IMU samples
//!   ago (the stabilizer's one-tick delay between estimate and controller).
//!
//! ```toml
//! [sensors]
//! gyro_lpf_hz = 80.0            # 0 = no filter
//! acc_lpf_hz = 30.0
//! gyro_noise_rad_s = 0.005      # σ per sample
//! gyro_bias_rad_s = [0.0, 0.0, 0.0]
//! acc_noise_m_s2 = 0.04
//! acc_bias_m_s2 = [0.0, 0.0, 0.0]
//! estimator = "ekf"             # or "truth"
//! predict_hz = 100.0
//! pose_hz = 100.0
//! pose_latency_s = 0.0
//! pose_pos_noise_m = 0.0005     # σ of the pose source
//! pose_att_noise_rad = 0.002
//! pose_attitude = true          # false: position only (Lighthouse-like)
//! ekf_pos_std_m = 0.01          # σ the filter assumes for the pose (the Crazyflie's defaults)
//! ekf_att_std_rad = 0.0045
//! delay_samples = 1
//! seed = 7                      # the chain's own noise stream
//! ```

use std::collections::VecDeque;

use nalgebra::{Matrix3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::sim::ekf::{Ekf, EkfTuning};
use crate::sim::plant::{gaussian, so3_exp, Plant, PlantState};

/// Which state the controller's p, v and R come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum EstimatorKind {
    /// The error-state EKF fed by the IMU and the pose source.
    #[default]
    Ekf,
    /// The true p, v, R (only the body rates and the accelerometer go through the IMU chain).
    Truth,
}

/// The `[sensors]` table (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorSpec {
    /// Gyro low-pass cutoff (Hz); 0 turns it off.
    pub gyro_lpf_hz: f64,
    /// Accelerometer low-pass cutoff (Hz); 0 turns it off.
    pub acc_lpf_hz: f64,
    /// Gyro white noise σ per sample (rad/s).
    pub gyro_noise_rad_s: f64,
    /// Gyro bias (rad/s, body).
    pub gyro_bias_rad_s: [f64; 3],
    /// Accelerometer white noise σ per sample (m/s²).
    pub acc_noise_m_s2: f64,
    /// Accelerometer bias (m/s², body).
    pub acc_bias_m_s2: [f64; 3],
    /// The estimator.
    pub estimator: EstimatorKind,
    /// The EKF's prediction rate (Hz).
    pub predict_hz: f64,
    /// The pose source's rate (Hz).
    pub pose_hz: f64,
    /// The pose source's latency (s).
    pub pose_latency_s: f64,
    /// The pose source's position noise σ (m).
    pub pose_pos_noise_m: f64,
    /// The pose source's attitude noise σ (rad).
    pub pose_att_noise_rad: f64,
    /// Whether the pose source gives attitude.
    pub pose_attitude: bool,
    /// The position σ the EKF assumes (m).
    pub ekf_pos_std_m: f64,
    /// The attitude σ the EKF assumes (rad).
    pub ekf_att_std_rad: f64,
    /// IMU samples between the estimate and the controller.
    pub delay_samples: usize,
    /// Seed of the chain's noise stream.
    pub seed: u64,
}

impl Default for SensorSpec {
    fn default() -> Self {
        Self {
            gyro_lpf_hz: 80.0,
            acc_lpf_hz: 30.0,
            gyro_noise_rad_s: 0.005,
            gyro_bias_rad_s: [0.0; 3],
            acc_noise_m_s2: 0.04,
            acc_bias_m_s2: [0.0; 3],
            estimator: EstimatorKind::Ekf,
            predict_hz: 100.0,
            pose_hz: 100.0,
            pose_latency_s: 0.0,
            pose_pos_noise_m: 0.0005,
            pose_att_noise_rad: 0.002,
            pose_attitude: true,
            ekf_pos_std_m: 0.01,
            ekf_att_std_rad: 0.0045,
            delay_samples: 1,
            seed: 7,
        }
    }
}

impl SensorSpec {
    /// Checks every key; errors name the key.
    pub fn validate(&self) -> anyhow::Result<()> {
        let nonneg = |k: &str, x: f64| -> anyhow::Result<()> {
            if x.is_finite() && x >= 0.0 {
                Ok(())
            } else {
                anyhow::bail!("key `sensors.{k}`: expected a finite number ≥ 0, got {x}")
            }
        };
        let pos = |k: &str, x: f64| -> anyhow::Result<()> {
            if x.is_finite() && x > 0.0 {
                Ok(())
            } else {
                anyhow::bail!("key `sensors.{k}`: expected a positive number, got {x}")
            }
        };
        nonneg("gyro_lpf_hz", self.gyro_lpf_hz)?;
        nonneg("acc_lpf_hz", self.acc_lpf_hz)?;
        nonneg("gyro_noise_rad_s", self.gyro_noise_rad_s)?;
        nonneg("acc_noise_m_s2", self.acc_noise_m_s2)?;
        nonneg("pose_latency_s", self.pose_latency_s)?;
        nonneg("pose_pos_noise_m", self.pose_pos_noise_m)?;
        nonneg("pose_att_noise_rad", self.pose_att_noise_rad)?;
        pos("predict_hz", self.predict_hz)?;
        pos("pose_hz", self.pose_hz)?;
        pos("ekf_pos_std_m", self.ekf_pos_std_m)?;
        pos("ekf_att_std_rad", self.ekf_att_std_rad)?;
        if !self
            .gyro_bias_rad_s
            .iter()
            .chain(&self.acc_bias_m_s2)
            .all(|x| x.is_finite())
        {
            anyhow::bail!(
                "keys `sensors.gyro_bias_rad_s`, `acc_bias_m_s2`: expected finite numbers"
            );
        }
        if self.delay_samples > 100 {
            anyhow::bail!(
                "key `sensors.delay_samples`: expected at most 100 samples, got {}",
                self.delay_samples
            );
        }
        Ok(())
    }
}

/// A 2-pole Butterworth low-pass (a biquad from the bilinear transform with the cutoff
/// pre-warped): H(z) = b₀(1 + 2z⁻¹ + z⁻²) / (1 + a₁z⁻¹ + a₂z⁻²), unit gain at DC.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lpf2p {
    b0: f64,
    a1: f64,
    a2: f64,
    /// Direct form II state.
    d1: f64,
    d2: f64,
    /// Pass-through (cutoff 0 or at/above Nyquist).
    bypass: bool,
    primed: bool,
}

impl Lpf2p {
    /// A filter with cutoff `cutoff_hz` at sample rate `sample_hz`; a cutoff of 0 or at or above
    /// the Nyquist rate passes the input unchanged.
    pub fn new(sample_hz: f64, cutoff_hz: f64) -> Self {
        if !(cutoff_hz > 0.0 && cutoff_hz < 0.5 * sample_hz) {
            return Self {
                b0: 1.0,
                a1: 0.0,
                a2: 0.0,
                d1: 0.0,
                d2: 0.0,
                bypass: true,
                primed: false,
            };
        }
        let k = (core::f64::consts::PI * cutoff_hz / sample_hz).tan();
        let q = core::f64::consts::FRAC_1_SQRT_2;
        let norm = 1.0 / (1.0 + k / q + k * k);
        Self {
            b0: k * k * norm,
            a1: 2.0 * (k * k - 1.0) * norm,
            a2: (1.0 - k / q + k * k) * norm,
            d1: 0.0,
            d2: 0.0,
            bypass: false,
            primed: false,
        }
    }

    /// Filter one sample. The first sample primes the state to its steady value (no start-up
    /// transient).
    pub fn apply(&mut self, x: f64) -> f64 {
        if self.bypass {
            return x;
        }
        if !self.primed {
            // Steady state for a constant input x: w = x / (1 + a₁ + a₂).
            let w = x / (1.0 + self.a1 + self.a2);
            self.d1 = w;
            self.d2 = w;
            self.primed = true;
        }
        let w = x - self.a1 * self.d1 - self.a2 * self.d2;
        let y = self.b0 * (w + 2.0 * self.d1 + self.d2);
        self.d2 = self.d1;
        self.d1 = w;
        y
    }
}

/// What the controller is given at one tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerView {
    /// p, v, R from the estimate and ω from the filtered gyro.
    pub state: PlantState,
    /// The filtered accelerometer (m/s², body).
    pub acc_body_m_s2: Vector3<f64>,
}

/// A pose measurement in flight to the estimator.
#[derive(Clone, Copy, Debug)]
struct Pose {
    arrive_s: f64,
    p_m: Vector3<f64>,
    rot: Matrix3<f64>,
}

/// The chain of one flight (module docs).
#[derive(Clone, Debug)]
pub struct SensorChain {
    spec: SensorSpec,
    gyro: [Lpf2p; 3],
    acc: [Lpf2p; 3],
    ekf: Ekf,
    rng: ChaCha8Rng,
    sum_w: Vector3<f64>,
    sum_a: Vector3<f64>,
    n_sum: usize,
    next_predict_s: f64,
    next_pose_s: f64,
    last_predict_s: f64,
    poses: VecDeque<Pose>,
    views: VecDeque<ControllerView>,
}

impl SensorChain {
    /// A chain at rest on `initial`, sampling at `sample_hz` (the physics rate).
    pub fn new(spec: &SensorSpec, initial: &PlantState, sample_hz: f64) -> Self {
        let lpf = |c| [Lpf2p::new(sample_hz, c); 3];
        let ekf = Ekf::new(
            EkfTuning::default(),
            initial.p_m,
            initial.v_body_m_s,
            initial.rot,
        );
        Self {
            spec: spec.clone(),
            gyro: lpf(spec.gyro_lpf_hz),
            acc: lpf(spec.acc_lpf_hz),
            ekf,
            rng: ChaCha8Rng::seed_from_u64(spec.seed),
            sum_w: Vector3::zeros(),
            sum_a: Vector3::zeros(),
            n_sum: 0,
            next_predict_s: 1.0 / spec.predict_hz,
            next_pose_s: 0.0,
            last_predict_s: 0.0,
            poses: VecDeque::new(),
            views: VecDeque::new(),
        }
    }

    /// The estimator (for logs and tests).
    pub fn ekf(&self) -> &Ekf {
        &self.ekf
    }

    fn noise3(&mut self, sigma: f64) -> Vector3<f64> {
        if sigma > 0.0 {
            let rng = &mut self.rng;
            Vector3::new(gaussian(rng), gaussian(rng), gaussian(rng)) * sigma
        } else {
            Vector3::zeros()
        }
    }

    /// One IMU sample of `plant` at its current time: filters, estimator prediction and pose
    /// updates when due, and the view the controller will get.
    pub fn sample(&mut self, plant: &Plant) {
        let t = plant.t_s();
        let truth = *plant.state();
        let gyro_raw = truth.w_body_rad_s
            + Vector3::from(self.spec.gyro_bias_rad_s)
            + self.noise3(self.spec.gyro_noise_rad_s);
        let acc_raw = plant.accelerometer()
            + Vector3::from(self.spec.acc_bias_m_s2)
            + self.noise3(self.spec.acc_noise_m_s2);
        let gyro = Vector3::from_fn(|i, _| self.gyro[i].apply(gyro_raw[i]));
        let acc = Vector3::from_fn(|i, _| self.acc[i].apply(acc_raw[i]));
        self.sum_w += gyro;
        self.sum_a += acc;
        self.n_sum += 1;
        if self.spec.estimator == EstimatorKind::Ekf {
            if t + 1e-9 >= self.next_predict_s && self.n_sum > 0 {
                let n = self.n_sum as f64;
                let dt = t - self.last_predict_s;
                self.ekf
                    .predict(&(self.sum_w / n), &(self.sum_a / n), dt, true);
                self.sum_w = Vector3::zeros();
                self.sum_a = Vector3::zeros();
                self.n_sum = 0;
                self.last_predict_s = t;
                self.next_predict_s += 1.0 / self.spec.predict_hz;
            }
            if t + 1e-9 >= self.next_pose_s {
                let p_m = truth.p_m + self.noise3(self.spec.pose_pos_noise_m);
                let rot = truth.rot * so3_exp(&self.noise3(self.spec.pose_att_noise_rad));
                self.poses.push_back(Pose {
                    arrive_s: t + self.spec.pose_latency_s,
                    p_m,
                    rot,
                });
                self.next_pose_s += 1.0 / self.spec.pose_hz;
            }
            while self.poses.front().is_some_and(|p| p.arrive_s <= t + 1e-9) {
                let Some(p) = self.poses.pop_front() else {
                    break;
                };
                self.ekf.update_position(&p.p_m, self.spec.ekf_pos_std_m);
                if self.spec.pose_attitude {
                    self.ekf.update_attitude(&p.rot, self.spec.ekf_att_std_rad);
                }
            }
        }
        let state = match self.spec.estimator {
            EstimatorKind::Ekf => PlantState {
                p_m: self.ekf.p_m,
                rot: self.ekf.rot,
                v_body_m_s: self.ekf.v_body_m_s,
                w_body_rad_s: gyro,
            },
            EstimatorKind::Truth => PlantState {
                w_body_rad_s: gyro,
                ..truth
            },
        };
        self.views.push_back(ControllerView {
            state,
            acc_body_m_s2: acc,
        });
        while self.views.len() > self.spec.delay_samples + 1 {
            self.views.pop_front();
        }
    }

    /// What the controller sees now: the view of `delay_samples` samples ago (the oldest one
    /// kept), or `None` before the first sample.
    pub fn view(&self) -> Option<ControllerView> {
        self.views.front().copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Butterworth's textbook properties: unit DC gain, −3 dB at the cutoff, and the
    /// ≈ 2.8 ms low-frequency group delay of an 80 Hz filter.
    #[test]
    fn lpf2p_is_a_butterworth() {
        let fs = 1000.0;
        let gain_at = |f: f64| {
            let mut lp = Lpf2p::new(fs, 80.0);
            let (mut s, mut c) = (0.0, 0.0);
            let n = 4000;
            for k in 0..n {
                let t = k as f64 / fs;
                let y = lp.apply((core::f64::consts::TAU * f * t).sin());
                if k >= n / 2 {
                    s += y * (core::f64::consts::TAU * f * t).sin();
                    c += y * (core::f64::consts::TAU * f * t).cos();
                }
            }
            let m = (n / 2) as f64 / 2.0;
            ((s / m).hypot(c / m), (c / m).atan2(s / m))
        };
        let (g0, _) = gain_at(1.0);
        assert!((g0 - 1.0).abs() < 1e-3, "DC gain {g0}");
        let (gc, _) = gain_at(80.0);
        assert!(
            (gc - core::f64::consts::FRAC_1_SQRT_2).abs() < 0.02,
            "cutoff gain {gc}"
        );
        let f = 5.0;
        let (_, ph) = gain_at(f);
        let delay_ms = -ph / (core::f64::consts::TAU * f) * 1e3;
        assert!((delay_ms - 2.8).abs() < 0.3, "group delay {delay_ms} ms");
        let mut dc = Lpf2p::new(fs, 80.0);
        assert!(
            (dc.apply(3.0) - 3.0).abs() < 1e-12,
            "primed at the first sample"
        );
    }
}
