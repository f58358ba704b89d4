//! `host-train import`: flight logs in, a dataset ([`crate::io::dataset`]) out.
//!
//! Each input file becomes one realization (one a_j in training); `--calm FILE` imports a file
//! marked disturbance-free (a_j pinned to 0). Two sources:
//!
//! # (a) Bitcraze uSD-card deck logs ([`crate::io::usdlog`])
//!
//! The `fixedFrequency` event must hold these variables (`tools/usd/config.txt` logs them):
//! `stateEstimate.x/y/z` (m, world), `stateEstimate.vx/vy/vz` (m/s, **world**),
//! `stateEstimate.qx/qy/qz/qw` (attitude, body → world), `gyro.x/y/z` (deg/s, body) and the
//! commanded wrench, by default Bitcraze's Lee controller's `ctrlLee.thrustSi` (N) and
//! `ctrlLee.torquex/y/z` (N·m) (`--command-vars` names others, for example our Crazyflie app's).
//! `acc.x/y/z` (g, body specific force) is optional. Conversions: R from the normalised
//! quaternion, v_body = Rᵀ v_world, ω = gyro · π/180, acc · 9.81 m/s². Other event types are
//! skipped and counted.
//!
//! # (b) CSV of time-stamped states and commanded wrench
//!
//! A header line with (at least) these columns, in any order, SI units:
//!
//! ```text
//! t_s,px_m,py_m,pz_m,qw,qx,qy,qz,vx_world_m_s,vy_world_m_s,vz_world_m_s,wx_rad_s,wy_rad_s,wz_rad_s,f_n,tau_x_nm,tau_y_nm,tau_z_nm
//! ```
//!
//! plus optionally `ax_m_s2,ay_m_s2,az_m_s2` (body specific force). Instead of the wrench a
//! log may give the four **measured rotor speeds**, `w1_rad_s..w4_rad_s` (rad/s) or
//! `erpm1..erpm4` (electrical rpm, with `--motor-poles N`: rpm = eRPM / (N/2)); the realized
//! wrench is then computed from them with `--vehicle`'s coefficients (rotor numbering of
//! [`crate::sim::vehicle`]), after glitches (non-finite, negative, above 1.5× the top speed, or
//! one-sample spikes) are interpolated and counted. The uSD path takes rotor speeds in rpm
//! with `--rotor-speed-vars` (for example the rpm deck's `rpm.m1..m4`; Bitcraze's `motor.m1..m4`
//! are PWM duty, not speeds, and are not accepted). One row per state sample:
//! time (s), world position, attitude quaternion (body → world, any sign, normalised on
//! import), **world** velocity, **body** angular rate, and the commanded thrust and body torques
//! in force from that sample on. Extra columns are ignored.
//!
//! # Rates and resampling
//!
//! States are never interpolated: the dataset keeps each log's own sample times, and its rate is
//! the median sample interval of the first input (every input must agree within 10 %). Where
//! the command is logged at another rate than the state (CSV rows with empty command cells),
//! the last command is held (zero-order hold, as the motors hold it); rows before the first
//! command are dropped.
//!
//! # Motor dynamics (`--motor-tau-s T`)
//!
//! The log holds the *commanded* wrench; with motor lag the rotors realize it only after a
//! delay, and a model trained on the commanded wrench takes up the lag elsewhere (on the heavy
//! vehicle of docs/vehicles.md it learned a J several times too large). With `--motor-tau-s T`
//! the importer turns each logged command into the realized one the trainer integrates. The log
//! has no motor outputs, so the wrench is taken apart per rotor through the mixer inverse of `--vehicle`
//! (else the CF2X's) into squared rotor speeds ωᵢ² (as
//! [`crate::sim::plant::VehicleParams::wrench_to_rpm_squared`]), each rotor speed follows
//! the commanded one through the first-order lag ω̇ᵢ = (ωᵢ,cmd − ωᵢ)/T from sample to sample
//! (exactly, the command held between samples), and the stored wrench is that of the step's
//! mean ωᵢ² (exact for the lag). The filter starts at each continuous stretch's first command
//! (the rotors at steady state) and runs over every decoded sample before the airborne rule
//! picks flights, so take-off's transient is outside the kept data. The manifest's
//! `vehicle.motor_tau_s` records T. `--inertia-kg-m2` and `--rotor-efficiency` describe the
//! vehicle further for the training report's "true" values; `--vehicle FILE` describes it
//! whole ([`crate::sim::vehicle`]) and is saved in the manifest for training.
//!
//! # Ground, take-off and landing
//!
//! A sample is on the ground when `z < --min-height-m` (default 0.10 m above the floor, z = 0),
//! or when the thrust is below `--min-thrust-frac` (default 0.25) of m g *and* the vehicle
//! stands still (speed under 0.1 m/s) for at least `--min-ground-s` (default 0.3 s): an
//! aggressive descent at low thrust is flight, a landing on a table is not. Each airborne
//! stretch (split at non-increasing timestamps and at gaps over `--max-gap-s`, default 0.1 s;
//! shorter gaps stay inside a flight, and training's windows never span one) loses `--trim-s`
//! (default 0.5 s) at both ends, where take-off and landing transients, ground contact and
//! ground effect act; what remains becomes one flight of the dataset.
//!
//! # Messy logs
//!
//! - A sample whose state repeats the previous one exactly while its velocity or rate says it
//!   moved (a dropped packet filled in by a resampling logger) is dropped and counted
//!   (`repeated_states` in the summary).
//! - A quaternion whose norm differs from 1 by more than 1e-3 is an error naming the row.
//!
//! Bad input gets an error naming the file and the byte offset (uSD) or line (CSV); all inputs
//! are decoded before anything is written, and every file is written whole.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use crate::io::dataset::{self, Dataset, Realization, RealizationMeta, Sample};
use crate::io::usdlog::{self, ParseOptions, LEE_COMMAND_VARS};
use crate::sim::plant::{PlantState, VehicleParams};

