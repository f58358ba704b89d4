//! `host-train replay`: closed-loop replay of logged flights. Each candidate plant (a
//! scenario's vehicle: the rigid `bl-*`, the weak-torque `bl-real-*`, an identified `bl-id-*`;
//! or a weight blob's learned model behind the motors, [`plant`])
//! is flown by the reproduced onboard controller ([`crate::control::onboard`]) along the logged
//! reference, from the logged state, in windows of 10 / 50 / 100 / 300 rows and over each
//! flight's longest airborne stretch; the plant that replays the flights best is the reading
//! the data pick. With `--fit BASE` the torque gains and the flapping moment are identified
//! against that error on the training flights ([`identify`]).

pub mod closed_loop;
pub mod identify;
pub mod plant;
pub mod plot;
pub mod synthetic;

use crate::control::onboard::OnboardConfig;
use crate::io::{read_loop_csv, write_json_atomic, LoopFlight};
use crate::pipeline::onboard::replay::{setpoints, AccelSource, ReplayOptions};
use crate::sim::scenario::Scenario;
use anyhow::{bail, Context, Result};
use closed_loop::{fly, longest_airborne, score_windows, ErrorAcc, ReplayConfig, RotorMap};
use identify::{fit_loop, fit_open_loop, LoopFit, PlantTerms};
use plant::{BlobPlant, Replayable};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Fly candidate plants under the onboard controller along logged flights (closed-loop replay).
#[derive(clap::Args, Debug, Clone)]
#[command(after_help = "LOOPDIR holds train/*.csv and test/*.csv loop logs \
(tools/benchmark/nanodrone.py --loop-out LOOPDIR). Every --plant is a scenario TOML whose vehicle \
(and effects) is the plant; its trajectory is ignored. Every --plant-blob is a weight blob whose \
learned model is the plant (a = 0, its own input lags), fed the rotor speeds of the --blob-rotors \
vehicle's motors (their lag and limits, its thrust and drag coefficients). Each window starts \
from the logged state, \
the controller having run on the logged states for --warmup rows so its integrators hold what \
the vehicle's did; errors are against the logged states that follow. A replay that leaves the \
log by more than 1 m has diverged and its remaining steps count at 1 m and 90 degrees. \
Only the training flights are used unless --test is given: score the test flights once, at \
the end. Example: host-train replay --data /tmp/nd-loop --plant scenarios/bl-calm-spiral.toml \
--plant scenarios/bl-real-calm-spiral.toml --fit scenarios/bl-calm-spiral.toml --out out/replay")]
pub struct ReplayArgs {
    /// The loop-log folder (train/ and test/ subfolders).
    #[arg(long, value_name = "LOOPDIR")]
    pub data: PathBuf,
    /// A candidate plant (scenario TOML); repeat for several.
    #[arg(long = "plant", value_name = "SCENARIO.toml")]
    pub plants: Vec<PathBuf>,
    /// A weight blob whose learned model is a candidate plant (a = 0); repeat for several.
    #[arg(long = "plant-blob", value_name = "FILE.hfw")]
    pub blob_plants: Vec<PathBuf>,
    /// The motors and rotors a blob plant is fed through (a scenario: its vehicle's
    /// coefficients and speed limits, its `[effects] motor_tau_s`); default: the --fit base,
    /// else the first --plant.
    #[arg(long, value_name = "SCENARIO.toml")]
    pub blob_rotors: Option<PathBuf>,
    /// The onboard controller's configuration (JSON, as `host-train onboard --fit --out`
    /// writes); default: the firmware 2025.09 defaults.
    #[arg(long, value_name = "FILE.json")]
    pub config: Option<PathBuf>,
    /// Window lengths, rows (100 Hz).
    #[arg(long, value_delimiter = ',', default_value = "10,50,100,300")]
    pub windows: Vec<usize>,
    /// Rows between window starts.
    #[arg(long, default_value_t = 100)]
    pub stride: usize,
    /// Rows the controller runs on the logged states before each window (the default reaches
    /// back to the flight's start: its position integrators hold the whole flight).
    #[arg(long, default_value_t = 100_000)]
    pub warmup: usize,
    /// The reference acceleration (the logs have none) is the central difference of the logged
    /// reference velocity over ± this many rows.
    #[arg(long, default_value_t = 10)]
    pub accel_span: usize,
    /// Identify the torque gains and the flapping moment on top of this scenario's vehicle
    /// against the closed-loop error on the training flights; the result joins the plants as
    /// `identified`.
    #[arg(long, value_name = "BASE.toml")]
    pub fit: Option<PathBuf>,
    /// Window length of the fit's objective, rows.
    #[arg(long, default_value_t = 100)]
    pub fit_steps: usize,
    /// Rows between the fit's windows.
    #[arg(long, default_value_t = 200)]
    pub fit_stride: usize,
    /// Objective evaluations the fit may use.
    #[arg(long, default_value_t = 80)]
    pub fit_evals: usize,
    /// Also score the test flights (melon). Do this once, after choosing on train.
    #[arg(long)]
    pub test: bool,
    /// Output folder: report.json and one figure per flight (logged against replayed).
    #[arg(long, value_name = "DIR", default_value = "out/replay")]
    pub out: PathBuf,
}

