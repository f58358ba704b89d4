//! Training data: collection as in the paper's Sec. 4 (`host-train collect`) and the dataset
//! format with its loader.
//!
//! # Dataset format `hamflight-dataset-v1`
//!
//! A directory with one manifest and one CSV file per disturbance realization. Every file is
//! written whole (temporary name, then rename); the manifest is written last.
//!
//! `DIR/manifest.json`:
//!
//! ```json
//! {"format": "hamflight-dataset-v1", "sample_hz": 240.0, "window_len": 5,
//!  "mass_kg": 0.027, "gravity_m_s2": 9.8, "seed": 0,
//!  "realizations": [{"file": "realization_00.csv", "wind_m_s2": [x, y, z],
//!                    "rotor_efficiency": [d1, d2, d3, d4], "windows": 1080}, ...]}
//! ```
//!
//! - `sample_hz`: rate of the states within a window (Hz); consecutive rows of a window are
//!   `1/sample_hz` s apart.
//! - `window_len`: states per window N (rows per window).
//! - `wind_m_s2`: the realization's true wind, a world-frame specific force (m/s²; force m·w).
//! - `rotor_efficiency`: the true δ₁..δ₄ (rotor i makes δᵢ of its nominal thrust and torque).
//! - `windows`: number of windows in the file.
//!
//! `DIR/realization_NN.csv` (NN = 00, 01, …), a header line, exactly
//!
//! ```text
//! window,step,t_s,px,py,pz,r11,r12,r13,r21,r22,r23,r31,r32,r33,vx,vy,vz,wx,wy,wz,f_n,tau_x_nm,tau_y_nm,tau_z_nm,rpm1,rpm2,rpm3,rpm4
//! ```
//!
//! then one row per state, `window_len` rows per window, windows in order:
//! - `window` (0-based index in the file), `step` (0 … window_len−1), `t_s` time (s);
//! - `px,py,pz`: position p (m, world);
//! - `r11 … r33`: rotation R (body → world) row-major, `rij = R[i][j]`;
//! - `vx,vy,vz`: linear velocity v (m/s, **body** frame); `wx,wy,wz`: angular velocity ω
//!   (rad/s, body frame);
//! - `f_n,tau_x_nm,tau_y_nm,tau_z_nm`: the **nominal** wrench u = [f; τ] (N, N·m) of the held
//!   rotor command (no efficiency, no disturbance), identical on every row of a window;
//! - `rpm1..rpm4`: the held rotor command (rpm, clamped to the rotor limits), rotors 1..4 =
//!   front-right, back-right, back-left, front-left; identical on every row of a window.
//!
//! The control is constant through a window: the state at `step = k+1` is the plant's response
//! to the state at `step = k` under that command for `1/sample_hz` s (physics at
//! `sample_hz × 10` Hz by default). Numbers are printed in Rust's shortest round-trip form, so
//! they parse back to the same f64.
//!
//! Collection (defaults = paper Sec. 4): for each realization j the wind's x and y components are
//! drawn from ±`--wind-levels` (z = 0) and δ₁, δ₂ ~ U[0.94, 0.98] (δ₃ = δ₄ = 1); then for each of
//! the 9 desired poses (x, y ∈ U[−1, 1] m, z ∈ U[0.5, 1.5] m, yaw ∈ U[−0.5, 0.5] rad) the vehicle
//! starts at a random state near it (position ± 0.5 m, roll/pitch ± 0.2 rad, velocity ± 0.3 m/s,
//! rates ± 0.5 rad/s) and the DSL PID flies to it. The PID is called once per window at the
//! window's first state and its command is held for the window's N − 1 intervals (so it runs at
//! 240/4 = 60 Hz); consecutive windows of a pose are contiguous (the last state of one window is
//! the first of the next). Each realization has its own RNG stream of `--seed`. Load with pandas: `pd.read_csv(f)` then
//! `df.groupby("window")`, or numpy: `np.loadtxt(f, delimiter=",", skiprows=1).reshape(-1, N, 29)`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::baselines::DslPid;
use crate::controller::{Controller, TrajectoryPoint};
use crate::fsutil::{write_atomic, write_json_atomic};
use crate::plant::{rot_from_rpy, Disturbance, Effects, Plant, PlantState, VehicleParams};

