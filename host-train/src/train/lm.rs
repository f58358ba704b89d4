//! Levenberg–Marquardt on multi-step rollouts, the engine of `fit-response` ([`super::response`])
//! and `fit-port` ([`super::port_fit`]): residuals at a few horizons of every window, the
//! benchmark's mean-error-norm metric by IRLS, a forward-difference Jacobian on threads.

use hamflight::lie;
use hamflight::model::State;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use super::data::Windows;

/// One fit iteration, for progress and the report.
#[derive(Clone, Debug, Serialize)]
pub struct FitStep {
    /// Iteration (0: the start).
    pub iteration: usize,
    /// The mean squared scaled residual.
    pub cost: f64,
    /// LM's damping λ after the iteration.
    pub lambda: f64,
}

/// The horizons (steps) whose errors the fit's residuals hold, for windows of `n` steps.
fn residual_steps(n: usize) -> Vec<usize> {
    let mut s: Vec<usize> = [1, 2, 5, 10, 20, 30, 40, 50]
        .into_iter()
        .filter(|&k| k <= n)
        .collect();
    if s.last() != Some(&n) && n > 0 {
        s.push(n);
    }
    s
}

/// A rollout of a parameter vector: from the first state under the logged wrenches (one per
/// step of the given dt), calling `visit(k, state)` after step k.
pub(crate) trait Roll: Sync {
    /// Rolls the model of `p` out ([`rollout`]'s contract).
    fn roll(
        &self,
        p: &[f64],
        s0: &State,
        u: &[[f32; 4]],
        dt_s: f32,
        visit: &mut dyn FnMut(usize, &State),
    );
}

/// The scaled residuals of `p` over windows `ids`: for every window and every step of
/// [`residual_steps`], 12 numbers (position, world velocity, attitude log, rates). A diverged
/// rollout gives non-finite residuals.
fn residuals(
    roll: &dyn Roll,
    p: &[f64],
    data: &Windows,
    ids: &[usize],
    scales: &[f64; 4],
) -> Vec<f64> {
    let dt = 1.0 / data.sample_hz;
    let n = data.window_len.saturating_sub(1);
    let steps = residual_steps(n);
    let mut out = Vec::with_capacity(ids.len() * steps.len() * 12);
    for w in ids.iter().filter_map(|&i| data.windows.get(i)) {
        let Some(s0) = w.states.first() else { continue };
        let u = w.u.get(..n).unwrap_or(&w.u);
        let mut at = vec![None; n];
        roll.roll(p, s0, u, dt, &mut |k, s| {
            if let Some(slot) = at.get_mut(k) {
                *slot = Some(*s);
            }
        });
        for &k in &steps {
            let (Some(Some(pred)), Some(truth)) = (at.get(k - 1), w.states.get(k)) else {
                out.extend([f64::NAN; 12]);
                continue;
            };
            let dp = pred.p_m - truth.p_m;
            let dv = pred.rot * pred.v_body_m_s - truth.rot * truth.v_body_m_s;
            let da = lie::log(&(truth.rot.transpose() * pred.rot));
            let dw = pred.w_body_rad_s - truth.w_body_rad_s;
            for (v, s) in [
                (dp, scales[0]),
                (dv, scales[1]),
                (da, scales[2]),
                (dw, scales[3]),
            ] {
                out.extend(v.iter().map(|&x| f64::from(x) / s));
            }
        }
    }
    out
}

/// δ of the pseudo-Huber cost √(‖r‖² + δ²) − δ (scaled units): quadratic below, the norm above.
const ROBUST_DELTA: f64 = 0.05;

/// The fit's objective: the mean over residual triples of the pseudo-Huber √(‖r‖² + δ²) − δ,
/// the benchmark's metric (mean error norm, in scaled units) for errors above δ and smooth
/// below. Infinite if a rollout diverged.
fn cost(r: &[f64]) -> f64 {
    if !r.iter().all(|v| v.is_finite()) {
        return f64::INFINITY;
    }
    let groups = r.chunks(3);
    let n = groups.len().max(1) as f64;
    groups
        .map(|g| {
            (g.iter().map(|v| v * v).sum::<f64>() + ROBUST_DELTA.powi(2)).sqrt() - ROBUST_DELTA
        })
        .sum::<f64>()
        / n
}

/// The IRLS row weights (‖r_g‖² + δ²)^(−1/4) of each residual triple: the weighted least
/// squares' gradient is [`cost`]'s at the current point.
fn irls_weights(r: &[f64]) -> Vec<f64> {
    r.chunks(3)
        .flat_map(|g| {
            let n2 = g.iter().map(|v| v * v).sum::<f64>();
            let w = (n2 + ROBUST_DELTA.powi(2)).powf(-0.25);
            std::iter::repeat_n(w, g.len())
        })
        .collect()
}