mod clean;
mod csv;
mod usd;

pub use clean::{
    airborne_flights, drop_repeated_states, fix_rotor_glitches, median_dt_s, realize_commands,
    stretches,
};
pub use csv::decode_csv;
pub use usd::decode_usd;

/// Input format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// By content: a first byte 0xBC is a uSD log, anything else CSV.
    Auto,
    /// Bitcraze uSD-card deck binary log.
    Usd,
    /// The documented CSV.
    Csv,
}

/// Arguments of `host-train import`; also [`ImportJob`], the same arguments as a typed
/// (serde) job: a key left out takes the flag's default ([`ImportArgs::default`], which the
/// flags read too), an unknown key is an error.
#[derive(Args, Clone, Debug, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImportArgs {
    /// Output dataset directory (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Flight logs, one realization (one a_j) each.
    #[arg(value_name = "LOG")]
    pub logs: Vec<PathBuf>,
    /// Flight logs flown without disturbance (their a_j is pinned to 0 in training). Takes every
    /// log that follows it up to the next option (`--calm C1 C2`), and may be repeated; give the
    /// disturbed logs before it.
    #[arg(long, value_name = "LOG", num_args = 1..)]
    pub calm: Vec<PathBuf>,
    /// Input format.
    #[arg(long, value_enum, default_value_t = LogFormat::Auto)]
    pub format: LogFormat,
    /// The vehicle description (a TOML file, see `host_train::sim::vehicle`, or `cf2x`): mass,
    /// gravity, inertia, airframe, rotor coefficients and motor lag. It turns rotor speeds into
    /// the realized wrench, gives the motor-lag filter its mixer, and is saved in the manifest
    /// for training's prior and flight check.
    #[arg(long, value_name = "FILE|cf2x")]
    pub vehicle: Option<PathBuf>,
    /// Vehicle mass (kg), written to the manifest and used by the thrust rule. Required unless
    /// `--vehicle` gives it (then this overrides it): neither log format carries it, and a wrong
    /// mass scales every force the model learns (the stock Crazyflie 2.1 is 0.027).
    #[arg(long, required_unless_present = "vehicle")]
    pub mass_kg: Option<f64>,
    /// Gravity (m/s²) [default: the vehicle's, else 9.8].
    #[arg(long)]
    pub gravity_m_s2: Option<f64>,
    /// Vehicle inertia diag(J) (kg·m²), comma-separated, overriding the vehicle file's.
    #[arg(long, value_delimiter = ',', value_name = "JX,JY,JZ")]
    pub inertia_kg_m2: Option<Vec<f64>>,
    /// The vehicle's own rotor thrust factors δ₁..δ₄, when known; for the training report only.
    #[arg(long, value_delimiter = ',', value_name = "D1,D2,D3,D4")]
    pub rotor_efficiency: Option<Vec<f64>>,
    /// First-order motor time constant (s): store the realized command (the logged one through
    /// the motor lag, per rotor) instead of the logged one; see the module docs. Not with
    /// measured rotor speeds (they are realized already).
    #[arg(long, value_name = "T")]
    pub motor_tau_s: Option<f64>,
    /// Motor pole count, for CSV rotor speeds logged as electrical rpm (`erpm1..erpm4`):
    /// mechanical rpm = eRPM / (poles / 2).
    #[arg(long, value_name = "POLES")]
    pub motor_poles: Option<u32>,
    /// uSD variables of the four measured rotor speeds (rpm), comma-separated (for example the
    /// rpm deck's `rpm.m1,rpm.m2,rpm.m3,rpm.m4`); then the wrench comes from them and the
    /// vehicle's coefficients, not from `--command-vars`.
    #[arg(long, value_delimiter = ',', value_name = "V1,V2,V3,V4")]
    pub rotor_speed_vars: Vec<String>,
    /// uSD variables of the commanded thrust (N) and body torques (N·m), comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = LEE_COMMAND_VARS.map(String::from))]
    pub command_vars: Vec<String>,
    /// Airborne only at or above this height (m, world z).
    #[arg(long, default_value_t = ImportArgs::default().min_height_m)]
    pub min_height_m: f64,
    /// Airborne only with a commanded thrust of at least this fraction of m g.
    #[arg(long, default_value_t = ImportArgs::default().min_thrust_frac)]
    pub min_thrust_frac: f64,
    /// Seconds cut from both ends of every airborne stretch (take-off, landing).
    #[arg(long, default_value_t = ImportArgs::default().trim_s)]
    pub trim_s: f64,
    /// Gaps in the log (dropped packets, removed repeated states) up to this long stay inside
    /// one flight; longer ones end it. Training never integrates across a gap either way.
    #[arg(long, default_value_t = ImportArgs::default().max_gap_s)]
    pub max_gap_s: f64,
    /// Low thrust counts as landed only when the vehicle also stays still (speed under
    /// 0.1 m/s) this long: an aggressive descent at low thrust is still flight.
    #[arg(long, default_value_t = ImportArgs::default().min_ground_s)]
    pub min_ground_s: f64,
    /// Decode uSD logs whose CRC does not match (for example cut short by a power loss).
    #[arg(long)]
    pub allow_bad_crc: bool,
    /// Keep exactly repeated states (see "Messy logs"): for scoring on a log as a benchmark
    /// protocol defines it, never for training.
    #[arg(long)]
    pub keep_repeated_states: bool,
}

