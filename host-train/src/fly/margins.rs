//! Stability margins measured in SITL: the loop is broken at one point, a sine is injected
//! there, and the loop's return ratio L(jω) = −(returned signal) / (signal at the break) is read
//! off the flight at the injection frequency (one flight per frequency, the response correlated
//! with sin and cos over whole periods after a settling time).
//!
//! - **Attitude loop** (`--loop roll` / `pitch`): broken at the plant input. The controller's
//!   roll (pitch) torque c is returned; the plant gets u = c + d. L = −C / U.
//! - **Position loop** (`--loop x` / `y`): broken at the position measurement. The controller is
//!   given x_meas + d; L = −X / (X + D), with X the measured (estimated) position the loop
//!   returns.
//!
//! From the sweep: the gain crossover (|L| = 1, log-interpolated) gives the phase margin
//! 180° + ∠L, the phase crossover (∠L = −180°) the gain margin −20 log₁₀|L|. Everything in the
//! loop is in the measurement: motor lag, the sensor chain and estimator, the adaptation.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::control::controller::Controller;

use crate::sim::plant::{PlantState, VehicleParams};
use crate::sim::scenario::Scenario;
use crate::sim::trajectory::TrajectoryPoint;

/// Where the loop is broken.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum LoopPoint {
    /// The roll torque at the plant input.
    Roll,
    /// The pitch torque at the plant input.
    Pitch,
    /// The world-x position measurement.
    X,
    /// The world-y position measurement.
    Y,
}

impl LoopPoint {
    /// A default sweep (Hz) for the loop.
    pub fn default_frequencies_hz(self) -> Vec<f64> {
        let (lo, hi, n) = match self {
            Self::Roll | Self::Pitch => (0.5_f64, 40.0_f64, 22),
            Self::X | Self::Y => (0.05_f64, 5.0_f64, 20),
        };
        (0..n)
            .map(|k| lo * (hi / lo).powf(k as f64 / (n - 1) as f64))
            .collect()
    }

    /// The injection's amplitude: 2e-4 N·m of torque (≈ 1 % of the CF2X's authority), or 1 cm.
    pub fn default_amplitude(self) -> f64 {
        match self {
            Self::Roll | Self::Pitch => 2e-4,
            Self::X | Self::Y => 0.01,
        }
    }
}

/// One frequency of the sweep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SweepPoint {
    /// Frequency (Hz).
    pub f_hz: f64,
    /// |L|.
    pub gain: f64,
    /// ∠L (deg, unwrapped into (−360, 0]).
    pub phase_deg: f64,
    /// The flight crashed before the measurement window ended.
    pub crashed: bool,
}

/// The margins of one loop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Margins {
    /// Gain crossover frequency (Hz), where |L| = 1.
    pub crossover_hz: Option<f64>,
    /// Phase margin (deg).
    pub phase_margin_deg: Option<f64>,
    /// Phase crossover frequency (Hz), where ∠L = −180°.
    pub phase_crossover_hz: Option<f64>,
    /// Gain margin (dB); null when the phase never reaches −180° in the sweep.
    pub gain_margin_db: Option<f64>,
    /// The sweep.
    pub sweep: Vec<SweepPoint>,
}

/// A controller with a sine injected at the loop's break point, recording both signals.
struct Injected<'a> {
    inner: &'a mut dyn Controller,
    params: VehicleParams,
    point: LoopPoint,
    f_hz: f64,
    amp: f64,
    /// (t, signal at the break, returned signal) per tick.
    rec: Vec<(f64, f64, f64)>,
}

impl Controller for Injected<'_> {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn reset(&mut self) {
        self.inner.reset();
        self.rec.clear();
    }

    fn step(&mut self, t: f64, s: &PlantState, r: &TrajectoryPoint, dt: f64) -> [f64; 4] {
        self.step_measured(t, s, None, r, dt)
    }

    fn step_measured(
        &mut self,
        t: f64,
        s: &PlantState,
        acc: Option<&Vector3<f64>>,
        r: &TrajectoryPoint,
        dt: f64,
    ) -> [f64; 4] {
        let d = self.amp * (core::f64::consts::TAU * self.f_hz * t).sin();
        match self.point {
            LoopPoint::Roll | LoopPoint::Pitch => {
                let cmd = self.inner.step_measured(t, s, acc, r, dt);
                let mut u = self.params.nominal_wrench(cmd);
                let k = if self.point == LoopPoint::Roll { 1 } else { 2 };
                let c = u[k];
                u[k] = c + d;
                self.rec.push((t, c + d, c));
                self.params.wrench_to_rpm(u)
            }
            LoopPoint::X | LoopPoint::Y => {
                let k = if self.point == LoopPoint::X { 0 } else { 1 };
                let mut m = *s;
                let x = s.p_m[k] - r.p_m[k];
                m.p_m[k] += d;
                self.rec.push((t, x + d, x));
                self.inner.step_measured(t, &m, acc, r, dt)
            }
        }
    }

    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        self.inner.adaptation_estimate()
    }
}

