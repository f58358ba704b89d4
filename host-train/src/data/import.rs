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
//! vehicle of docs/vehicles.md it learned a J 5× too large). With `--motor-tau-s T` the importer
//! turns each logged command into the realized one the trainer integrates. The log has no motor
//! outputs, so the wrench is taken apart per rotor through the mixer inverse of `--vehicle`
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
use serde::Deserialize;

use crate::io::dataset::{self, Dataset, Flight, Realization, RealizationMeta, Sample};
use crate::io::usdlog::{
    self, ParseOptions, G0_M_S2, LEE_COMMAND_VARS, USD_ACC_VARS, USD_STATE_VARS,
};
use crate::sim::plant::{PlantState, VehicleParams};

/// Input format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    /// By content: a first byte 0xBC is a uSD log, anything else CSV.
    Auto,
    /// Bitcraze uSD-card deck binary log.
    Usd,
    /// The documented CSV.
    Csv,
}

/// Arguments of `host-train import`.
#[derive(Args, Clone, Debug)]
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
    #[arg(long, default_value_t = 0.10)]
    pub min_height_m: f64,
    /// Airborne only with a commanded thrust of at least this fraction of m g.
    #[arg(long, default_value_t = 0.25)]
    pub min_thrust_frac: f64,
    /// Seconds cut from both ends of every airborne stretch (take-off, landing).
    #[arg(long, default_value_t = 0.5)]
    pub trim_s: f64,
    /// Gaps in the log (dropped packets, removed repeated states) up to this long stay inside
    /// one flight; longer ones end it. Training never integrates across a gap either way.
    #[arg(long, default_value_t = 0.1)]
    pub max_gap_s: f64,
    /// Low thrust counts as landed only when the vehicle also stays still (speed under
    /// 0.1 m/s) this long: an aggressive descent at low thrust is still flight.
    #[arg(long, default_value_t = 0.3)]
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
            logs: Vec::new(),
            calm: Vec::new(),
            format: LogFormat::Auto,
            vehicle: None,
            mass_kg: Some(mass_kg),
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