impl ImportArgs {
    /// The command line's defaults, writing to `out`, for a vehicle of `mass_kg` (callers set
    /// the logs and anything else with struct update syntax).
    pub fn new(out: PathBuf, mass_kg: f64) -> Self {
        Self {
            out,
            mass_kg: Some(mass_kg),
            ..Self::default()
        }
    }
}

/// A typed log-import configuration that the CLI (`host-train import`) and Python
/// (`hamflight.import_logs`) both call directly: [`ImportArgs`], built from serde (JSON) instead
/// of a command line.
pub type ImportJob = ImportArgs;

impl Default for ImportArgs {
    /// The command line's defaults (the flags read them), with no `out`, logs or mass.
    fn default() -> Self {
        Self {
            out: PathBuf::new(),
            logs: Vec::new(),
            calm: Vec::new(),
            format: LogFormat::Auto,
            vehicle: None,
            mass_kg: None,
            gravity_m_s2: None,
            inertia_kg_m2: None,
            rotor_efficiency: None,
            motor_tau_s: None,
            motor_poles: None,
            rotor_speed_vars: Vec::new(),
            command_vars: LEE_COMMAND_VARS.map(String::from).to_vec(),
            min_height_m: 0.10,
            min_thrust_frac: 0.25,
            trim_s: 0.5,
            max_gap_s: 0.1,
            min_ground_s: 0.3,
            allow_bad_crc: false,
            keep_repeated_states: false,
        }
    }
}