/// The Fourier coefficient of `x` at `f_hz` over whole periods from `t0`.
fn phasor(rec: &[(f64, f64)], f_hz: f64, t0: f64) -> Option<nalgebra::Complex<f64>> {
    let period = 1.0 / f_hz;
    let t_end = rec.last()?.0;
    let n_periods = ((t_end - t0) / period).floor();
    if n_periods < 1.0 {
        return None;
    }
    let t1 = t0 + n_periods * period;
    let (mut re, mut im, mut n) = (0.0, 0.0, 0usize);
    for &(t, x) in rec.iter().filter(|(t, _)| *t >= t0 && *t < t1) {
        let w = core::f64::consts::TAU * f_hz * t;
        re += x * w.sin();
        im += x * w.cos();
        n += 1;
    }
    (n > 0).then(|| nalgebra::Complex::new(re, im) / n as f64)
}

/// Measure L at one frequency: fly `scenario` with the injection.
pub fn measure_point(
    scenario: &Scenario,
    ctrl: &mut dyn Controller,
    point: LoopPoint,
    f_hz: f64,
    amp: f64,
) -> SweepPoint {
    // Settle 3 s (the adaptation transient), then at least 8 periods and 2 s.
    let settle = 3.0;
    let window = (8.0 / f_hz).max(2.0);
    let mut sc = scenario.clone();
    sc.spec.duration_s = settle + window;
    let mut inj = Injected {
        inner: ctrl,
        params: sc.vehicle.clone(),
        point,
        f_hz,
        amp,
        rec: Vec::new(),
    };
    let log = crate::fly::eval::fly(&sc, &mut inj);
    let crashed = log.crash_time_s.is_some();
    let e: Vec<(f64, f64)> = inj.rec.iter().map(|&(t, e, _)| (t, e)).collect();
    let y: Vec<(f64, f64)> = inj.rec.iter().map(|&(t, _, y)| (t, y)).collect();
    let (ep, yp) = (phasor(&e, f_hz, settle), phasor(&y, f_hz, settle));
    let (gain, phase_deg) = match (ep, yp) {
        (Some(ep), Some(yp)) if !crashed && ep.norm() > 0.0 => {
            let l = -yp / ep;
            let mut ph = l.arg().to_degrees();
            while ph > 0.0 {
                ph -= 360.0;
            }
            (l.norm(), ph)
        }
        _ => (f64::NAN, f64::NAN),
    };
    SweepPoint {
        f_hz,
        gain,
        phase_deg,
        crashed,
    }
}

/// The margins of a measured sweep (module docs). The phase is unwrapped along the sweep from
/// its high-frequency end, where every loop here rolls off below −180°.
pub fn margins_of(mut sweep: Vec<SweepPoint>) -> Margins {
    // Unwrap downward in frequency: keep consecutive phases within 180° of each other.
    for i in (0..sweep.len().saturating_sub(1)).rev() {
        let next = sweep[i + 1].phase_deg;
        if next.is_finite() && sweep[i].phase_deg.is_finite() {
            while sweep[i].phase_deg - next > 180.0 {
                sweep[i].phase_deg -= 360.0;
            }
            while sweep[i].phase_deg - next < -180.0 {
                sweep[i].phase_deg += 360.0;
            }
        }
    }
    let ok = |p: &SweepPoint| p.gain.is_finite() && p.phase_deg.is_finite();
    let mut crossover = None;
    let mut phase_x = None;
    for w in sweep.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if !(ok(a) && ok(b)) {
            continue;
        }
        let (la, lb) = (a.gain.ln(), b.gain.ln());
        let (fa, fb) = (a.f_hz.ln(), b.f_hz.ln());
        if crossover.is_none() && la >= 0.0 && lb < 0.0 {
            let s = la / (la - lb);
            let f = (fa + s * (fb - fa)).exp();
            let ph = a.phase_deg + s * (b.phase_deg - a.phase_deg);
            // The margin to the nearest −180° (mod 360°).
            let pm = (180.0 + ph).rem_euclid(360.0);
            crossover = Some((f, if pm > 180.0 { pm - 360.0 } else { pm }));
        }
        // The first crossing of −180° (mod 360°) above the gain crossover.
        let k = ((a.phase_deg + 180.0) / 360.0).floor();
        let level = -180.0 + 360.0 * k;
        if phase_x.is_none() && crossover.is_some() && a.phase_deg >= level && b.phase_deg < level {
            let s = (a.phase_deg - level) / (a.phase_deg - b.phase_deg);
            let f = (fa + s * (fb - fa)).exp();
            let g = (la + s * (lb - la)).exp();
            phase_x = Some((f, -20.0 * g.log10()));
        }
    }
    Margins {
        crossover_hz: crossover.map(|c| c.0),
        phase_margin_deg: crossover.map(|c| c.1),
        phase_crossover_hz: phase_x.map(|c| c.0),
        gain_margin_db: phase_x.map(|c| c.1),
        sweep,
    }
}

