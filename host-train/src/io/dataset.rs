//! The dataset format: the one reader and writer that `collect`, `import`, `train` and the tests
//! all go through. Collection itself (PID, plant, random draws) lives in [`crate::data::collect`].
//!
//! # Dataset format `hamflight-dataset-v2`
//!
//! A directory with one manifest and one CSV file per disturbance realization j (the unit that
//! gets its own a_j in training). Every file is written whole (temporary name, then rename);
//! the manifest is written last.
//!
//! `DIR/manifest.json`:
//!
//! ```json
//! {"format": "hamflight-dataset-v2", "sample_hz": 240.0, "mass_kg": 0.027,
//!  "gravity_m_s2": 9.8, "source": "collect", "seed": 0,
//!  "vehicle": {"inertia_kg_m2": [1.4e-5, 1.4e-5, 2.17e-5], "rotor_efficiency": [1, 1, 1, 1],
//!              "motor_tau_s": null},
//!  "realizations": [{"file": "realization_00.csv", "source_file": null,
//!                    "wind_m_s2": [x, y, z], "rotor_efficiency": [d1, d2, d3, d4],
//!                    "disturbance_free": false, "flights": 9, "samples": 4329}, ...]}
//! ```
//!
//! - `sample_hz`: the nominal state rate (Hz). The trainer integrates every step with
//!   `1/sample_hz` s and uses only steps whose timestamps are that far apart (see [`segments`]).
//! - `mass_kg`, `gravity_m_s2`: the vehicle's mass and gravity the data was taken with.
//! - `source`: `collect` (our simulator) or `import` (flight logs); `seed`: collection seed or null.
//! - `vehicle` (optional, every key optional): what is known of the vehicle beyond its mass, for
//!   the training report's "true" values (omitted there when unknown): `inertia_kg_m2` diag(J)
//!   (kg·m²); `rotor_efficiency` the vehicle's own rotor thrust factors δ₁..δ₄; `motor_tau_s`
//!   the first-order motor time constant the stored commands were passed through at import (the
//!   stored command is then the *realized* one, see [`crate::data::import`]; null: stored as logged);
//!   `description` the whole vehicle file given to `import --vehicle` ([`crate::sim::vehicle`]).
//! - `source_file`: for imports, the log the realization came from.
//! - `wind_m_s2`, `rotor_efficiency`: the true disturbance (world specific force, m/s²; δ₁..δ₄)
//!   when known (collection), else null.
//! - `disturbance_free`: the flight had no disturbance; training pins its a_j to 0, so constant
//!   effects land in the shared model and not in a per-flight estimate that is dropped in flight.
//! - `flights`, `samples`: number of continuous flights and rows in the file.
//!
//! `DIR/realization_NN.csv` (NN = 00, 01, …), the header line exactly
//!
//! ```text
//! flight,t_s,px,py,pz,r11,r12,r13,r21,r22,r23,r31,r32,r33,vx,vy,vz,wx,wy,wz,f_n,tau_x_nm,tau_y_nm,tau_z_nm,rpm1,rpm2,rpm3,rpm4,ax_m_s2,ay_m_s2,az_m_s2
//! ```
//!
//! then one row per sampled state, flights in order, rows of a flight in time order:
//! - `flight`: index of the continuous flight in the file (0, 1, …; non-decreasing);
//! - `t_s`: the state's timestamp (s), increasing within a flight;
//! - `px,py,pz`: position p (m, world); `r11 … r33`: rotation R (body → world) row-major;
//! - `vx,vy,vz`: linear velocity v (m/s, **body** frame); `wx,wy,wz`: angular velocity ω
//!   (rad/s, body frame);
//! - `f_n,tau_x_nm,tau_y_nm,tau_z_nm`: the commanded wrench u = [f; τ] (N, N·m) applied from this
//!   row's time to the next row's (for collection: the nominal wrench of the rotor command, no
//!   efficiency, no disturbance). The last row of a flight repeats the previous command;
//! - `rpm1..rpm4`: the rotor command (rpm) when known (collection), else empty;
//! - `ax_m_s2,ay_m_s2,az_m_s2`: the measured body specific force (m/s², accelerometer) when
//!   logged, else empty.
//!
//! Numbers are printed in their shortest round-trip form, so they parse back to the same f64.
//! Load with pandas: `pd.read_csv(f)` then `df.groupby("flight")`.
//!
//! # From flights to training windows
//!
//! [`segments`] splits each flight where the data is not continuous: at a non-increasing
//! timestamp, or where consecutive timestamps are not `1/sample_hz` apart within
//! [`DT_TOLERANCE`] (a gap, a dropped sample, another rate). [`windows`] then cuts every segment
//! into windows of `len` states every `stride` samples; the command of each step comes from its
//! row, so the trainer integrates each step with its own command. No resampling happens here:
//! import writes the log's own rate (see [`crate::data::import`] for how commands logged at another
//! rate are held).
//!
//! `hamflight-dataset-v1` (fixed windows with one held command) is no longer read: the error
//! says to collect again.

