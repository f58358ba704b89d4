//! Decoding a Bitcraze uSD-card deck log into samples.

use std::path::Path;

use anyhow::{bail, Result};

use super::{quat_norm, state_from, Decoded, QUATERNION_NORM_TOLERANCE};
use crate::io::dataset::{self, Sample};
use crate::io::usdlog::{self, ParseOptions, G0_M_S2, USD_ACC_VARS, USD_STATE_VARS};

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
