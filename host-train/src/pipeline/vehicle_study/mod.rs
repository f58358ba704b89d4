//! `host-train vehicle-study`: the evidence on a vehicle the nominal model does not know.
//!
//! 1. **Log.** Bitcraze's Lee-type geometric controller ([`logging_controller`], told the
//!    vehicle's true mass and inertia, as Bitcraze's Lee is configured, and its motor lag)
//!    flies the vehicle of `--vehicle` ([`VEHICLES`]: `heavy`, the default, 0.034 kg, inertia ×1.3, rotor 3 at 90 %,
//!    20 ms motor lag; `light`, 0.030 kg, another inertia, 70 ms lag; `asym`, 0.031 kg, rotors 1
//!    and 2 at 80 / 85 %, 30 ms lag; all with rotor drag and paper-spiral-realistic's state
//!    noise; or a scenario file's `[vehicle]` and `[effects]`) through [`flight_plan`]: hover, circles and spirals, three in calm air and five under wind
//!    (constant, a step, a sinusoid; one with a weak rotor), each `--flight-s` long, logged as
//!    uSD-card deck version-2 logs at 500 Hz (`DIR/logs/*.bin`, [`crate::fly::usdrecord`]).
//! 2. **Import** ([`crate::data::import`]) with the vehicle's mass, inertia, rotor efficiencies and
//!    `--motor-tau-s` of its motors; the calm flights are marked disturbance-free (`DIR/data`).
//! 3. **Train** `--seeds` blobs (`DIR/seed-K.hfw` and its `.json` report, which holds the
//!    held-out N-step errors of the learned model against the nominal one).
//! 4. **Fly** the vehicle's calm spiral, windy spiral and mid-flight rotor loss (for `heavy`:
//!    `mismatch-calm-spiral`, `mismatch-paper-spiral`, `mismatch-rotor-loss`) with
//!    [`STUDY_CONTROLLERS`], both adaptation laws; write `DIR/report.json` and the markdown
//!    table `DIR/table.md` ([`table`]).
//!
//! Scores are position RMSE over t ≥ 5 s ([`crate::fly::eval::Report::rmse_pos_window_m`]).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use hamflight::model::NominalModel;
use hamflight::{AdaptationLaw, Gains, VehicleFacts};
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use crate::control::adapter::CoreController;
use crate::control::baselines::Geometric;
use crate::control::controller::Controller;
use crate::control::{adapter, registry};
use crate::data::import::{self, ImportArgs, LogFormat};
use crate::fly::eval::{self, Report};
use crate::fly::usdrecord::UsdRecorder;
use crate::io::files::{write_atomic, write_json_atomic};
use crate::pipeline::train as pipeline_train;
use crate::sim::plant::{WindSine, WindStep};
use crate::sim::scenario::{DisturbanceSpec, Scenario, Trajectory};
use crate::train::{self, TrainConfig};

mod plan;
mod table;

pub use plan::{flight_plan, PlannedFlight};
pub use table::table;

/// The calm spiral on the heavy vehicle (built in, so the study runs from any directory).
pub const CALM_SPIRAL_TOML: &str = include_str!("../../../../scenarios/mismatch-calm-spiral.toml");
/// paper-spiral on the heavy vehicle.
pub const PAPER_SPIRAL_TOML: &str =
    include_str!("../../../../scenarios/mismatch-paper-spiral.toml");

/// A built-in study vehicle: its name and its three scenarios (name, TOML): the calm spiral
/// (whose `[vehicle]` and `[effects]` the logged flights use), the windy spiral, the rotor loss.
pub struct StudyVehicle {
    /// `--vehicle NAME`.
    pub name: &'static str,
    /// One line for the help text.
    pub description: &'static str,
    /// Calm spiral, windy spiral, mid-flight rotor loss.
    pub scenarios: [(&'static str, &'static str); 3],
}

