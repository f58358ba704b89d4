//! Cleaning decoded samples: rotor-speed glitches, repeated states, the sample period, the
//! commands realized through the motor lag, continuous stretches and the airborne flights.

use anyhow::{bail, Result};

use super::{Decoded, ImportArgs};
use crate::io::dataset::{self, Flight, Sample};
use crate::sim::plant::VehicleParams;

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