use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::io::files::{write_atomic, write_json_atomic};
use crate::sim::plant::PlantState;

/// The format tag in `manifest.json`.
pub const FORMAT: &str = "hamflight-dataset-v2";
/// The previous format's tag, recognised only to explain that it is no longer read.
pub const FORMAT_V1: &str = "hamflight-dataset-v1";
/// The CSV header line (without newline).
pub const CSV_HEADER: &str = "flight,t_s,px,py,pz,r11,r12,r13,r21,r22,r23,r31,r32,r33,vx,vy,vz,wx,wy,wz,f_n,tau_x_nm,tau_y_nm,tau_z_nm,rpm1,rpm2,rpm3,rpm4,ax_m_s2,ay_m_s2,az_m_s2";
/// Largest relative deviation of a step's dt from `1/sample_hz` inside a segment.
pub const DT_TOLERANCE: f64 = 0.1;
/// Largest ‖RᵀR − I‖ (Frobenius) accepted for a stored rotation.
pub const ROT_TOLERANCE: f64 = 1e-3;

/// `manifest.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`FORMAT`].
    pub format: String,
    /// Nominal state rate (Hz).
    pub sample_hz: f64,
    /// Vehicle mass (kg).
    pub mass_kg: f64,
    /// Gravity (m/s²).
    pub gravity_m_s2: f64,
    /// `collect` or `import`.
    pub source: String,
    /// Collection seed, if any.
    pub seed: Option<u64>,
    /// What is known of the vehicle beyond its mass.
    #[serde(default)]
    pub vehicle: VehicleDescription,
    /// One entry per realization file.
    pub realizations: Vec<RealizationMeta>,
}

/// The manifest's `vehicle`: what is known of the vehicle beyond its mass (each key optional).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct VehicleDescription {
    /// Principal moments of inertia diag(J) (kg·m²).
    pub inertia_kg_m2: Option<[f64; 3]>,
    /// The vehicle's own rotor thrust factors δ₁..δ₄.
    pub rotor_efficiency: Option<[f64; 4]>,
    /// First-order motor time constant (s) the stored commands were filtered with at import.
    pub motor_tau_s: Option<f64>,
    /// The whole vehicle description the data was imported with (`import --vehicle`): its
    /// airframe builds the flight check's plant and mixer, its inertia the training prior.
    pub description: Option<crate::sim::vehicle::VehicleFile>,
}

/// One realization's entry in the manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RealizationMeta {
    /// CSV file name, relative to the dataset directory.
    pub file: String,
    /// The flight log it was imported from, if any.
    #[serde(default)]
    pub source_file: Option<String>,
    /// True wind specific force (m/s², world), when known.
    #[serde(default)]
    pub wind_m_s2: Option<[f64; 3]>,
    /// True rotor efficiencies δ₁..δ₄, when known.
    #[serde(default)]
    pub rotor_efficiency: Option<[f64; 4]>,
    /// No disturbance: training pins this realization's a_j to 0.
    #[serde(default)]
    pub disturbance_free: bool,
    /// Number of continuous flights in the file.
    pub flights: usize,
    /// Number of rows in the file.
    pub samples: usize,
}

/// One row of a realization file (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Row {
    flight: usize,
    t_s: f64,
    px: f64,
    py: f64,
    pz: f64,
    r11: f64,
    r12: f64,
    r13: f64,
    r21: f64,
    r22: f64,
    r23: f64,
    r31: f64,
    r32: f64,
    r33: f64,
    vx: f64,
    vy: f64,
    vz: f64,
    wx: f64,
    wy: f64,
    wz: f64,
    f_n: f64,
    tau_x_nm: f64,
    tau_y_nm: f64,
    tau_z_nm: f64,
    rpm1: Option<f64>,
    rpm2: Option<f64>,
    rpm3: Option<f64>,
    rpm4: Option<f64>,
    ax_m_s2: Option<f64>,
    ay_m_s2: Option<f64>,
    az_m_s2: Option<f64>,
}