/// One plant's windowed errors at one length.
#[derive(Clone, Debug, Serialize)]
pub struct WindowRow {
    /// Window length, rows.
    pub steps: usize,
    /// Position RMSE (m).
    pub pos_rmse_m: f64,
    /// Attitude RMSE (rad).
    pub att_rmse_rad: f64,
    /// Windows pooled and how many diverged.
    pub windows: usize,
    /// Windows that diverged.
    pub diverged: usize,
}

/// One plant's replay of one flight's longest airborne stretch.
#[derive(Clone, Debug, Serialize)]
pub struct FlightRow {
    /// The run.
    pub flight: String,
    /// Rows replayed (fewer than the stretch: it diverged).
    pub rows: usize,
    /// Position RMSE (m).
    pub pos_rmse_m: f64,
    /// Attitude RMSE (rad).
    pub att_rmse_rad: f64,
    /// Whether it diverged.
    pub diverged: bool,
}

/// One plant reading's scores.
#[derive(Clone, Debug, Serialize)]
pub struct PlantScore {
    /// The plant's name.
    pub plant: String,
    /// `train` or `test`.
    pub split: String,
    /// Per window length.
    pub windows: Vec<WindowRow>,
    /// Per flight, the whole airborne stretch.
    pub flights: Vec<FlightRow>,
}

/// The report.
#[derive(Clone, Debug, Serialize)]
pub struct ReplayReport {
    /// How the replay flew.
    pub config: ReplayConfig,
    /// The open-loop estimate of the torque terms on the training flights (one-step
    /// regression on the logged rotor speeds).
    pub open_loop: PlantTerms,
    /// The closed-loop fit, with --fit.
    pub loop_fit: Option<LoopFit>,
    /// Per plant and split.
    pub scores: Vec<PlantScore>,
}

