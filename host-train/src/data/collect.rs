//! Training data collection as in the paper's Sec. 4 (`host-train collect`): the DSL PID flies
//! the SITL plant to random poses under M disturbance realizations. The file format is
//! [`crate::io::dataset`]'s; this module only makes the flights.
//!
//! Defaults = paper Sec. 4: for each realization j the wind's x and y components are drawn from
//! ±`--wind-levels` (z = 0) and δ₁, δ₂ ~ U[0.94, 0.98] (δ₃ = δ₄ = 1); then for each of the 9
//! desired poses (x, y ∈ U[−1, 1] m, z ∈ U[0.5, 1.5] m, yaw ∈ U[−0.5, 0.5] rad) the vehicle
//! starts at a random state near it (position ± 0.5 m, roll/pitch ± 0.2 rad, velocity ± 0.3 m/s,
//! rates ± 0.5 rad/s) and the DSL PID flies to it. Each pose is one continuous flight of the
//! dataset. The PID is called every `window_len − 1` samples and its command held in between
//! (240/4 = 60 Hz), so the trainer's default windows (5 states every 4 samples) each see one
//! command, exactly the paper's windows. States are sampled at `--sample-hz` with physics at
//! `sample_hz × substeps`. Each realization has its own RNG stream of `--seed`.
//!
//! Beyond the paper: `--calm-realizations` (default 1) calm realizations follow the M disturbed
//! ones, marked disturbance-free, so that the shared model learns the undisturbed vehicle and
//! the a_j only what differs from it (calm-air identifiability, see docs/training.md).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::control::baselines::DslPid;
use crate::control::controller::Controller;
use crate::io::dataset::{self, Dataset, Flight, Manifest, Realization, RealizationMeta, Sample};
use crate::sim::plant::{rot_from_rpy, Disturbance, Effects, Plant, PlantState, VehicleParams};
use crate::sim::trajectory::TrajectoryPoint;

/// Settings of a collection run (defaults: the paper's Sec. 4).
///
/// A key left out of a typed job ([`CollectJob`]) takes the flag's default
/// ([`CollectConfig::default`], which the flags read too); an unknown key is an error.
#[derive(Args, Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CollectConfig {
    /// Number of disturbance realizations M.
    #[arg(long, default_value_t = CollectConfig::default().realizations)]
    pub realizations: usize,
    /// Windows per realization D_j (of `window_len` states, consecutive ones sharing an end
    /// state).
    #[arg(long, default_value_t = CollectConfig::default().windows)]
    pub windows: usize,
    /// Desired poses per realization; the PID flies from a random start to each in turn, and the
    /// windows are split evenly between them.
    #[arg(long, default_value_t = CollectConfig::default().poses)]
    pub poses: usize,
    /// State sample rate within a window (Hz).
    #[arg(long, default_value_t = CollectConfig::default().sample_hz)]
    pub sample_hz: f64,
    /// States per window N: the PID's command is held for N−1 sample intervals.
    #[arg(long, default_value_t = CollectConfig::default().window_len)]
    pub window_len: usize,
    /// Physics steps per sample interval (10 → 2400 Hz physics at 240 Hz sampling).
    #[arg(long, default_value_t = CollectConfig::default().substeps)]
    pub substeps: usize,
    /// Wind component magnitudes (m/s²) to draw x and y from, each with a random sign.
    #[arg(long, value_delimiter = ',', default_values_t = CollectConfig::default().wind_levels)]
    pub wind_levels: Vec<f64>,
    /// Lower bound of δ₁, δ₂ ~ U[delta_min, delta_max] (rotors 1 and 2; rotors 3, 4 stay 1).
    #[arg(long, default_value_t = CollectConfig::default().delta_min)]
    pub delta_min: f64,
    /// Upper bound of δ₁, δ₂.
    #[arg(long, default_value_t = CollectConfig::default().delta_max)]
    pub delta_max: f64,
    /// Half-width (m) of the box around each desired pose from which the start is drawn.
    #[arg(long, default_value_t = CollectConfig::default().start_radius_m)]
    pub start_radius_m: f64,
    /// RNG seed; the same seed gives the same files.
    #[arg(long, default_value_t = CollectConfig::default().seed)]
    pub seed: u64,
    /// Calm realizations appended after the M disturbed ones: no wind, all rotors at 100 %,
    /// marked disturbance-free (training pins their a_j to 0). Without one, the shared model
    /// and the a_j can trade any constant effect, and the learned g takes up the realizations'
    /// mean thrust deficit (calm-air identifiability, docs/training.md); one anchors g to the calm
    /// vehicle.
    #[arg(long, default_value_t = CollectConfig::default().calm_realizations)]
    pub calm_realizations: usize,
}

