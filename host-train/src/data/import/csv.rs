//! Decoding a CSV log (docs/formats.md) into samples.

use std::path::Path;

use anyhow::{bail, Result};
use serde::Deserialize;

use super::{quat_norm, state_from, Decoded, QUATERNION_NORM_TOLERANCE};
use crate::io::dataset::{self, Sample};

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