fn read_split(dir: &Path, split: &str) -> Result<Vec<LoopFlight>> {
    let folder = dir.join(split);
    if !folder.is_dir() {
        bail!("{} is not a folder: LOOPDIR must hold {split}/*.csv (tools/benchmark/nanodrone.py --loop-out LOOPDIR)", folder.display());
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(&folder)
        .with_context(|| format!("listing {}", folder.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("no loop logs (*.csv) in {}", folder.display());
    }
    files.iter().map(|p| read_loop_csv(p)).collect()
}

/// Scores `plant` on `flights`: windows of each length and each flight's airborne stretch
/// (whose replayed states are returned for the figures).
pub fn score_plant<P: Replayable + ?Sized>(
    flights: &[&LoopFlight],
    plant: &P,
    cfg: &ReplayConfig,
    lengths: &[usize],
    stride: usize,
) -> (Vec<WindowRow>, Vec<FlightRow>, Vec<closed_loop::Flown>) {
    let windows = lengths
        .iter()
        .map(|&steps| {
            let e = score_windows(flights, plant, cfg, steps, stride);
            WindowRow {
                steps,
                pos_rmse_m: e.pos_rmse_m(),
                att_rmse_rad: e.att_rmse_rad(),
                windows: e.windows,
                diverged: e.diverged,
            }
        })
        .collect();
    let mut rows = Vec::new();
    let mut flown_all = Vec::new();
    for f in flights {
        let Some((a, n)) = longest_airborne(f) else {
            continue;
        };
        let sps = setpoints(f, &cfg.options);
        let steps = n.saturating_sub(1);
        let flown = fly(f, &sps, plant, cfg, a, steps);
        let mut e = ErrorAcc::default();
        e.add(f, a, steps, &flown);
        rows.push(FlightRow {
            flight: f.name.clone(),
            rows: flown.states.len(),
            pos_rmse_m: e.pos_rmse_m(),
            att_rmse_rad: e.att_rmse_rad(),
            diverged: flown.diverged,
        });
        flown_all.push(flown);
    }
    (windows, rows, flown_all)
}

/// Runs `host-train replay`.
///
/// # Errors
/// Unreadable logs, plants or configuration; no plant; a zero window; a failure writing.
pub fn run(args: &ReplayArgs) -> Result<ReplayReport> {
    if args.plants.is_empty() && args.blob_plants.is_empty() && args.fit.is_none() {
        bail!("give at least one --plant SCENARIO.toml, --plant-blob FILE.hfw or --fit BASE.toml");
    }
    if !args.blob_plants.is_empty()
        && args.blob_rotors.is_none()
        && args.fit.is_none()
        && args.plants.is_empty()
    {
        bail!("--plant-blob needs the motors it is fed through: give --blob-rotors SCENARIO.toml (e.g. scenarios/bl-calm-spiral.toml), --fit or a --plant");
    }
    if args.windows.contains(&0) || args.stride == 0 || args.fit_steps == 0 || args.accel_span == 0
    {
        bail!("--windows, --stride, --fit-steps and --accel-span must be at least 1");
    }
    let controller = match &args.config {
        Some(p) => OnboardConfig::load(p)?,
        None => OnboardConfig::cf21bl_2025_09(),
    };
    let train = read_split(&args.data, "train")?;
    let train_refs: Vec<&LoopFlight> = train.iter().collect();
    let map = RotorMap::fit(&train_refs)?;
    eprintln!(
        "command → speed (train): rpm² = {:.4e} + {:.4e} · command",
        map.offset_rpm2, map.rpm2_per_cmd
    );
    let cfg = ReplayConfig {
        controller,
        map,
        options: ReplayOptions {
            substeps: 5,
            accel: AccelSource::Diff,
            accel_span: args.accel_span.max(1),
            smooth_rows: 0,
        },
        warmup_rows: args.warmup,
    };
    let mut plants: Vec<(String, Box<dyn Replayable>)> = Vec::new();
    let load = |p: &Path, what: &str| {
        Scenario::load(p).with_context(|| format!("loading {what} {}", p.display()))
    };
    let mut first_vehicle = None;
    for p in &args.plants {
        let s = load(p, "plant")?;
        first_vehicle.get_or_insert_with(|| s.clone());
        plants.push((s.name.clone(), Box::new(s)));
    }
    let blob_rotors = match &args.blob_rotors {
        Some(p) => Some(load(p, "--blob-rotors")?),
        None => None,
    };
    let base_for_open = match (&args.fit, first_vehicle, &blob_rotors) {
        (Some(p), _, _) => load(p, "--fit base")?,
        (None, Some(s), _) => s,
        (None, None, Some(r)) => r.clone(),
        (None, None, None) => bail!("no plant"),
    };
    let rotors = blob_rotors.unwrap_or_else(|| base_for_open.clone());
    for p in &args.blob_plants {
        let model = crate::control::load_learned(p)?;
        let stem = p.file_stem().map_or_else(
            || p.display().to_string(),
            |s| s.to_string_lossy().into_owned(),
        );
        plants.push((
            format!("blob {stem}"),
            Box::new(BlobPlant::new(model, &rotors)),
        ));
    }
    let open_loop = fit_open_loop(&train_refs, &base_for_open);
    eprintln!(
        "open-loop torque gains (train): {:.3} / {:.3} / {:.3}, flapping {:.3} rad/s² per m/s",
        open_loop.torque_gain[0],
        open_loop.torque_gain[1],
        open_loop.torque_gain[2],
        open_loop.flap_rad_s2_per_m_s
    );
    let mut loop_fit = None;
    if let Some(base) = &args.fit {
        eprintln!(
            "fitting the torque gains and flapping against {}-row closed-loop windows (≤ {} evaluations)…",
            args.fit_steps, args.fit_evals
        );
        let r = fit_loop(
            &train_refs,
            &base_for_open,
            &cfg,
            args.fit_steps,
            args.fit_stride,
            args.fit_evals,
        );
        eprintln!(
            "closed-loop fit ({}): torque gains {:.3} / {:.3} / {:.3}, flapping {:.3}, objective {:.4} ({} evaluations)",
            base.display(),
            r.terms.torque_gain[0],
            r.terms.torque_gain[1],
            r.terms.torque_gain[2],
            r.terms.flap_rad_s2_per_m_s,
            r.objective,
            r.evaluations
        );
        plants.push(("identified".into(), Box::new(r.terms.apply(&base_for_open))));
        loop_fit = Some(r);
    }
    let test = if args.test {
        Some(read_split(&args.data, "test")?)
    } else {
        None
    };
    let mut scores = Vec::new();
    let mut figures: Vec<(String, Vec<(String, closed_loop::Flown)>)> = Vec::new();
    let mut splits: Vec<(&str, Vec<&LoopFlight>)> = vec![("train", train_refs.clone())];
    if let Some(t) = &test {
        splits.push(("test", t.iter().collect()));
    }
    for (split, flights) in &splits {
        for (name, plant) in &plants {
            eprintln!("replaying {name} on {} {split} flights…", flights.len());
            let (windows, rows, flown) =
                score_plant(flights, plant.as_ref(), &cfg, &args.windows, args.stride);
            for w in &windows {
                eprintln!(
                    "  {split} {name} {:>4} rows: position {:.4} m, attitude {:.4} rad, {} windows, {} diverged",
                    w.steps, w.pos_rmse_m, w.att_rmse_rad, w.windows, w.diverged
                );
            }
            for (f, fl) in flights.iter().zip(flown) {
                match figures.iter_mut().find(|(n, _)| n == &f.name) {
                    Some((_, v)) => v.push((name.clone(), fl)),
                    None => figures.push((f.name.clone(), vec![(name.clone(), fl)])),
                }
            }
            scores.push(PlantScore {
                plant: name.clone(),
                split: split.to_string(),
                windows,
                flights: rows,
            });
        }
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let all: Vec<&LoopFlight> = splits.iter().flat_map(|(_, v)| v.iter().copied()).collect();
    for (fname, runs) in &figures {
        if let Some(f) = all.iter().find(|f| &f.name == fname) {
            plot::replay_svg(f, runs, &args.out.join(format!("{fname}.svg")))?;
        }
    }
    let report = ReplayReport {
        config: cfg,
        open_loop,
        loop_fit,
        scores,
    };
    write_json_atomic(&args.out.join("report.json"), &report)?;
    eprintln!(
        "wrote {}/report.json and {} figures",
        args.out.display(),
        figures.len()
    );
    Ok(report)
}