/// What the import of one file found.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FileSummary {
    /// The input file.
    pub file: String,
    /// Samples decoded.
    pub samples_in: usize,
    /// Samples kept (airborne, trimmed).
    pub samples_kept: usize,
    /// Flights written.
    pub flights: usize,
    /// Events of other types skipped (uSD).
    pub skipped_events: usize,
    /// The CRC matched (uSD; true for CSV).
    pub crc_ok: bool,
    /// Marked disturbance-free.
    pub disturbance_free: bool,
    /// Samples that repeated the previous state exactly (a dropped packet filled in by the
    /// logger), dropped.
    pub repeated_states: usize,
    /// Rotor-speed readings out of range or spiking for one sample, interpolated.
    pub rotor_glitches: usize,
}

/// Decoded samples of one log, in file order, with what was skipped.
#[derive(Clone, Debug, Default)]
pub struct Decoded {
    /// The samples.
    pub samples: Vec<Sample>,
    /// Events of other types skipped.
    pub skipped_events: usize,
    /// CRC matched.
    pub crc_ok: bool,
    /// Measured rotor speeds (rad/s) per sample, when the log has them (the wrench is then
    /// computed from them, after [`fix_rotor_glitches`]).
    pub rotor_rad_s: Option<Vec<[f64; 4]>>,
}

/// A quaternion's norm may differ from 1 by this much (rounding in a log); more is an error.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

fn state_from(
    p: [f64; 3],
    q_xyzw: [f64; 4],
    v_world: [f64; 3],
    w_body: [f64; 3],
) -> Option<PlantState> {
    let q = Quaternion::new(q_xyzw[3], q_xyzw[0], q_xyzw[1], q_xyzw[2]);
    let n = q.norm();
    if !(n.is_finite() && (n - 1.0).abs() <= QUATERNION_NORM_TOLERANCE) {
        return None;
    }
    let rot = UnitQuaternion::from_quaternion(q)
        .to_rotation_matrix()
        .into_inner();
    Some(PlantState {
        p_m: Vector3::from(p),
        rot,
        v_body_m_s: rot.transpose() * Vector3::from(v_world),
        w_body_rad_s: Vector3::from(w_body),
    })
}