impl Default for CollectConfig {
    fn default() -> Self {
        Self {
            realizations: 8,
            windows: 1080,
            poses: 9,
            sample_hz: 240.0,
            window_len: 5,
            substeps: 10,
            wind_levels: vec![0.25, 0.5],
            delta_min: 0.94,
            delta_max: 0.98,
            start_radius_m: 0.5,
            seed: 0,
            calm_realizations: 1,
        }
    }
}

/// Arguments of `host-train collect`.
#[derive(Args, Clone, Debug)]
pub struct CollectArgs {
    /// Output directory (created if missing); existing dataset files in it are replaced.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Collection settings.
    #[command(flatten)]
    pub config: CollectConfig,
}

/// A typed data-collection configuration that the CLI (`host-train collect`) and Python
/// (`hamflight.collect`) both call directly: [`CollectArgs`], built from serde (JSON) instead of
/// a command line.
pub type CollectJob = CollectArgs;

/// A typed job ([`CollectJob`]): `out` and the [`CollectConfig`] keys in one map, as the
/// flags are on the command line (serde's `flatten` would not reject unknown keys).
impl<'de> serde::Deserialize<'de> for CollectArgs {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        use serde::de::Error;
        let mut map = serde_json::Map::deserialize(d)?;
        let out = map
            .remove("out")
            .ok_or_else(|| D::Error::missing_field("out"))?;
        Ok(Self {
            out: PathBuf::deserialize(out).map_err(D::Error::custom)?,
            config: CollectConfig::deserialize(serde_json::Value::Object(map))
                .map_err(D::Error::custom)?,
        })
    }
}

fn check_config(c: &CollectConfig) -> Result<()> {
    if c.realizations == 0 || c.windows == 0 || c.poses == 0 {
        bail!("--realizations, --windows and --poses must be at least 1");
    }
    if c.window_len < 2 {
        bail!("--window-len must be at least 2, got {}", c.window_len);
    }
    if !(c.sample_hz.is_finite() && c.sample_hz > 0.0) || c.substeps == 0 {
        bail!("--sample-hz must be positive and --substeps at least 1");
    }
    if c.sample_hz * (c.substeps as f64) < 1000.0 {
        bail!(
            "physics rate sample_hz × substeps = {} Hz is below 1000 Hz",
            c.sample_hz * c.substeps as f64
        );
    }
    if c.wind_levels.is_empty() || !c.wind_levels.iter().all(|w| w.is_finite()) {
        bail!("--wind-levels needs at least one finite value");
    }
    if !(c.delta_min.is_finite() && c.delta_max.is_finite() && c.delta_min <= c.delta_max) {
        bail!("need --delta-min ≤ --delta-max");
    }
    if !(c.start_radius_m.is_finite() && c.start_radius_m >= 0.0) {
        bail!("--start-radius-m must be ≥ 0");
    }
    Ok(())
}

/// Draw realization `j`'s disturbance.
pub fn draw_disturbance(c: &CollectConfig, rng: &mut impl Rng) -> Disturbance {
    let mut wind = [0.0; 3];
    for w in wind.iter_mut().take(2) {
        let mag = c.wind_levels[rng.gen_range(0..c.wind_levels.len())];
        *w = if rng.gen::<bool>() { mag } else { -mag };
    }
    let mut d = [1.0; 4];
    for di in d.iter_mut().take(2) {
        *di = if c.delta_max > c.delta_min {
            rng.gen_range(c.delta_min..c.delta_max)
        } else {
            c.delta_min
        };
    }
    Disturbance {
        wind_m_s2: wind,
        wind_onset_s: 0.0,
        rotor_efficiency: d,
        efficiency_onset_s: 0.0,
    }
}

