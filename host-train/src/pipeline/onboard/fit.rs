//! Identifying the few onboard parameters the firmware defaults may not match: Levenberg–
//! Marquardt on the replayed axes (collective, roll, pitch, yaw) of the training flights, the
//! Jacobian by finite differences of whole replays, and a grid over the command delay.

use super::replay::{active, replay, smooth, ReplayOptions};
use crate::control::onboard::OnboardConfig;
use crate::io::LoopFlight;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// The identified parameters, in order.
pub const FIT_PARAMS: [&str; 9] = [
    "mass_thrust",
    "kr_xy",
    "kw_xy",
    "kd_omega_rp",
    "roll_trim",
    "pitch_trim",
    "kr_z",
    "kw_z",
    "yaw_trim",
];

/// Trims are fitted in units of 1000 counts, gains as log-scale factors.
fn apply(base: &OnboardConfig, th: &[f64]) -> OnboardConfig {
    let mut c = *base;
    let e = |i: usize| th.get(i).copied().unwrap_or(0.0);
    c.mass_thrust = base.mass_thrust * e(0).exp();
    c.gains.kr_xy = base.gains.kr_xy * e(1).exp();
    c.gains.kw_xy = base.gains.kw_xy * e(2).exp();
    c.gains.kd_omega_rp = base.gains.kd_omega_rp * e(3).exp();
    c.roll_trim = base.roll_trim + 1000.0 * e(4);
    c.pitch_trim = base.pitch_trim + 1000.0 * e(5);
    c.gains.kr_z = base.gains.kr_z * e(6).exp();
    c.gains.kw_z = base.gains.kw_z * e(7).exp();
    c.yaw_trim = base.yaw_trim + 1000.0 * e(8);
    c
}

/// Rows the fit uses: flown, and no logged motor at the idle floor or at full command (the
/// distribution's inverse holds there).
fn fit_rows(f: &LoopFlight, idle: f64) -> Vec<usize> {
    (0..f.len())
        .filter(|&k| active(f, k) && f.cmd[k].0.iter().all(|&m| m > idle + 2e-3 && m < 0.998))
        .collect()
}

struct Problem<'a> {
    flights: &'a [LoopFlight],
    rows: Vec<Vec<usize>>,
    scale: [f64; 4],
    opt: ReplayOptions,
}

impl Problem<'_> {
    fn residuals(&self, cfg: &OnboardConfig) -> DVector<f64> {
        let mut r = Vec::new();
        for (f, rows) in self.flights.iter().zip(&self.rows) {
            let pred = smooth(f, &replay(f, cfg, &self.opt), self.opt.smooth_rows);
            let log = smooth(f, &f.cmd, self.opt.smooth_rows);
            for &k in rows {
                let (a, b) = (log[k].axes(), pred[k].axes());
                for i in 0..4 {
                    r.push((b[i] - a[i]) / self.scale[i]);
                }
            }
        }
        DVector::from_vec(r)
    }
}

/// What the fit found.
#[derive(Clone, Debug, Serialize)]
pub struct FitResult {
    /// The identified configuration.
    #[serde(skip)]
    pub config: OnboardConfig,
    /// The parameter names and their identified values.
    pub params: Vec<(String, f64)>,
    /// The command delay the grid picked, s.
    pub cmd_delay_s: f64,
    /// Cost (mean squared normalized residual) before and after.
    pub cost_start: f64,
    /// Cost after the fit.
    pub cost_end: f64,
    /// Rows used.
    pub rows: usize,
    /// Iterations run.
    pub iterations: usize,
}