fn quat_norm(q: [f64; 4]) -> f64 {
    q.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Reads and decodes one log in `format`.
///
/// # Errors
/// An unreadable file or the decoders' errors.
pub fn decode_file(path: &Path, args: &ImportArgs) -> Result<Decoded> {
    let bytes =
        std::fs::read(path).with_context(|| format!("cannot read log `{}`", path.display()))?;
    let usd = match args.format {
        LogFormat::Usd => true,
        LogFormat::Csv => false,
        LogFormat::Auto => bytes.first() == Some(&usdlog::MAGIC),
    };
    if usd {
        decode_usd(
            path,
            &bytes,
            &args.command_vars,
            &args.rotor_speed_vars,
            ParseOptions {
                allow_bad_crc: args.allow_bad_crc,
            },
        )
    } else {
        decode_csv(path, &bytes, args.motor_poles)
    }
}

/// Runs `host-train import`: decodes every log, then writes the dataset. Returns a summary per
/// input file.
///
/// # Errors
/// No input, bad settings, any decoding error, logs at different rates, a log with no airborne
/// flight, or a failure writing (nothing is written before every input has decoded).
pub fn run(args: &ImportArgs) -> Result<Vec<FileSummary>> {
    let inputs: Vec<(&PathBuf, bool)> = args
        .logs
        .iter()
        .map(|p| (p, false))
        .chain(args.calm.iter().map(|p| (p, true)))
        .collect();
    if inputs.is_empty() {
        bail!(
            "no logs given: host-train import --out DIR (--vehicle FILE | --mass-kg KG) LOG... \
             [--calm LOG...]"
        );
    }
    let vehicle = args
        .vehicle
        .as_deref()
        .map(crate::sim::vehicle::VehicleFile::load)
        .transpose()?;
    let Some(mass_kg) = args.mass_kg.or(vehicle.as_ref().map(|v| v.mass_kg)) else {
        bail!(
            "the vehicle's mass is required: --mass-kg KG, or --vehicle FILE (the stock \
             Crazyflie 2.1 is `--vehicle cf2x`, 0.027 kg)"
        );
    };
    let gravity_m_s2 = args
        .gravity_m_s2
        .or(vehicle.as_ref().map(|v| v.gravity_m_s2))
        .unwrap_or(9.8);
    let args = &ImportArgs {
        mass_kg: Some(mass_kg),
        gravity_m_s2: Some(gravity_m_s2),
        ..args.clone()
    };
    let positive = |x: f64| x.is_finite() && x > 0.0;
    if !positive(mass_kg) || !positive(gravity_m_s2) {
        bail!("--mass-kg and --gravity-m-s2 must be positive");
    }
    if args
        .motor_tau_s
        .is_some_and(|t| !(t.is_finite() && t >= 0.0))
    {
        bail!("--motor-tau-s must be a time constant ≥ 0 s");
    }
    let inertia: Option<[f64; 3]> = match &args.inertia_kg_m2 {
        None => vehicle.as_ref().map(|v| v.inertia_kg_m2),
        Some(j) => match <[f64; 3]>::try_from(j.as_slice()) {
            Ok(j) if j.iter().all(|x| positive(*x)) => Some(j),
            _ => bail!("--inertia-kg-m2 needs three positive moments (kg·m²), got {j:?}"),
        },
    };
    let rotor_efficiency: Option<[f64; 4]> = match &args.rotor_efficiency {
        None => None,
        Some(d) => match <[f64; 4]>::try_from(d.as_slice()) {
            Ok(d) if d.iter().all(|x| positive(*x) && *x <= 2.0) => Some(d),
            _ => bail!("--rotor-efficiency needs four factors in (0, 2], got {d:?}"),
        },
    };
    if !(args.trim_s.is_finite()
        && args.trim_s >= 0.0
        && args.min_height_m.is_finite()
        && args.min_thrust_frac.is_finite()
        && args.max_gap_s.is_finite()
        && args.max_gap_s > 0.0
        && args.min_ground_s.is_finite()
        && args.min_ground_s >= 0.0)
    {
        bail!(
            "--trim-s and --min-ground-s must be ≥ 0, --max-gap-s > 0, and --min-height-m, \
             --min-thrust-frac finite"
        );
    }
    let mut decoded = Vec::with_capacity(inputs.len());
    let mut cleaning = Vec::with_capacity(inputs.len());
    for (path, calm) in &inputs {
        let mut d = decode_file(path, args)?;
        let mut glitches = 0;
        if let Some(mut w) = d.rotor_rad_s.take() {
            let Some(v) = vehicle.as_ref() else {
                bail!(
                    "`{}` gives rotor speeds: the wrench needs the vehicle's rotor coefficients \
                     (--vehicle FILE)",
                    path.display()
                );
            };
            if args.motor_tau_s.is_some_and(|t| t > 0.0) {
                bail!(
                    "`{}` gives measured rotor speeds, which the motors have realized already: \
                     leave out --motor-tau-s",
                    path.display()
                );
            }
            let t: Vec<f64> = d.samples.iter().map(|s| s.t_s).collect();
            glitches = fix_rotor_glitches(&t, &mut w, v.max_rotor_speed_rad_s())
                .with_context(|| format!("`{}`", path.display()))?;
            for (s, w) in d.samples.iter_mut().zip(&w) {
                s.wrench = v.wrench_of_rotor_speeds(*w);
                s.rpm = Some(w.map(|x| x * crate::sim::vehicle::RPM_PER_RAD_S));
            }
            d.rotor_rad_s = Some(w);
        }
        let repeated = if args.keep_repeated_states {
            0
        } else {
            drop_repeated_states(&mut d)
        };
        cleaning.push((repeated, glitches));
        decoded.push((*path, *calm, d));
    }
    let Some(dt) = decoded
        .first()
        .and_then(|(_, _, d)| median_dt_s(&d.samples))
    else {
        bail!("`{}`: fewer than two samples", inputs[0].0.display());
    };
    let sample_hz = 1.0 / dt;
    let mut ds = Dataset::new(sample_hz, mass_kg, gravity_m_s2, "import");
    // The lag filter realizes logged commands; measured rotor speeds are realized already.
    let any_speeds = decoded.iter().any(|(_, _, d)| d.rotor_rad_s.is_some());
    let tau = args
        .motor_tau_s
        .or(vehicle
            .as_ref()
            .and_then(|v| v.motor_tau_s)
            .filter(|_| !any_speeds))
        .filter(|t| *t > 0.0);
    ds.manifest.vehicle = dataset::VehicleDescription {
        inertia_kg_m2: inertia,
        rotor_efficiency,
        motor_tau_s: tau,
        description: vehicle.clone().map(|v| crate::sim::vehicle::VehicleFile {
            mass_kg,
            gravity_m_s2,
            inertia_kg_m2: inertia.unwrap_or(v.inertia_kg_m2),
            ..v
        }),
    };
    if let Some(tau) = tau {
        let mixer = vehicle
            .as_ref()
            .map_or_else(VehicleParams::cf2x, |v| v.params());
        for (_, _, d) in decoded.iter_mut() {
            realize_commands(&mut d.samples, sample_hz, tau, &mixer);
        }
    }
    let mut summaries = Vec::with_capacity(decoded.len());
    for (j, (path, calm, d)) in decoded.iter().enumerate() {
        let Some(dt_j) = median_dt_s(&d.samples) else {
            bail!("`{}`: fewer than two samples", path.display());
        };
        if (dt_j - dt).abs() > dataset::DT_TOLERANCE * dt {
            bail!(
                "`{}`: sampled at {:.1} Hz, but `{}` at {sample_hz:.1} Hz; import logs of one rate \
                 into one dataset",
                path.display(),
                1.0 / dt_j,
                inputs[0].0.display()
            );
        }
        let flights = airborne_flights(&d.samples, args);
        if flights.is_empty() {
            bail!(
                "`{}`: no airborne samples (z ≥ {} m, and not at thrust < {} m g standing still \
                 for {} s; {} s trimmed at both ends)",
                path.display(),
                args.min_height_m,
                args.min_thrust_frac,
                args.min_ground_s,
                args.trim_s
            );
        }
        summaries.push(FileSummary {
            file: path.display().to_string(),
            samples_in: d.samples.len(),
            samples_kept: flights.iter().map(|f| f.samples.len()).sum(),
            flights: flights.len(),
            skipped_events: d.skipped_events,
            crc_ok: d.crc_ok,
            disturbance_free: *calm,
            repeated_states: cleaning.get(j).map_or(0, |c| c.0),
            rotor_glitches: cleaning.get(j).map_or(0, |c| c.1),
        });
        ds.realizations.push(Realization {
            meta: RealizationMeta {
                file: dataset::realization_file(j),
                source_file: Some(path.display().to_string()),
                wind_m_s2: None,
                rotor_efficiency: None,
                disturbance_free: *calm,
                flights: 0,
                samples: 0,
            },
            flights,
        });
    }
    dataset::save(&args.out, &ds)?;
    Ok(summaries)
}