/// One sampled state with the command applied from it to the next sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Timestamp (s).
    pub t_s: f64,
    /// The state (body-frame velocities).
    pub state: PlantState,
    /// Commanded wrench [f; τx; τy; τz] (N, N·m) from this sample to the next.
    pub wrench: [f64; 4],
    /// Rotor command (rpm), when known.
    pub rpm: Option<[f64; 4]>,
    /// Measured body specific force (m/s²), when logged.
    pub acc_body_m_s2: Option<[f64; 3]>,
}

/// One continuous flight: samples in time order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Flight {
    /// The samples.
    pub samples: Vec<Sample>,
}

/// One realization: its description and its flights.
#[derive(Clone, Debug, PartialEq)]
pub struct Realization {
    /// The manifest entry (`flights` and `samples` are recomputed on [`save`]).
    pub meta: RealizationMeta,
    /// The flights.
    pub flights: Vec<Flight>,
}

/// A dataset in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// The manifest (its `realizations` mirror [`Dataset::realizations`]' metas).
    pub manifest: Manifest,
    /// The realizations, in manifest order.
    pub realizations: Vec<Realization>,
}

impl Dataset {
    /// An empty dataset with these vehicle constants.
    pub fn new(sample_hz: f64, mass_kg: f64, gravity_m_s2: f64, source: &str) -> Self {
        Self {
            manifest: Manifest {
                format: FORMAT.into(),
                sample_hz,
                mass_kg,
                gravity_m_s2,
                source: source.into(),
                seed: None,
                vehicle: VehicleDescription::default(),
                realizations: Vec::new(),
            },
            realizations: Vec::new(),
        }
    }
}

/// The file name of realization `j`.
pub fn realization_file(j: usize) -> String {
    format!("realization_{j:02}.csv")
}

fn to_row(flight: usize, s: &Sample) -> Row {
    let (p, r, v, w) = (
        &s.state.p_m,
        &s.state.rot,
        &s.state.v_body_m_s,
        &s.state.w_body_rad_s,
    );
    let rpm = |k: usize| s.rpm.map(|x| x[k]);
    let acc = |k: usize| s.acc_body_m_s2.map(|x| x[k]);
    Row {
        flight,
        t_s: s.t_s,
        px: p.x,
        py: p.y,
        pz: p.z,
        r11: r[(0, 0)],
        r12: r[(0, 1)],
        r13: r[(0, 2)],
        r21: r[(1, 0)],
        r22: r[(1, 1)],
        r23: r[(1, 2)],
        r31: r[(2, 0)],
        r32: r[(2, 1)],
        r33: r[(2, 2)],
        vx: v.x,
        vy: v.y,
        vz: v.z,
        wx: w.x,
        wy: w.y,
        wz: w.z,
        f_n: s.wrench[0],
        tau_x_nm: s.wrench[1],
        tau_y_nm: s.wrench[2],
        tau_z_nm: s.wrench[3],
        rpm1: rpm(0),
        rpm2: rpm(1),
        rpm3: rpm(2),
        rpm4: rpm(3),
        ax_m_s2: acc(0),
        ay_m_s2: acc(1),
        az_m_s2: acc(2),
    }
}

fn opt_array<const N: usize>(v: [Option<f64>; N], what: &str) -> Result<Option<[f64; N]>> {
    match v.iter().filter(|x| x.is_some()).count() {
        0 => Ok(None),
        n if n == N => Ok(Some(v.map(|x| x.unwrap_or(f64::NAN)))),
        _ => bail!("{what}: give all {N} columns or none"),
    }
}

fn from_row(r: &Row) -> Result<Sample> {
    let s = Sample {
        t_s: r.t_s,
        state: PlantState {
            p_m: Vector3::new(r.px, r.py, r.pz),
            rot: Matrix3::new(
                r.r11, r.r12, r.r13, r.r21, r.r22, r.r23, r.r31, r.r32, r.r33,
            ),
            v_body_m_s: Vector3::new(r.vx, r.vy, r.vz),
            w_body_rad_s: Vector3::new(r.wx, r.wy, r.wz),
        },
        wrench: [r.f_n, r.tau_x_nm, r.tau_y_nm, r.tau_z_nm],
        rpm: opt_array([r.rpm1, r.rpm2, r.rpm3, r.rpm4], "rpm1..rpm4")?,
        acc_body_m_s2: opt_array([r.ax_m_s2, r.ay_m_s2, r.az_m_s2], "ax_m_s2..az_m_s2")?,
    };
    check_sample(&s)?;
    Ok(s)
}