/// What [`lm_fit`] fits: a rollout of a parameter vector and the windows it is scored on.
pub(crate) struct Problem<'a> {
    /// The parametrized rollout.
    pub roll: &'a dyn Roll,
    /// The dataset.
    pub data: &'a Windows,
    /// The windows fitted on.
    pub ids: &'a [usize],
    /// The error scales (m, m/s, rad, rad/s) of the residuals.
    pub scales: [f64; 4],
    /// Threads for the Jacobian.
    pub threads: usize,
    /// Priors on single parameters: (index, target, weight). Each adds one residual triple
    /// whose share of [`cost`] is weight · |p[index] − target| (for deviations well above the
    /// robust δ), whatever the number of windows.
    pub priors: &'a [Prior],
}

/// A prior on one parameter of a fit ([`Problem::priors`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Prior {
    /// The parameter's index.
    pub index: usize,
    /// The value the prior pulls toward.
    pub target: f64,
    /// The cost of a unit deviation, in the fit's cost units (the mean scaled error norm).
    pub weight: f64,
}

impl Problem<'_> {
    fn residuals(&self, p: &[f64]) -> Vec<f64> {
        let mut r = residuals(self.roll, p, self.data, self.ids, &self.scales);
        // The data's triples; each prior triple is scaled by their number so that its share
        // of the mean is its weight times the deviation.
        let n = (r.len() / 3) as f64;
        for prior in self.priors {
            let x = p.get(prior.index).copied().unwrap_or(prior.target);
            r.extend([prior.weight * n * (x - prior.target), 0.0, 0.0]);
        }
        r
    }
}

/// Levenberg–Marquardt with IRLS on [`cost`] from `p`, the parameters where `fixed` is true
/// held, `project` applied to every trial point (bounds). Returns the best point found and the
/// iterations.
pub(crate) fn lm_fit(
    problem: &Problem<'_>,
    mut p: Vec<f64>,
    fixed: &[bool],
    project: &dyn Fn(&mut [f64]),
    iterations: usize,
    mut progress: impl FnMut(&FitStep),
) -> (Vec<f64>, Vec<FitStep>) {
    let n_params = p.len();
    let mut r = problem.residuals(&p);
    let mut c = cost(&r);
    let mut lambda = 1e-2;
    let mut steps = vec![FitStep {
        iteration: 0,
        cost: c,
        lambda,
    }];
    progress(&steps[0]);
    if !c.is_finite() || r.is_empty() {
        return (p, steps);
    }
    for iteration in 1..=iterations {
        let mut jac = jacobian(problem, &p, &r, fixed);
        let w = irls_weights(&r);
        for (mut row, wi) in jac.row_iter_mut().zip(&w) {
            row *= *wi;
        }
        let rw: Vec<f64> = r.iter().zip(&w).map(|(a, b)| a * b).collect();
        let jt_j = jac.transpose() * &jac;
        let jt_r = jac.transpose() * DVector::from_column_slice(&rw);
        let mut improved = false;
        let mut converged = false;
        for _ in 0..8 {
            let mut a = jt_j.clone();
            for i in 0..n_params {
                a[(i, i)] += lambda * (jt_j[(i, i)] + 1e-9);
            }
            let Some(delta) = a.cholesky().map(|ch| ch.solve(&(-&jt_r))) else {
                lambda *= 10.0;
                continue;
            };
            let mut q = p.clone();
            for (qi, d) in q.iter_mut().zip(delta.iter()) {
                *qi += d;
            }
            project(&mut q);
            let rq = problem.residuals(&q);
            let cq = cost(&rq);
            if cq < c {
                let gain = (c - cq) / c;
                (p, r, c) = (q, rq, cq);
                converged = gain < 1e-4;
                lambda = (lambda / 3.0).max(1e-7);
                improved = true;
                break;
            }
            lambda *= 4.0;
        }
        let step = FitStep {
            iteration,
            cost: c,
            lambda,
        };
        progress(&step);
        steps.push(step);
        if !improved || converged {
            break;
        }
    }
    (p, steps)
}

/// The forward-difference Jacobian of the residuals at `p` (with `r` their value there), its
/// columns split over the problem's threads; columns of `fixed` parameters are zero.
fn jacobian(problem: &Problem<'_>, p: &[f64], r: &[f64], fixed: &[bool]) -> DMatrix<f64> {
    let n_params = p.len();
    let column = |i: usize| -> Vec<f64> {
        if fixed.get(i).copied().unwrap_or(false) {
            return vec![0.0; r.len()];
        }
        let h = 1e-3 * p[i].abs().max(1.0);
        let mut q = p.to_vec();
        q[i] += h;
        problem
            .residuals(&q)
            .iter()
            .zip(r)
            .map(|(a, b)| {
                let d = (a - b) / h;
                if d.is_finite() {
                    d
                } else {
                    0.0
                }
            })
            .collect()
    };
    let threads = problem.threads.clamp(1, n_params.max(1));
    let cols: Vec<(usize, Vec<f64>)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let column = &column;
                s.spawn(move || {
                    (t..n_params)
                        .step_by(threads)
                        .map(|i| (i, column(i)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_default())
            .collect()
    });
    let mut jac = DMatrix::zeros(r.len(), n_params);
    for (i, col) in cols {
        for (row, v) in col.into_iter().enumerate() {
            jac[(row, i)] = v;
        }
    }
    jac
}