/// The built-in vehicles (`--vehicle heavy|light|asym`), built in so the study runs from any
/// directory.
pub static VEHICLES: [StudyVehicle; 3] = [
    StudyVehicle {
        name: "heavy",
        description: "0.034 kg, inertia ×1.3, rotor 3 at 90 %, 20 ms motor lag",
        scenarios: [
            ("mismatch-calm-spiral", CALM_SPIRAL_TOML),
            ("mismatch-paper-spiral", PAPER_SPIRAL_TOML),
            (
                "mismatch-rotor-loss",
                include_str!("../../../../scenarios/mismatch-rotor-loss.toml"),
            ),
        ],
    },
    StudyVehicle {
        name: "light",
        description: "0.030 kg, inertia diag(1.50, 1.60, 2.90)e-5, 70 ms motor lag",
        scenarios: [
            (
                "light-calm-spiral",
                include_str!("../../../../scenarios/light-calm-spiral.toml"),
            ),
            (
                "light-windy-spiral",
                include_str!("../../../../scenarios/light-windy-spiral.toml"),
            ),
            (
                "light-rotor-loss",
                include_str!("../../../../scenarios/light-rotor-loss.toml"),
            ),
        ],
    },
    StudyVehicle {
        name: "asym",
        description: "0.031 kg, inertia ×1.1, rotors 1 and 2 at 80 / 85 %, 30 ms motor lag",
        scenarios: [
            (
                "asym-calm-spiral",
                include_str!("../../../../scenarios/asym-calm-spiral.toml"),
            ),
            (
                "asym-windy-spiral",
                include_str!("../../../../scenarios/asym-windy-spiral.toml"),
            ),
            (
                "asym-rotor-loss",
                include_str!("../../../../scenarios/asym-rotor-loss.toml"),
            ),
        ],
    },
];

/// The controllers of the table, in order: (key, description).
pub const STUDY_CONTROLLERS: [(&str, &str); 12] = [
    (
        "geometric",
        "Lee geometric (true mass, inertia and motor lag; the logging controller)",
    ),
    (
        "ida-pbc-stock",
        "nominal IDA-PBC, stock vehicle's constants",
    ),
    ("ida-pbc-true", "nominal IDA-PBC, TRUE mass and inertia"),
    (
        "geometric-adaptive-gradient",
        "geometric-adaptive (nominal, stock constants), gradient law",
    ),
    (
        "geometric-adaptive-composite",
        "geometric-adaptive (nominal, stock constants), composite law",
    ),
    (
        TRUE_COMPOSITE,
        "nominal, TRUE mass, inertia and motor lag, composite law (the floor)",
    ),
    ("learned", "learned, no adaptation"),
    ("adaptive-gradient", "adaptive (learned), gradient law"),
    ("adaptive-composite", "adaptive (learned), composite law"),
    (
        "learned-no-lag",
        "learned, no adaptation, trained on the commanded wrench (no --motor-tau-s)",
    ),
    (
        "adaptive-gradient-no-lag",
        "adaptive (learned), gradient law, trained on the commanded wrench (no --motor-tau-s)",
    ),
    (
        "adaptive-composite-no-lag",
        "adaptive (learned), composite law, trained on the commanded wrench (no --motor-tau-s)",
    ),
];

/// The key of the composite law on the nominal model told the vehicle's true mass, inertia and
/// motor lag: the floor a learned model can reach under that law, since a model can know no more
/// than the truth. With the scenarios' measurement noise it sets the calm spirals' error
/// (`docs/vehicles.md`, "What sets the floor").
pub const TRUE_COMPOSITE: &str = "geometric-adaptive-composite-true";