/// Simulate one realization; returns its disturbance and one flight per pose. `on_window` is
/// called after each held command (one training window at the default window spec).
/// Realizations `j ≥ c.realizations` are the calm ones ([`CollectConfig::calm_realizations`]).
pub fn collect_realization(
    c: &CollectConfig,
    j: usize,
    params: &VehicleParams,
    mut on_window: impl FnMut(),
) -> Result<(Disturbance, Vec<Flight>)> {
    let mut rng = ChaCha8Rng::seed_from_u64(c.seed);
    rng.set_stream(j as u64);
    let dist = if j < c.realizations {
        draw_disturbance(c, &mut rng)
    } else {
        Disturbance::default()
    };
    let dt_sample = 1.0 / c.sample_hz;
    let dt_phys = dt_sample / c.substeps as f64;
    let hold = (c.window_len - 1) as f64 * dt_sample;
    let mut pid = DslPid::new(params.clone());
    let mut flights = Vec::with_capacity(c.poses);
    let mut t_offset = 0.0;
    for pose in 0..c.poses {
        let n_win = c.windows / c.poses + usize::from(pose < c.windows % c.poses);
        let target = Vector3::new(
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(0.5..1.5),
        );
        let yaw = rng.gen_range(-0.5..0.5);
        let r = c.start_radius_m;
        let mut u = || if r > 0.0 { rng.gen_range(-r..r) } else { 0.0 };
        let p0 = target + Vector3::new(u(), u(), u());
        let rpy0 = Vector3::new(
            rng.gen_range(-0.2..0.2),
            rng.gen_range(-0.2..0.2),
            yaw + rng.gen_range(-0.3..0.3),
        );
        let rot0 = rot_from_rpy(rpy0);
        let v0w = Vector3::new(
            rng.gen_range(-0.3..0.3),
            rng.gen_range(-0.3..0.3),
            rng.gen_range(-0.3..0.3),
        );
        let start = PlantState {
            p_m: p0,
            rot: rot0,
            v_body_m_s: rot0.transpose() * v0w,
            w_body_rad_s: Vector3::new(
                rng.gen_range(-0.5..0.5),
                rng.gen_range(-0.5..0.5),
                rng.gen_range(-0.5..0.5),
            ),
        };
        let mut plant = Plant::new(params.clone(), dist.clone(), Effects::default(), start);
        plant.set_t_s(t_offset);
        pid.reset();
        let reference = TrajectoryPoint::hover(target, yaw);
        let mut samples: Vec<Sample> = Vec::with_capacity(n_win * (c.window_len - 1) + 1);
        for _ in 0..n_win {
            let s0 = *plant.state();
            let t0 = plant.t_s();
            let cmd = params.clamp_rpm(pid.step(t0, &s0, &reference, hold));
            let held = Sample {
                t_s: t0,
                state: s0,
                wrench: params.nominal_wrench(cmd),
                rpm: Some(cmd),
                acc_body_m_s2: None,
            };
            // The window's first state is the previous window's last: it takes the new command.
            match samples.last_mut() {
                Some(last) => *last = held,
                None => samples.push(held),
            }
            for _ in 1..c.window_len {
                for _ in 0..c.substeps {
                    plant.step(cmd, dt_phys);
                }
                samples.push(Sample {
                    t_s: plant.t_s(),
                    state: *plant.state(),
                    ..held
                });
            }
            let last = *plant.state();
            if !last.is_finite() || (last.p_m - target).norm() > 5.0 {
                bail!(
                    "realization {j}, pose {pose}: the PID lost the vehicle at t = {:.3} s \
                     (try a smaller --start-radius-m)",
                    plant.t_s()
                );
            }
            on_window();
        }
        flights.push(Flight { samples });
        t_offset = plant.t_s();
    }
    Ok((dist, flights))
}

/// Collect a dataset into `out` (format: [`crate::io::dataset`]); returns its manifest.
pub fn collect(out: &Path, c: &CollectConfig) -> Result<Manifest> {
    check_config(c)?;
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output directory `{}`", out.display()))?;
    let params = VehicleParams::cf2x();
    let total = c.realizations + c.calm_realizations;
    let pb = indicatif::ProgressBar::new((total * c.windows) as u64);
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "collect [{bar:30}] {pos}/{len} windows ({elapsed}, eta {eta})",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let mut ds = Dataset::new(c.sample_hz, params.mass_kg, params.gravity_m_s2, "collect");
    ds.manifest.seed = Some(c.seed);
    ds.manifest.vehicle = dataset::VehicleDescription {
        inertia_kg_m2: Some(params.inertia_kg_m2),
        rotor_efficiency: Some(params.rotor_efficiency),
        motor_tau_s: None,
        description: None,
    };
    for j in 0..total {
        let (dist, flights) = collect_realization(c, j, &params, || pb.inc(1))?;
        ds.realizations.push(Realization {
            meta: RealizationMeta {
                file: dataset::realization_file(j),
                source_file: None,
                wind_m_s2: Some(dist.wind_m_s2),
                rotor_efficiency: Some(dist.rotor_efficiency),
                disturbance_free: j >= c.realizations,
                flights: 0,
                samples: 0,
            },
            flights,
        });
    }
    pb.finish_and_clear();
    dataset::save(out, &ds)
}

/// Run `host-train collect`.
pub fn run(args: &CollectArgs) -> Result<Manifest> {
    collect(&args.out, &args.config)
}