/// Levenberg–Marquardt from `base` (parameters zero); the parameters, residuals, iterations.
fn levenberg_marquardt(p: &Problem, base: &OnboardConfig) -> (DVector<f64>, DVector<f64>, usize) {
    let np = FIT_PARAMS.len();
    let mut th = DVector::<f64>::zeros(np);
    let mut r = p.residuals(&apply(base, th.as_slice()));
    let mut lambda = 1e-3;
    let mut iterations = 0;
    for _ in 0..12 {
        iterations += 1;
        let h = 1e-3;
        let mut jac = DMatrix::<f64>::zeros(r.len(), np);
        for i in 0..np {
            let mut t = th.clone();
            t[i] += h;
            let ri = p.residuals(&apply(base, t.as_slice()));
            jac.set_column(i, &((ri - &r) / h));
        }
        let jtj = jac.transpose() * &jac;
        let g = jac.transpose() * &r;
        let mut improved = false;
        for _ in 0..6 {
            let mut a = jtj.clone();
            for i in 0..np {
                a[(i, i)] += lambda * (jtj[(i, i)] + 1e-9);
            }
            let Some(step) = a.lu().solve(&(-&g)) else {
                lambda *= 10.0;
                continue;
            };
            let t = &th + step;
            let rt = p.residuals(&apply(base, t.as_slice()));
            if rt.norm_squared() < r.norm_squared() {
                let gain = r.norm_squared() - rt.norm_squared();
                th = t;
                r = rt;
                lambda = (lambda / 3.0).max(1e-7);
                improved = gain > 1e-6 * r.norm_squared();
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    (th, r, iterations)
}

/// Fits [`FIT_PARAMS`] and the delay on `flights` (the training flights) from `start`.
pub fn fit(flights: &[LoopFlight], start: &OnboardConfig, opt: &ReplayOptions) -> FitResult {
    let rows: Vec<Vec<usize>> = flights
        .iter()
        .map(|f| fit_rows(f, start.idle_cmd))
        .collect();
    // Scales: the axes' standard deviations over the fit rows.
    let mut scale = [0.0f64; 4];
    let mut mean = [0.0f64; 4];
    let mut n = 0.0f64;
    for (f, rs) in flights.iter().zip(&rows) {
        for &k in rs {
            let a = f.cmd[k].axes();
            for i in 0..4 {
                mean[i] += a[i];
                scale[i] += a[i] * a[i];
            }
            n += 1.0;
        }
    }
    for i in 0..4 {
        let m = mean[i] / n.max(1.0);
        scale[i] = (scale[i] / n.max(1.0) - m * m).max(1e-12).sqrt();
    }
    let nrows = rows.iter().map(Vec::len).sum();
    let p = Problem {
        flights,
        rows,
        scale,
        opt: *opt,
    };
    let cost = |c: &OnboardConfig| {
        let r = p.residuals(c);
        r.norm_squared() / r.len().max(1) as f64
    };

    let cost_start = cost(start);
    // The finite differences need a smooth replay: the fit runs without the firmware's integer
    // truncations (at most a count each), the result keeps the caller's setting.
    let mut base = *start;
    base.integer_outputs = false;
    // The delay: a grid of whole rows, the gains fitted at each.
    let mut best: Option<(f64, DVector<f64>, DVector<f64>, usize)> = None;
    for d in 0..=3 {
        base.cmd_delay_s = d as f64 * 0.01;
        let (th, r, it) = levenberg_marquardt(&p, &base);
        if best
            .as_ref()
            .is_none_or(|b| r.norm_squared() < b.2.norm_squared())
        {
            best = Some((base.cmd_delay_s, th, r, it));
        }
    }
    let (delay, th, r, iterations) =
        best.unwrap_or_else(|| (0.0, DVector::zeros(FIT_PARAMS.len()), DVector::zeros(0), 0));
    base.cmd_delay_s = delay;
    let mut config = apply(&base, th.as_slice());
    config.integer_outputs = start.integer_outputs;
    let values = [
        config.mass_thrust,
        config.gains.kr_xy,
        config.gains.kw_xy,
        config.gains.kd_omega_rp,
        config.roll_trim,
        config.pitch_trim,
        config.gains.kr_z,
        config.gains.kw_z,
        config.yaw_trim,
    ];
    FitResult {
        config,
        params: FIT_PARAMS
            .iter()
            .zip(values)
            .map(|(n, v)| (n.to_string(), v))
            .collect(),
        cmd_delay_s: config.cmd_delay_s,
        cost_start,
        cost_end: r.norm_squared() / r.len().max(1) as f64,
        rows: nrows,
        iterations,
    }
}