/// The format tag in `manifest.json`.
pub const FORMAT: &str = "hamflight-dataset-v1";
/// The CSV header line (without newline).
pub const CSV_HEADER: &str = "window,step,t_s,px,py,pz,r11,r12,r13,r21,r22,r23,r31,r32,r33,vx,vy,vz,wx,wy,wz,f_n,tau_x_nm,tau_y_nm,tau_z_nm,rpm1,rpm2,rpm3,rpm4";
const NCOLS: usize = 29;

/// `manifest.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`FORMAT`].
    pub format: String,
    /// State sample rate inside a window (Hz).
    pub sample_hz: f64,
    /// States per window.
    pub window_len: usize,
    /// Vehicle mass (kg).
    pub mass_kg: f64,
    /// Gravity (m/s²).
    pub gravity_m_s2: f64,
    /// Seed the data was collected with.
    pub seed: u64,
    /// One entry per realization file.
    pub realizations: Vec<RealizationMeta>,
}

/// One realization's entry in the manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RealizationMeta {
    /// CSV file name, relative to the dataset directory.
    pub file: String,
    /// True wind specific force (m/s², world).
    pub wind_m_s2: [f64; 3],
    /// True rotor efficiencies δ₁..δ₄.
    pub rotor_efficiency: [f64; 4],
    /// Number of windows in the file.
    pub windows: usize,
}

/// One window: `window_len` states under one held rotor command.
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    /// Sample times (s).
    pub t_s: Vec<f64>,
    /// States, in order.
    pub states: Vec<PlantState>,
    /// Nominal wrench [f; τx; τy; τz] of the command (N, N·m).
    pub wrench: [f64; 4],
    /// Held rotor command (rpm).
    pub rpm: [f64; 4],
}

/// One realization: its true disturbance and its windows.
#[derive(Clone, Debug, PartialEq)]
pub struct Realization {
    /// The manifest entry.
    pub meta: RealizationMeta,
    /// The windows.
    pub windows: Vec<Window>,
}

/// A loaded dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// Directory it was loaded from.
    pub dir: PathBuf,
    /// The manifest.
    pub manifest: Manifest,
    /// The realizations, in manifest order.
    pub realizations: Vec<Realization>,
}

/// Settings of a collection run (defaults: the paper's Sec. 4).
#[derive(Args, Clone, Debug, PartialEq)]
pub struct CollectConfig {
    /// Number of disturbance realizations M.
    #[arg(long, default_value_t = 8)]
    pub realizations: usize,
    /// Windows per realization D_j.
    #[arg(long, default_value_t = 1080)]
    pub windows: usize,
    /// Desired poses per realization; the PID flies from a random start to each in turn, and the
    /// windows are split evenly between them.
    #[arg(long, default_value_t = 9)]
    pub poses: usize,
    /// State sample rate within a window (Hz).
    #[arg(long, default_value_t = 240.0)]
    pub sample_hz: f64,
    /// States per window N (the control is held for N−1 sample intervals).
    #[arg(long, default_value_t = 5)]
    pub window_len: usize,
    /// Physics steps per sample interval (10 → 2400 Hz physics at 240 Hz sampling).
    #[arg(long, default_value_t = 10)]
    pub substeps: usize,
    /// Wind component magnitudes (m/s²) to draw x and y from, each with a random sign.
    #[arg(long, value_delimiter = ',', default_values_t = vec![0.25, 0.5])]
    pub wind_levels: Vec<f64>,
    /// Lower bound of δ₁, δ₂ ~ U[delta_min, delta_max] (rotors 1 and 2; rotors 3, 4 stay 1).
    #[arg(long, default_value_t = 0.94)]
    pub delta_min: f64,
    /// Upper bound of δ₁, δ₂.
    #[arg(long, default_value_t = 0.98)]
    pub delta_max: f64,
    /// Half-width (m) of the box around each desired pose from which the start is drawn.
    #[arg(long, default_value_t = 0.5)]
    pub start_radius_m: f64,
    /// RNG seed; the same seed gives the same files.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
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

/// Simulate one realization; returns its windows. `on_window` is called after each window.
pub fn collect_realization(
    c: &CollectConfig,
    j: usize,
    params: &VehicleParams,
    mut on_window: impl FnMut(),
) -> Result<(Disturbance, Vec<Window>)> {
    let mut rng = ChaCha8Rng::seed_from_u64(c.seed);
    rng.set_stream(j as u64);
    let dist = draw_disturbance(c, &mut rng);
    let dt_sample = 1.0 / c.sample_hz;
    let dt_phys = dt_sample / c.substeps as f64;
    let hold = (c.window_len - 1) as f64 * dt_sample;
    let mut pid = DslPid::new(params.clone());
    let mut windows = Vec::with_capacity(c.windows);
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
        for _ in 0..n_win {
            let s0 = *plant.state();
            let t0 = plant.t_s();
            let cmd = params.clamp_rpm(pid.step(t0, &s0, &reference, hold));
            let mut states = Vec::with_capacity(c.window_len);
            let mut ts = Vec::with_capacity(c.window_len);
            states.push(s0);
            ts.push(t0);
            for _ in 1..c.window_len {
                for _ in 0..c.substeps {
                    plant.step(cmd, dt_phys);
                }
                states.push(*plant.state());
                ts.push(plant.t_s());
            }
            let last = states[states.len() - 1];
            if !last.is_finite() || (last.p_m - target).norm() > 5.0 {
                bail!(
                    "realization {j}, pose {pose}: the PID lost the vehicle at t = {:.3} s \
                     (try a smaller --start-radius-m)",
                    plant.t_s()
                );
            }
            windows.push(Window {
                t_s: ts,
                states,
                wrench: params.nominal_wrench(cmd),
                rpm: cmd,
            });
            on_window();
        }
        t_offset = plant.t_s();
    }
    Ok((dist, windows))
}