/// Arguments of `host-train vehicle-study`.
#[derive(Args, Debug, Clone)]
pub struct VehicleStudyArgs {
    /// Output directory: logs/, data/, seed-K.hfw(.json), report.json, table.md.
    #[arg(long, value_name = "DIR", default_value = "out/vehicle-study")]
    pub out: PathBuf,
    /// Training seeds (0..N).
    #[arg(long, default_value_t = 3)]
    pub seeds: u64,
    /// Skip the comparison blob trained without the motor-lag filter (seed 0).
    #[arg(long)]
    pub no_lag_comparison: bool,
    /// Training epochs per seed.
    #[arg(long, default_value_t = 20)]
    pub epochs: usize,
    /// Length of each logged training flight (s); eight flights.
    #[arg(long, default_value_t = 10.0)]
    pub flight_s: f64,
    /// The vehicle: `heavy` (default; 0.034 kg, inertia ×1.3, rotor 3 at 90 %, 20 ms motor
    /// lag), `light` (0.030 kg, another inertia, 70 ms lag) or `asym` (0.031 kg, rotors 1 and 2
    /// at 80 / 85 %, 30 ms lag), each with rotor drag and noisy state estimates and its calm
    /// spiral, windy spiral and rotor loss; or a scenario file whose `[vehicle]` and `[effects]`
    /// the logged flights use (then the heavy vehicle's scenarios are flown unless --calm,
    /// --disturbed and --rotor-loss name others).
    #[arg(long, value_name = "NAME|FILE", default_value = "heavy")]
    pub vehicle: String,
    /// The calm scenario flown for the table (default: the vehicle's calm spiral).
    #[arg(long, value_name = "FILE")]
    pub calm: Option<PathBuf>,
    /// The windy scenario flown for the table (default: the vehicle's windy spiral).
    #[arg(long, value_name = "FILE")]
    pub disturbed: Option<PathBuf>,
    /// The rotor-loss scenario flown for the table (default: the vehicle's rotor loss).
    #[arg(long, value_name = "FILE")]
    pub rotor_loss: Option<PathBuf>,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Also write the flights' scores and the vehicle as JSON here (no wall-clock times or
    /// paths): the source of the docs' vehicle tables, `docs/data/vehicle-study-NAME.json`,
    /// which `tools/vehicle-study-doc-data.sh` regenerates.
    #[arg(long, value_name = "FILE")]
    pub scores: Option<PathBuf>,
}

impl VehicleStudyArgs {
    /// The defaults, writing to `out`.
    pub fn new(out: &Path) -> Self {
        Self {
            out: out.to_path_buf(),
            seeds: 3,
            no_lag_comparison: false,
            epochs: 20,
            flight_s: 10.0,
            vehicle: "heavy".into(),
            calm: None,
            disturbed: None,
            rotor_loss: None,
            quiet: true,
            scores: None,
        }
    }
}

/// One controller on one scenario, with the seed of its blob (learned ones).
#[derive(Clone, Debug, Serialize)]
pub struct Flown {
    /// Key in [`STUDY_CONTROLLERS`].
    pub controller: String,
    /// Training seed of the blob, for `learned` and `adaptive`.
    pub seed: Option<u64>,
    /// Scenario name.
    pub scenario: String,
    /// Position RMSE over t ≥ 5 s (m); null if the flight ended before.
    pub rmse_m: Option<f64>,
    /// Crashed.
    pub crashed: bool,
    /// Crash time (s).
    pub crash_time_s: Option<f64>,
}

/// One seed's training summary.
#[derive(Clone, Debug, Serialize)]
pub struct SeedSummary {
    /// Training seed.
    pub seed: u64,
    /// Trained on the realized command (`import --motor-tau-s`); false: on the commanded one.
    pub motor_lag_filter: bool,
    /// The blob.
    pub weights: String,
    /// Training windows.
    pub train_windows: usize,
    /// Held-out windows.
    pub heldout_windows: usize,
    /// Training wall time (s).
    pub train_time_s: f64,
    /// Held-out N-step errors at step N (pos m, rot rad, vel m/s, rate rad/s): learned with a_j.
    pub heldout_learned: [f64; 4],
    /// The same for the stock vehicle's nominal model.
    pub heldout_nominal_stock: [f64; 4],
    /// The same for the nominal model with the true mass and inertia.
    pub heldout_nominal_true: Option<[f64; 4]>,
    /// Learned J at hover, diagonal (kg·m²).
    pub learned_inertia_diag_kg_m2: [f32; 3],
    /// Learned thrust gain g (body z force per N of commanded thrust) at hover.
    pub learned_thrust_gain: f32,
}