/// Sweep `point` of `controller` on `scenario` and return the margins.
pub fn measure(
    scenario: &Scenario,
    controller: &str,
    weights: Option<&std::path::Path>,
    point: LoopPoint,
) -> Result<Margins> {
    let mut ctrl = crate::control::registry::by_name(controller, scenario, weights)?;
    let sweep = point
        .default_frequencies_hz()
        .into_iter()
        .map(|f| measure_point(scenario, ctrl.as_mut(), point, f, point.default_amplitude()))
        .collect();
    Ok(margins_of(sweep))
}

/// Arguments of `host-train margins`.
#[derive(Args, Debug, Clone)]
pub struct MarginsArgs {
    /// Scenario to fly (a hover: the sweep flies it once per frequency), e.g.
    /// scenarios/cf-hover-lag70.toml.
    #[arg(long, value_name = "FILE")]
    pub scenario: PathBuf,
    /// Controllers to measure (comma-separated names, as `eval --controller`).
    #[arg(long, value_name = "NAMES", default_value = "adaptive,learned")]
    pub controllers: String,
    /// Weight blob for the learned controllers.
    #[arg(long, value_name = "FILE", default_value = crate::control::registry::DEFAULT_WEIGHTS)]
    pub weights: PathBuf,
    /// Where to break the loop (the attitude loop at the plant input, or the position loop at
    /// its measurement).
    #[arg(long = "loop", value_enum, default_value = "roll")]
    pub point: LoopPoint,
    /// Output directory for margins.json.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// One row of `margins.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MarginsRow {
    /// Controller name.
    pub controller: String,
    /// The loop.
    pub point: LoopPoint,
    /// Its margins.
    pub margins: Margins,
}

/// Run `host-train margins`: print a table, write DIR/margins.json.
pub fn run(args: &MarginsArgs) -> Result<Vec<MarginsRow>> {
    let scenario = Scenario::load(&args.scenario)?;
    let mut rows = Vec::new();
    for name in args
        .controllers
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
    {
        let m = measure(&scenario, name, Some(&args.weights), args.point)
            .with_context(|| format!("controller `{name}`"))?;
        rows.push(MarginsRow {
            controller: name.to_string(),
            point: args.point,
            margins: m,
        });
    }
    if rows.is_empty() {
        bail!("--controllers: no controller named");
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output directory `{}`", args.out.display()))?;
    crate::io::files::write_json_atomic(&args.out.join("margins.json"), &rows)?;
    Ok(rows)
}

/// The table `host-train margins` prints.
pub fn table(scenario: &str, rows: &[MarginsRow]) -> String {
    let f = |x: Option<f64>, p: usize| x.map_or("—".to_string(), |v| format!("{v:.p$}"));
    let mut s = format!(
        "{scenario}\n| controller | loop | crossover (Hz) | phase margin (deg) | phase crossover (Hz) | gain margin (dB) |\n| --- | --- | --- | --- | --- | --- |\n"
    );
    for r in rows {
        let m = &r.margins;
        s += &format!(
            "| {} | {:?} | {} | {} | {} | {} |\n",
            r.controller,
            r.point,
            f(m.crossover_hz, 2),
            f(m.phase_margin_deg, 1),
            f(m.phase_crossover_hz, 2),
            f(m.gain_margin_db, 1)
        );
    }
    s
}