/// Checks one sample: every value finite, R a rotation (‖RᵀR − I‖ ≤ [`ROT_TOLERANCE`],
/// det R > 0).
pub fn check_sample(s: &Sample) -> Result<()> {
    let finite = s.t_s.is_finite()
        && s.state.is_finite()
        && s.wrench.iter().all(|x| x.is_finite())
        && s.rpm.is_none_or(|r| r.iter().all(|x| x.is_finite()))
        && s.acc_body_m_s2
            .is_none_or(|a| a.iter().all(|x| x.is_finite()));
    if !finite {
        bail!("a value is not a finite number");
    }
    let r = &s.state.rot;
    let ortho = (r.transpose() * r - Matrix3::identity()).norm();
    if ortho > ROT_TOLERANCE || r.determinant() <= 0.0 {
        bail!(
            "r11..r33 is not a rotation (‖RᵀR − I‖ = {ortho:.2e}, det = {:.3})",
            r.determinant()
        );
    }
    Ok(())
}

/// The CSV text of one realization (header line first).
pub fn realization_csv(flights: &[Flight]) -> Result<Vec<u8>> {
    let mut w = csv::WriterBuilder::new().from_writer(Vec::new());
    let mut wrote = false;
    for (f, flight) in flights.iter().enumerate() {
        for s in &flight.samples {
            w.serialize(to_row(f, s))?;
            wrote = true;
        }
    }
    if !wrote {
        w.write_record(CSV_HEADER.split(','))?;
    }
    w.into_inner()
        .map_err(|e| anyhow::anyhow!("cannot render CSV: {e}"))
}

/// Writes `ds` into `dir` (created if missing): every realization file, then the manifest, each
/// whole. The manifest's realization entries are taken from `ds.realizations` with `flights`
/// and `samples` recomputed; returns the manifest written.
///
/// # Errors
/// Any I/O failure, naming the file.
pub fn save(dir: &Path, ds: &Dataset) -> Result<Manifest> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create dataset directory `{}`", dir.display()))?;
    let mut manifest = ds.manifest.clone();
    manifest.format = FORMAT.into();
    manifest.realizations.clear();
    for r in &ds.realizations {
        let bytes = realization_csv(&r.flights)?;
        write_atomic(&dir.join(&r.meta.file), &bytes)?;
        manifest.realizations.push(RealizationMeta {
            flights: r.flights.len(),
            samples: r.flights.iter().map(|f| f.samples.len()).sum(),
            ..r.meta.clone()
        });
    }
    write_json_atomic(&dir.join("manifest.json"), &manifest)?;
    Ok(manifest)
}

/// Reads the manifest of `dir`.
///
/// # Errors
/// A missing or malformed manifest, or another format (naming the file).
pub fn load_manifest(dir: &Path) -> Result<Manifest> {
    let mpath = dir.join("manifest.json");
    let text = std::fs::read_to_string(&mpath)
        .with_context(|| format!("cannot read dataset manifest `{}`", mpath.display()))?;
    let tag: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("bad dataset manifest `{}`", mpath.display()))?;
    match tag.get("format").and_then(|f| f.as_str()) {
        Some(FORMAT) => {}
        Some(FORMAT_V1) => bail!(
            "`{}`: dataset format `{FORMAT_V1}` (fixed windows under one held command) is no \
             longer read; collect again with `host-train collect --out DIR` or import the logs \
             again (format `{FORMAT}`: continuous flights with a timestamp and a command per state)",
            mpath.display()
        ),
        other => bail!(
            "`{}`: unsupported format {other:?}, expected `{FORMAT}`",
            mpath.display()
        ),
    }
    let manifest: Manifest = serde_json::from_value(tag)
        .with_context(|| format!("bad dataset manifest `{}`", mpath.display()))?;
    if !(manifest.sample_hz.is_finite() && manifest.sample_hz > 0.0) {
        bail!("`{}`: sample_hz must be positive", mpath.display());
    }
    if manifest.realizations.is_empty() {
        bail!("`{}`: no realizations", mpath.display());
    }
    Ok(manifest)
}

/// Loads a dataset directory; errors name the file and line.
///
/// # Errors
/// See [`load_manifest`]; a realization file that is missing, has another header, a malformed
/// or non-finite value, a non-rotation, flights out of order, or counts other than the
/// manifest's.
pub fn load(dir: impl AsRef<Path>) -> Result<Dataset> {
    let dir = dir.as_ref();
    let manifest = load_manifest(dir)?;
    let mut realizations = Vec::with_capacity(manifest.realizations.len());
    for meta in &manifest.realizations {
        let path = dir.join(&meta.file);
        let flights = load_csv(&path)?;
        let samples: usize = flights.iter().map(|f| f.samples.len()).sum();
        if flights.len() != meta.flights || samples != meta.samples {
            bail!(
                "`{}`: has {} flights and {samples} samples, manifest says {} and {}",
                path.display(),
                flights.len(),
                meta.flights,
                meta.samples
            );
        }
        realizations.push(Realization {
            meta: meta.clone(),
            flights,
        });
    }
    Ok(Dataset {
        manifest,
        realizations,
    })
}