/// `DIR/report.json`.
#[derive(Clone, Debug, Serialize)]
pub struct StudyReport {
    /// The vehicle (the plant's constants).
    pub vehicle: crate::sim::plant::VehicleParams,
    /// Motor time constant (s).
    pub motor_tau_s: f64,
    /// Logged flights (in import order: windy, then calm): log name, calm, samples kept.
    pub logs: Vec<(String, bool, usize)>,
    /// One summary per trained blob: the seeds on the realized command, then the comparison
    /// blob on the commanded one.
    pub seeds: Vec<SeedSummary>,
    /// Every flight of the table.
    pub flights: Vec<Flown>,
    /// The scenarios flown: calm spiral, windy spiral, rotor loss.
    pub scenarios: Vec<String>,
    /// Wall time of the study (s).
    pub wall_s: f64,
}

impl StudyReport {
    /// The flights of `controller` on `scenario`, in seed order.
    pub fn results(&self, controller: &str, scenario: &str) -> Vec<&Flown> {
        self.flights
            .iter()
            .filter(|f| f.controller == controller && f.scenario == scenario)
            .collect()
    }
}

fn load_or_builtin(path: Option<&Path>, builtin: &str, name: &str) -> Result<Scenario> {
    match path {
        Some(p) => Scenario::load(p),
        None => Scenario::from_toml_str(builtin, &format!("built-in {name}"), name),
    }
}

fn last4(e: &train::export::PredictionErrors) -> [f64; 4] {
    let l = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
    [l(&e.pos_m), l(&e.rot_rad), l(&e.vel_m_s), l(&e.rate_rad_s)]
}

/// The logging controller: Lee on the vehicle's true mass and inertia, told its motor lag
/// ([`Geometric::with_motor_lag`]: a lead for lags over 30 ms, so the light vehicle's 70 ms
/// flies; the heavy and asymmetric vehicles' 20 and 30 ms fly Lee unchanged).
pub fn logging_controller(sc: &Scenario) -> Geometric {
    Geometric::with_motor_lag(sc.vehicle.clone(), sc.spec.effects.motor_tau_s)
}

fn fly_one(sc: &Scenario, key: &str, seed: Option<u64>, ctrl: &mut dyn Controller) -> Flown {
    let log = eval::fly(sc, ctrl);
    let r = Report::from_log(&log, None);
    Flown {
        controller: key.to_string(),
        seed,
        scenario: sc.name.clone(),
        rmse_m: r.rmse_pos_window_m,
        crashed: r.crashed,
        crash_time_s: r.crash_time_s,
    }
}