/// Render a realization's windows as CSV (with the header line).
pub fn windows_to_csv(windows: &[Window]) -> String {
    let mut s = String::with_capacity(windows.len() * 5 * 400);
    s.push_str(CSV_HEADER);
    s.push('\n');
    for (w, win) in windows.iter().enumerate() {
        for (k, (st, t)) in win.states.iter().zip(&win.t_s).enumerate() {
            let r = &st.rot;
            let _ = write!(s, "{w},{k},{t}");
            let vals = [
                st.p_m.x,
                st.p_m.y,
                st.p_m.z,
                r[(0, 0)],
                r[(0, 1)],
                r[(0, 2)],
                r[(1, 0)],
                r[(1, 1)],
                r[(1, 2)],
                r[(2, 0)],
                r[(2, 1)],
                r[(2, 2)],
                st.v_body_m_s.x,
                st.v_body_m_s.y,
                st.v_body_m_s.z,
                st.w_body_rad_s.x,
                st.w_body_rad_s.y,
                st.w_body_rad_s.z,
                win.wrench[0],
                win.wrench[1],
                win.wrench[2],
                win.wrench[3],
                win.rpm[0],
                win.rpm[1],
                win.rpm[2],
                win.rpm[3],
            ];
            for v in vals {
                let _ = write!(s, ",{v}");
            }
            s.push('\n');
        }
    }
    s
}

/// Collect a dataset into `out` (see the module docs for the format); returns its manifest.
pub fn collect(out: &Path, c: &CollectConfig) -> Result<Manifest> {
    check_config(c)?;
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output directory `{}`", out.display()))?;
    let params = VehicleParams::cf2x();
    let pb = indicatif::ProgressBar::new((c.realizations * c.windows) as u64);
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "collect [{bar:30}] {pos}/{len} windows ({elapsed}, eta {eta})",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let mut metas = Vec::with_capacity(c.realizations);
    for j in 0..c.realizations {
        let (dist, windows) = collect_realization(c, j, &params, || pb.inc(1))?;
        let file = format!("realization_{j:02}.csv");
        write_atomic(&out.join(&file), windows_to_csv(&windows).as_bytes())?;
        metas.push(RealizationMeta {
            file,
            wind_m_s2: dist.wind_m_s2,
            rotor_efficiency: dist.rotor_efficiency,
            windows: windows.len(),
        });
    }
    pb.finish_and_clear();
    let manifest = Manifest {
        format: FORMAT.into(),
        sample_hz: c.sample_hz,
        window_len: c.window_len,
        mass_kg: params.mass_kg,
        gravity_m_s2: params.gravity_m_s2,
        seed: c.seed,
        realizations: metas,
    };
    write_json_atomic(&out.join("manifest.json"), &manifest)?;
    Ok(manifest)
}