fn load_csv(path: &Path) -> Result<Vec<Flight>> {
    let mut rd = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .with_context(|| format!("cannot read dataset file `{}`", path.display()))?;
    let header = rd
        .headers()
        .with_context(|| format!("`{}` line 1: cannot read the header", path.display()))?;
    if header.iter().collect::<Vec<_>>().join(",") != CSV_HEADER {
        bail!(
            "`{}` line 1: expected the header `{CSV_HEADER}`",
            path.display()
        );
    }
    let mut flights: Vec<Flight> = Vec::new();
    for (i, rec) in rd.deserialize::<Row>().enumerate() {
        let line_of = |e: &csv::Error| e.position().map_or(i as u64 + 2, |p| p.line());
        let row = match rec {
            Ok(r) => r,
            Err(e) => bail!("`{}` line {}: {e}", path.display(), line_of(&e)),
        };
        let ln = i + 2;
        let s = from_row(&row).with_context(|| format!("`{}` line {ln}", path.display()))?;
        if row.flight == flights.len() {
            flights.push(Flight::default());
        } else if Some(row.flight) != flights.len().checked_sub(1) {
            bail!(
                "`{}` line {ln}: flight {} out of order (expected {} or {})",
                path.display(),
                row.flight,
                flights.len().saturating_sub(1),
                flights.len()
            );
        }
        if let Some(f) = flights.last_mut() {
            f.samples.push(s);
        }
    }
    Ok(flights)
}

/// The continuous stretches of `samples` (index ranges): split wherever a timestamp does not
/// increase by `1/sample_hz` within [`DT_TOLERANCE`] (a gap, a repeated or backwards timestamp,
/// another rate). Every stretch has at least one sample.
pub fn segments(samples: &[Sample], sample_hz: f64) -> Vec<Range<usize>> {
    let dt = 1.0 / sample_hz;
    let mut out = Vec::new();
    let mut start = 0;
    for k in 1..samples.len() {
        let step = samples[k].t_s - samples[k - 1].t_s;
        let continuous = (step - dt).abs() <= DT_TOLERANCE * dt;
        if !continuous {
            out.push(start..k);
            start = k;
        }
    }
    if start < samples.len() {
        out.push(start..samples.len());
    }
    out
}

/// How training windows are cut from the flights.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct WindowSpec {
    /// States per window (N + 1 in the paper's notation).
    pub len: usize,
    /// Samples between the starts of consecutive windows.
    pub stride: usize,
}

impl Default for WindowSpec {
    /// The paper's: 5 states, a new window every 4 samples (consecutive windows share their end
    /// state; with `collect`'s command held for 4 steps each window sees one command).
    fn default() -> Self {
        Self { len: 5, stride: 4 }
    }
}

/// Where one window lies: realization, flight, first sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WindowAt {
    /// Realization index.
    pub realization: usize,
    /// Flight index within the realization.
    pub flight: usize,
    /// Index of the window's first sample in the flight.
    pub start: usize,
}

/// Every window of `spec` in `ds`: realization by realization, flight by flight, each
/// [`segments`] stretch cut into `spec.len` samples every `spec.stride`.
///
/// # Errors
/// `len < 2` or `stride == 0`.
pub fn windows(ds: &Dataset, spec: WindowSpec) -> Result<Vec<WindowAt>> {
    if spec.len < 2 || spec.stride == 0 {
        bail!(
            "window length must be at least 2 and stride at least 1 (got {} and {})",
            spec.len,
            spec.stride
        );
    }
    let mut out = Vec::new();
    for (j, r) in ds.realizations.iter().enumerate() {
        for (f, flight) in r.flights.iter().enumerate() {
            for seg in segments(&flight.samples, ds.manifest.sample_hz) {
                let mut s = Some(seg.start);
                while let Some(start) = s.filter(|s| s.saturating_add(spec.len) <= seg.end) {
                    out.push(WindowAt {
                        realization: j,
                        flight: f,
                        start,
                    });
                    s = start.checked_add(spec.stride);
                }
            }
        }
    }
    Ok(out)
}

/// The dataset directory's manifest path (for messages).
pub fn manifest_path(dir: &Path) -> PathBuf {
    dir.join("manifest.json")
}