/// Decodes a uSD log's fixed-frequency samples.
///
/// # Errors
/// The decoder's errors (with the byte offset), a missing `fixedFrequency` event type or
/// variable, a quaternion far from unit norm or a non-finite value (with the event's offset);
/// the error names `path`.
pub fn decode_usd(
    path: &Path,
    bytes: &[u8],
    command_vars: &[String],
    rotor_speed_vars: &[String],
    opts: ParseOptions,
) -> Result<Decoded> {
    let (log, rep) =
        usdlog::parse(bytes, opts).map_err(|e| anyhow::anyhow!("`{}`: {e}", path.display()))?;
    let Some(ff) = log.fixed_frequency() else {
        bail!(
            "`{}`: no `{}` event type in the header (log the variables of tools/usd/config.txt)",
            path.display(),
            usdlog::FIXED_FREQUENCY_NAME
        );
    };
    let et = &log.event_types[ff];
    let speeds = !rotor_speed_vars.is_empty();
    let input_vars = if speeds {
        if rotor_speed_vars.len() != 4 {
            bail!(
                "--rotor-speed-vars needs 4 names (rotors 1..4, rpm), got {}",
                rotor_speed_vars.len()
            );
        }
        rotor_speed_vars
    } else {
        if command_vars.len() != 4 {
            bail!(
                "--command-vars needs 4 names (thrust, torque x, y, z), got {}",
                command_vars.len()
            );
        }
        command_vars
    };
    let want: Vec<&str> = USD_STATE_VARS
        .iter()
        .copied()
        .chain(input_vars.iter().map(String::as_str))
        .collect();
    let missing: Vec<&str> = want
        .iter()
        .copied()
        .filter(|n| et.var_index(n).is_none())
        .collect();
    if !missing.is_empty() {
        bail!(
            "`{}`: the `{}` event lacks {} (it has: {})",
            path.display(),
            et.name,
            missing.join(", "),
            et.vars
                .iter()
                .map(|v| v.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let idx: Vec<usize> = want.iter().filter_map(|n| et.var_index(n)).collect();
    let acc_idx: Option<Vec<usize>> = USD_ACC_VARS.iter().map(|n| et.var_index(n)).collect();
    let mut out = Decoded {
        crc_ok: rep.crc_ok,
        rotor_rad_s: speeds.then(Vec::new),
        ..Decoded::default()
    };
    let rad_s_per_rpm = 1.0 / crate::sim::vehicle::RPM_PER_RAD_S;
    for ev in &log.events {
        if ev.type_index != ff {
            out.skipped_events += 1;
            continue;
        }
        let v = |k: usize| {
            idx.get(k)
                .and_then(|&i| ev.values.get(i))
                .copied()
                .unwrap_or(f64::NAN)
        };
        let deg = std::f64::consts::PI / 180.0;
        let bad = |what: &str| anyhow::anyhow!("`{}`: byte {}: {what}", path.display(), ev.offset);
        let state = state_from(
            [v(0), v(1), v(2)],
            [v(6), v(7), v(8), v(9)],
            [v(3), v(4), v(5)],
            [v(10) * deg, v(11) * deg, v(12) * deg],
        )
        .ok_or_else(|| {
            bad(&format!(
                "the attitude quaternion's norm is not 1 within {QUATERNION_NORM_TOLERANCE} (it is {:.4})",
                quat_norm([v(6), v(7), v(8), v(9)])
            ))
        })?;
        let input = [v(13), v(14), v(15), v(16)];
        let s = Sample {
            t_s: ev.timestamp_us as f64 * 1e-6,
            state,
            // With rotor speeds the wrench is computed once the speeds are cleaned.
            wrench: if speeds { [0.0; 4] } else { input },
            rpm: None,
            acc_body_m_s2: acc_idx.as_ref().map(|a| {
                std::array::from_fn(|k| {
                    a.get(k)
                        .and_then(|&i| ev.values.get(i))
                        .copied()
                        .unwrap_or(f64::NAN)
                        * G0_M_S2
                })
            }),
        };
        dataset::check_sample(&s).map_err(|e| bad(&e.to_string()))?;
        out.samples.push(s);
        if let Some(w) = out.rotor_rad_s.as_mut() {
            // Non-finite readings pass here: they are glitches, fixed with the others.
            w.push(input.map(|r| r * rad_s_per_rpm));
        }
    }
    Ok(out)
}

#[derive(Debug, Deserialize)]
struct CsvRow {
    t_s: f64,
    px_m: f64,
    py_m: f64,
    pz_m: f64,
    qw: f64,
    qx: f64,
    qy: f64,
    qz: f64,
    vx_world_m_s: f64,
    vy_world_m_s: f64,
    vz_world_m_s: f64,
    wx_rad_s: f64,
    wy_rad_s: f64,
    wz_rad_s: f64,
    #[serde(default)]
    f_n: Option<f64>,
    #[serde(default)]
    tau_x_nm: Option<f64>,
    #[serde(default)]
    tau_y_nm: Option<f64>,
    #[serde(default)]
    tau_z_nm: Option<f64>,
    #[serde(default)]
    ax_m_s2: Option<f64>,
    #[serde(default)]
    ay_m_s2: Option<f64>,
    #[serde(default)]
    az_m_s2: Option<f64>,
    #[serde(default)]
    w1_rad_s: Option<f64>,
    #[serde(default)]
    w2_rad_s: Option<f64>,
    #[serde(default)]
    w3_rad_s: Option<f64>,
    #[serde(default)]
    w4_rad_s: Option<f64>,
    #[serde(default)]
    erpm1: Option<f64>,
    #[serde(default)]
    erpm2: Option<f64>,
    #[serde(default)]
    erpm3: Option<f64>,
    #[serde(default)]
    erpm4: Option<f64>,
}

/// Decodes the documented CSV (see the module docs). `motor_poles` converts `erpm1..erpm4`.
///
/// # Errors
/// Unreadable text, a missing column, a malformed or non-finite number, a quaternion whose norm
/// is not 1 within [`QUATERNION_NORM_TOLERANCE`], a command or rotor speeds given in part,
/// rotor speeds and a wrench in one file, eRPM without `motor_poles`; the error names `path`
/// and the line.
pub fn decode_csv(path: &Path, bytes: &[u8], motor_poles: Option<u32>) -> Result<Decoded> {
    let mut rd = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(bytes);
    let mut out = Decoded {
        crc_ok: true,
        ..Decoded::default()
    };
    let mut held: Option<[f64; 4]> = None;
    let mut speeds: Vec<[f64; 4]> = Vec::new();
    let mut held_speed: Option<[f64; 4]> = None;
    for (i, rec) in rd.deserialize::<CsvRow>().enumerate() {
        let r = match rec {
            Ok(r) => r,
            Err(e) => {
                let line = e.position().map_or(i as u64 + 2, |p| p.line());
                bail!("`{}` line {line}: {e}", path.display());
            }
        };
        let ln = i + 2;
        let bad = |what: &str| anyhow::anyhow!("`{}` line {ln}: {what}", path.display());
        match (r.f_n, r.tau_x_nm, r.tau_y_nm, r.tau_z_nm) {
            (Some(f), Some(x), Some(y), Some(z)) => held = Some([f, x, y, z]),
            (None, None, None, None) => {}
            _ => return Err(bad("give all of f_n, tau_x_nm, tau_y_nm, tau_z_nm or none")),
        }
        let rad = match (r.w1_rad_s, r.w2_rad_s, r.w3_rad_s, r.w4_rad_s) {
            (Some(a), Some(b), Some(c), Some(d)) => Some([a, b, c, d]),
            (None, None, None, None) => None,
            _ => return Err(bad("give all of w1_rad_s..w4_rad_s or none")),
        };
        let erpm = match (r.erpm1, r.erpm2, r.erpm3, r.erpm4) {
            (Some(a), Some(b), Some(c), Some(d)) => Some([a, b, c, d]),
            (None, None, None, None) => None,
            _ => return Err(bad("give all of erpm1..erpm4 or none")),
        };
        let speed = match (rad, erpm) {
            (Some(_), Some(_)) => {
                return Err(bad("give rotor speeds as w*_rad_s or erpm*, not both"))
            }
            (Some(w), None) => Some(w),
            (None, Some(e)) => {
                let Some(poles) = motor_poles.filter(|p| *p >= 2 && p % 2 == 0) else {
                    return Err(bad(
                        "erpm1..erpm4 need the motors' pole count: --motor-poles N (even, ≥ 2)",
                    ));
                };
                let pairs = f64::from(poles / 2);
                Some(e.map(|x| x / pairs / crate::sim::vehicle::RPM_PER_RAD_S))
            }
            (None, None) => None,
        };
        if speed.is_some() {
            held_speed = speed;
        }
        if held.is_some() && held_speed.is_some() {
            return Err(bad(
                "the file gives both a wrench (f_n, tau_*) and rotor speeds: give one input",
            ));
        }
        let wrench = match (held, held_speed) {
            (Some(w), None) => w,
            // Computed from the speeds once they are cleaned (fix_rotor_glitches).
            (None, Some(_)) => [0.0; 4],
            _ => continue,
        };
        let acc = match (r.ax_m_s2, r.ay_m_s2, r.az_m_s2) {
            (Some(x), Some(y), Some(z)) => Some([x, y, z]),
            (None, None, None) => None,
            _ => return Err(bad("give all of ax_m_s2, ay_m_s2, az_m_s2 or none")),
        };
        let state = state_from(
            [r.px_m, r.py_m, r.pz_m],
            [r.qx, r.qy, r.qz, r.qw],
            [r.vx_world_m_s, r.vy_world_m_s, r.vz_world_m_s],
            [r.wx_rad_s, r.wy_rad_s, r.wz_rad_s],
        )
        .ok_or_else(|| {
            bad(&format!(
                "the attitude quaternion (qw, qx, qy, qz) has norm {:.4}, not 1 within {QUATERNION_NORM_TOLERANCE}",
                quat_norm([r.qx, r.qy, r.qz, r.qw])
            ))
        })?;
        let s = Sample {
            t_s: r.t_s,
            state,
            wrench,
            rpm: None,
            acc_body_m_s2: acc,
        };
        dataset::check_sample(&s).map_err(|e| bad(&e.to_string()))?;
        out.samples.push(s);
        if let Some(w) = held_speed {
            speeds.push(w);
        }
    }
    if held_speed.is_some() {
        out.rotor_rad_s = Some(speeds);
    }
    Ok(out)
}

/// Replaces rotor-speed glitches by linear interpolation in time between the nearest good
/// readings of that rotor, and returns how many readings were replaced. A reading is a glitch
/// when it is not finite, negative, above 1.5× the top speed `max_rad_s`, or a one-sample spike
/// (it differs from both neighbours by more than half the top speed while they agree within a
/// quarter of it).
///
/// # Errors
/// A rotor with no good reading at all.
pub fn fix_rotor_glitches(t_s: &[f64], speeds: &mut [[f64; 4]], max_rad_s: f64) -> Result<usize> {
    let n = speeds.len().min(t_s.len());
    let mut fixed = 0;
    for r in 0..4 {
        let x: Vec<f64> = speeds.iter().take(n).map(|w| w[r]).collect();
        let bad: Vec<bool> = (0..n)
            .map(|k| {
                let v = x[k];
                if !(v.is_finite() && v >= 0.0 && v <= 1.5 * max_rad_s) {
                    return true;
                }
                match (k.checked_sub(1).map(|j| x[j]), x.get(k + 1).copied()) {
                    (Some(a), Some(b)) if a.is_finite() && b.is_finite() => {
                        (v - a).abs() > 0.5 * max_rad_s
                            && (v - b).abs() > 0.5 * max_rad_s
                            && (a - b).abs() < 0.25 * max_rad_s
                    }
                    _ => false,
                }
            })
            .collect();
        let good: Vec<usize> = (0..n).filter(|&k| !bad[k]).collect();
        if good.is_empty() && n > 0 {
            bail!("rotor {}: no valid speed reading in the whole log", r + 1);
        }
        let mut g = 0; // index into `good` of the first good reading at or after k
        for k in 0..n {
            while g < good.len() && good[g] < k {
                g += 1;
            }
            if !bad[k] {
                continue;
            }
            let after = good.get(g).copied();
            let before = g.checked_sub(1).and_then(|i| good.get(i)).copied();
            let v = match (before, after) {
                (Some(a), Some(b)) => {
                    let span = t_s[b] - t_s[a];
                    let f = if span > 0.0 {
                        (t_s[k] - t_s[a]) / span
                    } else {
                        0.5
                    };
                    x[a] + f * (x[b] - x[a])
                }
                (Some(a), None) => x[a],
                (None, Some(b)) => x[b],
                (None, None) => continue,
            };
            speeds[k][r] = v;
            fixed += 1;
        }
    }
    Ok(fixed)
}

/// Speed (m/s) or rate (rad/s) above which an exactly repeated state is a filled-in packet,
/// not a vehicle at rest.
const MOVING: f64 = 1e-3;

/// Drops every sample whose state (position, attitude, velocity, rate) repeats the previous
/// sample's exactly although its velocity or rate says it moved: a logger that resamples to a
/// fixed rate fills a dropped packet with the last state, and training on it would learn that
/// the vehicle stopped. (A vehicle at rest repeats its state legitimately.) Keeps the parallel
/// rotor speeds in step. Returns how many were dropped.
pub fn drop_repeated_states(d: &mut Decoded) -> usize {
    let n = d.samples.len();
    let keep: Vec<bool> = (0..n)
        .map(|k| {
            let s = &d.samples[k].state;
            let moving = s.v_body_m_s.norm() > MOVING || s.w_body_rad_s.norm() > MOVING;
            k == 0 || !moving || *s != d.samples[k - 1].state
        })
        .collect();
    let mut it = keep.iter();
    d.samples.retain(|_| *it.next().unwrap_or(&true));
    if let Some(w) = d.rotor_rad_s.as_mut() {
        let mut it = keep.iter();
        w.retain(|_| *it.next().unwrap_or(&true));
    }
    keep.iter().filter(|k| !**k).count()
}

/// The median sample interval (s) of `samples` over increasing steps.
pub fn median_dt_s(samples: &[Sample]) -> Option<f64> {
    let mut d: Vec<f64> = samples
        .windows(2)
        .map(|w| w[1].t_s - w[0].t_s)
        .filter(|d| *d > 0.0)
        .collect();
    if d.is_empty() {
        return None;
    }
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied()
}

/// Replaces each sample's commanded wrench by the realized one under a first-order motor lag of
/// `tau_s` (module docs, "Motor dynamics"), stretch by stretch ([`dataset::segments`] at
/// `sample_hz`); `params` gives the mixer (the CF2X's rotor geometry and coefficients).
pub fn realize_commands(
    samples: &mut [Sample],
    sample_hz: f64,
    tau_s: f64,
    params: &VehicleParams,
) {
    if tau_s.is_nan() || tau_s <= 0.0 {
        return;
    }
    let nominal_dt = 1.0 / sample_hz;
    for seg in dataset::segments(samples, sample_hz) {
        let seg = &mut samples[seg];
        let cmd_of = |s: &Sample| {
            params
                .wrench_to_rpm_squared(s.wrench)
                .map(|q| q.max(0.0).sqrt())
        };
        let Some(first) = seg.first() else { continue };
        let mut rotor = cmd_of(first);
        for k in 0..seg.len() {
            let dt = seg
                .get(k + 1)
                .map_or(nominal_dt, |n| n.t_s - seg[k].t_s)
                .max(0.0);
            let c = cmd_of(&seg[k]);
            let e1 = (-dt / tau_s).exp();
            // Mean over the step of ω(t)² with ω(t) = c + (ω₀ − c) e^{−t/T}.
            let (m1, m2) = if dt > 0.0 {
                (
                    tau_s / dt * (1.0 - e1),
                    tau_s / (2.0 * dt) * (1.0 - e1 * e1),
                )
            } else {
                (1.0, 1.0)
            };
            let mean_sq: [f64; 4] = std::array::from_fn(|i| {
                let d = rotor[i] - c[i];
                c[i] * c[i] + 2.0 * c[i] * d * m1 + d * d * m2
            });
            seg[k].wrench = params.wrench_of_rpm_squared(mean_sq);
            rotor = std::array::from_fn(|i| c[i] + (rotor[i] - c[i]) * e1);
        }
    }
}

/// Index ranges of `samples` split where time does not increase or jumps by more than
/// `max_gap_s`: shorter gaps (dropped packets) stay inside one range.
pub fn stretches(samples: &[Sample], max_gap_s: f64) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for k in 1..samples.len() {
        let step = samples[k].t_s - samples[k - 1].t_s;
        if !(step > 0.0 && step <= max_gap_s) {
            out.push(start..k);
            start = k;
        }
    }
    if start < samples.len() {
        out.push(start..samples.len());
    }
    out
}

/// Speed under which a low-thrust vehicle counts as standing (m/s).
const STANDING_SPEED_M_S: f64 = 0.1;

/// Per sample of `seg`: on the ground by the documented rule (module docs): below the minimum
/// height, or at low thrust while standing still for at least `min_ground_s`.
fn grounded(seg: &[Sample], weight_n: f64, args: &ImportArgs) -> Vec<bool> {
    let low_still: Vec<bool> = seg
        .iter()
        .map(|s| {
            s.wrench[0] < args.min_thrust_frac * weight_n
                && s.state.v_body_m_s.norm() < STANDING_SPEED_M_S
        })
        .collect();
    let mut out: Vec<bool> = seg
        .iter()
        .map(|s| s.state.p_m.z < args.min_height_m)
        .collect();
    let mut k = 0;
    while k < seg.len() {
        if !low_still[k] {
            k += 1;
            continue;
        }
        let start = k;
        while k < seg.len() && low_still[k] {
            k += 1;
        }
        if seg[k - 1].t_s - seg[start].t_s >= args.min_ground_s {
            out[start..k].iter_mut().for_each(|g| *g = true);
        }
    }
    out
}

/// The airborne flights of `samples` by the documented rule (module docs). Gaps up to
/// `--max-gap-s` stay inside a flight (training's windows never span one).
pub fn airborne_flights(samples: &[Sample], args: &ImportArgs) -> Vec<Flight> {
    let weight = args.mass_kg.unwrap_or(f64::NAN) * args.gravity_m_s2.unwrap_or(9.8);
    let mut flights = Vec::new();
    for seg in stretches(samples, args.max_gap_s) {
        let seg = &samples[seg];
        let ground = grounded(seg, weight, args);
        let mut k = 0;
        while k < seg.len() {
            if ground[k] {
                k += 1;
                continue;
            }
            let start = k;
            while k < seg.len() && !ground[k] {
                k += 1;
            }
            let stretch = &seg[start..k];
            let (t0, t1) = (
                stretch[0].t_s + args.trim_s,
                stretch[stretch.len() - 1].t_s - args.trim_s,
            );
            let kept: Vec<Sample> = stretch
                .iter()
                .filter(|s| s.t_s >= t0 - 1e-9 && s.t_s <= t1 + 1e-9)
                .copied()
                .collect();
            if kept.len() >= 2 {
                flights.push(Flight { samples: kept });
            }
        }
    }
    flights
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
