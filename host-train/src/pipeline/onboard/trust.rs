//! Which logged wrench columns can be trusted: each against what the logged motor commands
//! imply through the power distribution's inverse (collective, roll, pitch, yaw).

use super::replay::active;
use crate::io::LoopFlight;
use serde::Serialize;

/// The logged wrench columns, each with the command axis it should follow.
pub const WRENCH_COLUMNS: [(&str, usize); 4] = [
    ("log_thrust", 0),
    ("log_torque_roll", 1),
    ("log_torque_pitch", 2),
    ("log_torque_yaw", 3),
];

/// One column's verdict.
#[derive(Clone, Debug, Serialize)]
pub struct ColumnTrust {
    /// The column.
    pub column: String,
    /// The command axis it is compared with.
    pub axis: String,
    /// Flown rows compared.
    pub rows: usize,
    /// Pearson correlation with the axis.
    pub corr: f64,
    /// Fraction of rows equal to `log_thrust` (a copy).
    pub copy_of_thrust: f64,
    /// The largest |value|, and the fraction of rows within 0.1 % of it (saturation).
    pub max_abs: f64,
    /// Fraction of rows at ±`max_abs`.
    pub at_max: f64,
    /// Fraction of flown rows exactly zero.
    pub zero: f64,
    /// Trusted or not, and why.
    pub verdict: String,
}

const AXES: [&str; 4] = ["collective", "roll", "pitch", "yaw"];

/// The table over the flights that carry the columns (one row per column, all flights pooled;
/// `per_flight` adds one row per column and flight).
pub fn trust_table(flights: &[LoopFlight], per_flight: bool) -> Vec<ColumnTrust> {
    let mut out = Vec::new();
    for (col, axis) in WRENCH_COLUMNS {
        out.push(column(flights, col, axis, "all"));
        if per_flight {
            for f in flights {
                out.push(column(std::slice::from_ref(f), col, axis, &f.name));
            }
        }
    }
    out
}

fn column(flights: &[LoopFlight], col: &str, axis: usize, label: &str) -> ColumnTrust {
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    let mut copies = 0usize;
    for f in flights {
        let (Some(x), Some(th)) = (f.extra.get(col), f.extra.get("log_thrust")) else {
            continue;
        };
        for k in 0..f.len() {
            if !active(f, k) || !x[k].is_finite() {
                continue;
            }
            xs.push(x[k]);
            ys.push(f.cmd[k].axes()[axis]);
            if x[k] == th[k] {
                copies += 1;
            }
        }
    }
    let n = xs.len();
    let nf = n.max(1) as f64;
    let mx = xs.iter().sum::<f64>() / nf;
    let my = ys.iter().sum::<f64>() / nf;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (x, y) in xs.iter().zip(&ys) {
        sxy += (x - mx) * (y - my);
        sxx += (x - mx) * (x - mx);
        syy += (y - my) * (y - my);
    }
    let corr = sxy / (sxx * syy).sqrt();
    let max_abs = xs.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    let at_max = xs
        .iter()
        .filter(|x| max_abs > 0.0 && (x.abs() - max_abs).abs() <= 1e-3 * max_abs)
        .count() as f64
        / nf;
    let zero = xs.iter().filter(|&&x| x == 0.0).count() as f64 / nf;
    let copy = copies as f64 / nf;
    let verdict = if n == 0 {
        "absent".to_string()
    } else if col != "log_thrust" && copy > 0.95 {
        format!(
            "NOT trusted: a copy of thrust on {:.0} % of rows",
            100.0 * copy
        )
    } else if !corr.is_finite() || corr.abs() < 0.9 {
        format!(
            "NOT trusted: correlation {corr:.2} with the commands' {}",
            AXES[axis]
        )
    } else if at_max > 0.01 {
        format!(
            "partly: saturates at ±{max_abs:.3} on {:.1} % of rows (corr {corr:.2})",
            100.0 * at_max
        )
    } else {
        format!(
            "trusted: correlation {corr:.3} with the commands' {}",
            AXES[axis]
        )
    };
    ColumnTrust {
        column: format!("{col} ({label})"),
        axis: AXES[axis].to_string(),
        rows: n,
        corr,
        copy_of_thrust: copy,
        max_abs,
        at_max,
        zero,
        verdict,
    }
}