/// Runs the study (module docs) and writes its outputs into `args.out`.
///
/// # Errors
/// A scenario that does not load, a crash of the logging controller, or any import, training
/// or I/O error.
pub fn run(args: &VehicleStudyArgs) -> Result<StudyReport> {
    let t0 = Instant::now();
    let named = VEHICLES.iter().find(|v| v.name == args.vehicle);
    let builtin = named.unwrap_or(&VEHICLES[0]);
    let [calm_b, windy_b, loss_b] = builtin.scenarios;
    let base = match named {
        Some(_) => load_or_builtin(None, calm_b.1, calm_b.0)?,
        None if Path::new(&args.vehicle).exists() => Scenario::load(Path::new(&args.vehicle))?,
        None => {
            let names: Vec<&str> = VEHICLES.iter().map(|v| v.name).collect();
            anyhow::bail!(
                "--vehicle `{}`: expected one of {} or a scenario file",
                args.vehicle,
                names.join(", ")
            )
        }
    };
    let flown = [
        load_or_builtin(args.calm.as_deref(), calm_b.1, calm_b.0)?,
        load_or_builtin(args.disturbed.as_deref(), windy_b.1, windy_b.0)?,
        load_or_builtin(args.rotor_loss.as_deref(), loss_b.1, loss_b.0)?,
    ];
    let logs_dir = args.out.join("logs");
    std::fs::create_dir_all(&logs_dir)
        .with_context(|| format!("cannot create `{}`", logs_dir.display()))?;

    // 1. Log the Lee controller's flights.
    let mut calm_logs = Vec::new();
    let mut windy_logs = Vec::new();
    for (k, pf) in flight_plan().into_iter().enumerate() {
        let mut spec = base.spec.clone();
        spec.name = Some(pf.name.to_string());
        spec.description = None;
        spec.duration_s = args.flight_s;
        spec.seed = 100 + k as u64;
        spec.trajectory = pf.trajectory.clone();
        spec.disturbance = pf.disturbance.clone();
        spec.start = None;
        spec.yaw_rad = 0.0;
        spec.yaw_rate_rad_s = pf.yaw_rate_rad_s;
        let sc = Scenario::from_spec(pf.name, spec)?;
        let mut lee = logging_controller(&sc);
        let mut rec = UsdRecorder::new(&mut lee, sc.vehicle.clone());
        let log = eval::fly(&sc, &mut rec);
        if let Some(t) = log.crash_time_s {
            anyhow::bail!("the logging flight `{}` crashed at {t:.2} s", pf.name);
        }
        let path = logs_dir.join(format!("{k:02}-{}.bin", pf.name));
        rec.write(&path)?;
        if pf.calm {
            calm_logs.push(path);
        } else {
            windy_logs.push(path);
        }
    }

    // 2. Import with the vehicle's description and motor lag.
    let v = &base.vehicle;
    let tau = base.spec.effects.motor_tau_s;
    let data_dir = args.out.join("data");
    let imp = ImportArgs {
        logs: windy_logs,
        calm: calm_logs,
        format: LogFormat::Usd,
        gravity_m_s2: Some(v.gravity_m_s2),
        inertia_kg_m2: Some(v.inertia_kg_m2.to_vec()),
        rotor_efficiency: Some(v.rotor_efficiency.to_vec()),
        motor_tau_s: (tau > 0.0).then_some(tau),
        ..ImportArgs::new(data_dir.clone(), v.mass_kg)
    };
    let summaries = import::run(&imp)?;
    // import orders the windy logs first, then the calm ones.
    let kept: Vec<(String, bool, usize)> = summaries
        .iter()
        .map(|s| {
            let name = Path::new(&s.file)
                .file_stem()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            (name, s.disturbance_free, s.samples_kept)
        })
        .collect();

    let no_lag_dir = args.out.join("data-no-lag");
    if !args.no_lag_comparison {
        import::run(&ImportArgs {
            out: no_lag_dir.clone(),
            motor_tau_s: None,
            ..imp.clone()
        })?;
    }

    // 3. Train.
    let mut seeds = Vec::new();
    let mut blobs = Vec::new();
    let mut runs: Vec<(u64, bool)> = (0..args.seeds).map(|k| (k, true)).collect();
    if !args.no_lag_comparison {
        runs.push((0, false));
    }
    for (seed, lag) in runs {
        let cfg = TrainConfig {
            epochs: args.epochs,
            seed,
            // The comparison blob is trained on the wrench without the motor-lag filter, but it
            // still tells the controller the vehicle's lag (its gains and lag compensation come
            // from it): the comparison is of the training data, not of the vehicle facts.
            motor_tau_s: (!lag && tau > 0.0).then_some(tau),
            ..TrainConfig::default()
        };
        let (dir, blob) = if lag {
            (&data_dir, args.out.join(format!("seed-{seed}.hfw")))
        } else {
            (
                &no_lag_dir,
                args.out.join(format!("no-lag-seed-{seed}.hfw")),
            )
        };
        let r = pipeline_train::run(&cfg, dir, &blob, args.quiet)?;
        let j = r.learned_inertia_hover_kg_m2;
        seeds.push(SeedSummary {
            seed,
            motor_lag_filter: lag,
            weights: blob.display().to_string(),
            train_windows: r.train_windows,
            heldout_windows: r.heldout_windows,
            train_time_s: r.train_time_s,
            heldout_learned: last4(&r.heldout_learned),
            heldout_nominal_stock: last4(&r.heldout_nominal),
            heldout_nominal_true: r.heldout_nominal_true_vehicle.as_ref().map(last4),
            learned_inertia_diag_kg_m2: [j[0][0], j[1][1], j[2][2]],
            learned_thrust_gain: r.learned_gain_hover[2][0],
        });
        blobs.push((seed, lag, blob));
    }

    // 4. Fly the table.
    let mass = v.mass_kg as f32;
    let inertia = Matrix3::from_diagonal(&Vector3::from(v.inertia_kg_m2.map(|x| x as f32)));
    let mut flights = Vec::new();
    for sc in &flown {
        flights.push(fly_one(sc, "geometric", None, &mut logging_controller(sc)));
        flights.push(fly_one(sc, "ida-pbc-stock", None, &mut adapter::ida_pbc()));
        let true_model = NominalModel::new(mass, inertia);
        let mut true_nominal = CoreController::new(
            "ida-pbc-true",
            true_model,
            Gains {
                adapt: false,
                ..Gains::for_vehicle(&VehicleFacts::of(&true_model))
            },
        );
        flights.push(fly_one(sc, "ida-pbc-true", None, &mut true_nominal));
        let mut true_composite = CoreController::new(
            TRUE_COMPOSITE,
            true_model,
            Gains {
                law: AdaptationLaw::Composite,
                ..Gains::for_vehicle(&VehicleFacts {
                    motor_tau_s: tau as f32,
                    ..VehicleFacts::of(&true_model)
                })
            },
        );
        flights.push(fly_one(sc, TRUE_COMPOSITE, None, &mut true_composite));
        for key in [
            "geometric-adaptive-gradient",
            "geometric-adaptive-composite",
        ] {
            let mut c = registry::core_by_name(key, None)?;
            flights.push(fly_one(sc, key, None, c.as_mut()));
        }
        for (seed, lag, blob) in &blobs {
            for key in ["learned", "adaptive-gradient", "adaptive-composite"] {
                let mut c = registry::core_by_name(key, Some(blob))?;
                let label = if *lag {
                    key.to_string()
                } else {
                    format!("{key}-no-lag")
                };
                flights.push(fly_one(sc, &label, Some(*seed), c.as_mut()));
            }
        }
    }
    let report = StudyReport {
        vehicle: v.clone(),
        motor_tau_s: tau,
        logs: kept,
        seeds,
        flights,
        scenarios: flown.iter().map(|sc| sc.name.clone()).collect(),
        wall_s: t0.elapsed().as_secs_f64(),
    };
    write_json_atomic(&args.out.join("report.json"), &report)?;
    write_atomic(&args.out.join("table.md"), table(&report).as_bytes())?;
    if let Some(path) = &args.scores {
        let scores = serde_json::json!({
            "tool": "host-train vehicle-study (regenerate: tools/vehicle-study-doc-data.sh)",
            "vehicle": args.vehicle,
            "seeds": args.seeds,
            "epochs": args.epochs,
            "flight_s": args.flight_s,
            "mass_kg": report.vehicle.mass_kg,
            "rotor_efficiency": report.vehicle.rotor_efficiency,
            "motor_tau_s": report.motor_tau_s,
            "scenarios": report.scenarios,
            "flights": report.flights,
        });
        let mut text = serde_json::to_string_pretty(&scores)?;
        text.push('\n');
        write_atomic(path, text.as_bytes())?;
    }
    Ok(report)
}