/// Run `host-train collect`.
pub fn run(args: &CollectArgs) -> Result<Manifest> {
    collect(&args.out, &args.config)
}

/// Load a dataset directory written by [`collect`]; errors name the file and line.
pub fn load(dir: impl AsRef<Path>) -> Result<Dataset> {
    let dir = dir.as_ref();
    let mpath = dir.join("manifest.json");
    let text = std::fs::read_to_string(&mpath)
        .with_context(|| format!("cannot read dataset manifest `{}`", mpath.display()))?;
    let manifest: Manifest = serde_json::from_str(&text)
        .with_context(|| format!("bad dataset manifest `{}`", mpath.display()))?;
    if manifest.format != FORMAT {
        bail!(
            "`{}`: unsupported format `{}`, expected `{FORMAT}`",
            mpath.display(),
            manifest.format
        );
    }
    if manifest.window_len < 2 {
        bail!("`{}`: window_len must be ≥ 2", mpath.display());
    }
    let mut realizations = Vec::with_capacity(manifest.realizations.len());
    for meta in &manifest.realizations {
        let path = dir.join(&meta.file);
        let windows = load_csv(&path, manifest.window_len)?;
        if windows.len() != meta.windows {
            bail!(
                "`{}`: has {} windows, manifest says {}",
                path.display(),
                windows.len(),
                meta.windows
            );
        }
        realizations.push(Realization {
            meta: meta.clone(),
            windows,
        });
    }
    Ok(Dataset {
        dir: dir.to_path_buf(),
        manifest,
        realizations,
    })
}

fn load_csv(path: &Path, window_len: usize) -> Result<Vec<Window>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read dataset file `{}`", path.display()))?;
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim_end() == CSV_HEADER => {}
        _ => bail!(
            "`{}` line 1: expected the header `{CSV_HEADER}`",
            path.display()
        ),
    }
    let mut windows: Vec<Window> = Vec::new();
    let mut row = [0.0f64; NCOLS];
    for (i, line) in lines {
        let ln = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let mut n = 0;
        for (k, field) in line.split(',').enumerate() {
            if k >= NCOLS {
                bail!("`{}` line {ln}: more than {NCOLS} columns", path.display());
            }
            row[k] = field.trim().parse::<f64>().with_context(|| {
                format!(
                    "`{}` line {ln}, column {} (`{}`): not a number: `{field}`",
                    path.display(),
                    k + 1,
                    CSV_HEADER.split(',').nth(k).unwrap_or("?")
                )
            })?;
            n = k + 1;
        }
        if n != NCOLS {
            bail!(
                "`{}` line {ln}: expected {NCOLS} columns, got {n}",
                path.display()
            );
        }
        let (w, step) = (row[0] as usize, row[1] as usize);
        if step == 0 {
            if w != windows.len() {
                bail!(
                    "`{}` line {ln}: window {w} out of order (expected {})",
                    path.display(),
                    windows.len()
                );
            }
            windows.push(Window {
                t_s: Vec::with_capacity(window_len),
                states: Vec::with_capacity(window_len),
                wrench: [row[21], row[22], row[23], row[24]],
                rpm: [row[25], row[26], row[27], row[28]],
            });
        }
        let nwin = windows.len();
        let Some(win) = windows.last_mut() else {
            bail!(
                "`{}` line {ln}: a window must start at step 0",
                path.display()
            );
        };
        if w + 1 != nwin || step != win.states.len() || step >= window_len {
            bail!(
                "`{}` line {ln}: window {w} step {step} out of order (window_len {window_len})",
                path.display()
            );
        }
        win.t_s.push(row[2]);
        win.states.push(PlantState {
            p_m: Vector3::new(row[3], row[4], row[5]),
            rot: Matrix3::new(
                row[6], row[7], row[8], row[9], row[10], row[11], row[12], row[13], row[14],
            ),
            v_body_m_s: Vector3::new(row[15], row[16], row[17]),
            w_body_rad_s: Vector3::new(row[18], row[19], row[20]),
        });
    }
    if let Some(last) = windows.last() {
        if last.states.len() != window_len {
            bail!(
                "`{}`: last window has {} states, expected {window_len}",
                path.display(),
                last.states.len()
            );
        }
    }
    Ok(windows)
}
