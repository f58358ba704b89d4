//! How fast the adaptation follows a changing disturbance: the amplitude ratio and phase lag of
//! the compensated specific force R (W a)_v / m against a sinusoidal wind, hovering (the
//! bandwidth table of docs/adaptation.md).

use anyhow::Result;
use hamflight::model::HamiltonianModel;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::control::adapter::CoreController;
use crate::sim::plant::PlantState;
use crate::sim::plant::WindSine;
use crate::sim::scenario::{Scenario, ScenarioSpec, Trajectory};

/// The wind amplitude of the measurement (m/s², along world x).
pub const AMPLITUDE_M_S2: f64 = 0.5;
/// The time before the fit starts (s): the estimate's start-up transient.
pub const SETTLE_S: f64 = 4.0;
/// The frequencies of the bandwidth table in docs/adaptation.md (Hz).
pub const FREQUENCIES_HZ: [f64; 4] = [0.25, 0.5, 1.0, 2.0];

// The data the plots draw are defined with them (`plot` does not depend on this module).
pub use crate::report::plot::{BandwidthPoint, DisturbanceSample};

/// The compensated disturbance as a world-frame specific force, R (W a)_v / m (m/s²).
pub fn compensated_specific_force<M: HamiltonianModel>(
    ctrl: &CoreController<M>,
    state: &PlantState,
) -> Vector3<f64> {
    let s: hamflight::State = state.into();
    let terms = ctrl.inner().model().terms(&s);
    let wa = terms.features * ctrl.inner().estimate();
    let f = Vector3::new(wa[0], wa[1], wa[2]).cast::<f64>() / f64::from(terms.mass_kg);
    state.rot * f
}

/// The hover scenario with wind AMPLITUDE sin(2π f t) along x, long enough for the fit.
pub fn sine_wind_scenario(frequency_hz: f64) -> Result<Scenario> {
    let periods = (4.0 * frequency_hz).ceil().max(4.0);
    let duration = SETTLE_S + periods / frequency_hz;
    let mut spec = ScenarioSpec::new(
        duration,
        Trajectory::Hover {
            position_m: [0.0, 0.0, 1.0],
        },
    );
    spec.disturbance.wind_sines = vec![WindSine {
        amplitude_m_s2: [AMPLITUDE_M_S2, 0.0, 0.0],
        frequency_hz,
        phase_rad: 0.0,
    }];
    Scenario::from_spec("bandwidth", spec)
}

/// Flies `sc` with `ctrl` in the one SITL loop ([`crate::fly::eval::fly_observed`]) and
/// returns per control tick (t, true wind, estimate).
pub fn track_disturbance<M: HamiltonianModel>(
    sc: &Scenario,
    ctrl: &mut CoreController<M>,
) -> Vec<DisturbanceSample> {
    let mut out = Vec::new();
    crate::fly::eval::fly_observed(sc, ctrl, None, |t, c, plant| {
        out.push((
            t,
            plant.wind_at(t),
            compensated_specific_force(c, plant.state()),
        ));
    });
    out
}

/// Least-squares fit of y ≈ c + a cos ωt + b sin ωt; returns (a, b).
fn fit(samples: &[(f64, f64)], w: f64) -> (f64, f64) {
    // Normal equations of the 3-parameter model.
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut r = nalgebra::Vector3::<f64>::zeros();
    for (t, y) in samples {
        let x = nalgebra::Vector3::new(1.0, (w * t).cos(), (w * t).sin());
        m += x * x.transpose();
        r += x * *y;
    }
    let p = m.try_inverse().map(|i| i * r).unwrap_or_default();
    (p[1], p[2])
}

/// The frequency response of `ctrl`'s estimate at `frequency_hz`.
pub fn measure<M: HamiltonianModel>(
    ctrl: &mut CoreController<M>,
    frequency_hz: f64,
) -> Result<BandwidthPoint> {
    let sc = sine_wind_scenario(frequency_hz)?;
    let trace = track_disturbance(&sc, ctrl);
    let w = core::f64::consts::TAU * frequency_hz;
    let est: Vec<(f64, f64)> = trace
        .iter()
        .filter(|(t, _, _)| *t >= SETTLE_S)
        .map(|(t, _, e)| (*t, e.x))
        .collect();
    let truth: Vec<(f64, f64)> = trace
        .iter()
        .filter(|(t, _, _)| *t >= SETTLE_S)
        .map(|(t, d, _)| (*t, d.x))
        .collect();
    let (ea, eb) = fit(&est, w);
    let (ta, tb) = fit(&truth, w);
    let amp = |a: f64, b: f64| (a * a + b * b).sqrt();
    // y = A cos + B sin = amp sin(ωt + φ) with φ = atan2(A, B).
    let lag = (ta.atan2(tb) - ea.atan2(eb)).to_degrees();
    let lag = (lag + 180.0).rem_euclid(360.0) - 180.0;
    Ok(BandwidthPoint {
        frequency_hz,
        amplitude_ratio: amp(ea, eb) / amp(ta, tb).max(1e-12),
        lag_deg: lag,
    })
}

/// The standard deviation of each component of the logged estimate a over t ≥ `from_s` (a's
/// units: m/s² for the force columns, 1e-3 N·m for the torque ones): how much the estimate
/// moves, chatter included, once converged.
pub fn estimate_std(log: &crate::fly::eval::FlightLog, from_s: f64) -> Vec<f64> {
    let rows: Vec<&Vec<f64>> = log
        .t_s
        .iter()
        .zip(&log.adaptation)
        .filter(|(t, a)| **t >= from_s && !a.is_empty())
        .map(|(_, a)| a)
        .collect();
    let Some(first) = rows.first() else {
        return Vec::new();
    };
    let n = rows.len() as f64;
    (0..first.len())
        .map(|i| {
            let xs = rows.iter().filter_map(|r| r.get(i).copied());
            let mean = xs.clone().sum::<f64>() / n;
            (xs.map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt()
        })
        .collect()
}

/// One law's estimate against the true disturbance over a flight.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrackedLaw {
    /// The adaptation law (`Gradient` or `Composite`).
    pub law: String,
    /// RMS over t ≥ 5 s of estimate − true wind, world x and y (m/s²).
    pub rms_error_m_s2: f64,
    /// Per tick: t (s), true wind (m/s², world), compensated specific force R (W a)_v / m.
    #[serde(skip)]
    pub trace: Vec<DisturbanceSample>,
}

/// `host-train track`: both laws on one scenario, estimate against truth.
#[derive(clap::Args, Debug, Clone)]
pub struct TrackArgs {
    /// Scenario TOML file (one with a wind: e.g. scenarios/gust-spiral.toml).
    #[arg(long, value_name = "FILE")]
    pub scenario: std::path::PathBuf,
    /// `adaptive` (learned model, `--weights`) or `geometric-adaptive` (nominal model).
    #[arg(long, value_name = "NAME", default_value = "adaptive")]
    pub controller: String,
    /// Weight blob for `adaptive`.
    #[arg(long, value_name = "FILE", default_value = crate::control::registry::DEFAULT_WEIGHTS)]
    pub weights: std::path::PathBuf,
    /// Output directory for disturbance.svg and track.json (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: std::path::PathBuf,
    /// Also measure the estimator's frequency response at 0.25, 0.5, 1 and 2 Hz (hovering,
    /// sinusoidal wind): bandwidth.svg and the points in track.json (about 8 flights a law).
    #[arg(long)]
    pub bandwidth: bool,
}

/// What `host-train track` measured.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrackReport {
    /// Scenario name.
    pub scenario: String,
    /// Controller name.
    pub controller: String,
    /// Per law: the estimate's RMS error.
    pub laws: Vec<TrackedLaw>,
    /// Per law: the frequency response (empty without `--bandwidth`).
    pub bandwidth: Vec<(String, Vec<BandwidthPoint>)>,
}

fn track_both<M: HamiltonianModel + Clone>(
    args: &TrackArgs,
    sc: &Scenario,
    model: M,
) -> Result<TrackReport> {
    use hamflight::AdaptationLaw;
    let mut laws = Vec::new();
    let mut bandwidth = Vec::new();
    for law in [AdaptationLaw::Gradient, AdaptationLaw::Composite] {
        let gains = hamflight::Gains {
            law,
            ..hamflight::Gains::for_vehicle(&hamflight::VehicleFacts::of(&model))
        };
        let mut ctrl = CoreController::new(&args.controller, model.clone(), gains);
        let trace = track_disturbance(sc, &mut ctrl);
        let errs: Vec<f64> = trace
            .iter()
            .filter(|(t, _, _)| *t >= crate::fly::eval::WINDOW_START_S)
            .map(|(_, d, e)| (d.x - e.x).powi(2) + (d.y - e.y).powi(2))
            .collect();
        let rms = (errs.iter().sum::<f64>() / errs.len().max(1) as f64).sqrt();
        laws.push(TrackedLaw {
            law: format!("{law:?}"),
            rms_error_m_s2: rms,
            trace,
        });
        if args.bandwidth {
            let mut pts = Vec::new();
            for f in FREQUENCIES_HZ {
                pts.push(measure(&mut ctrl, f)?);
            }
            bandwidth.push((format!("{law:?}"), pts));
        }
    }
    Ok(TrackReport {
        scenario: sc.name.clone(),
        controller: args.controller.clone(),
        laws,
        bandwidth,
    })
}

/// Run `host-train track`: fly `args.scenario` with both adaptation laws, write
/// `disturbance.svg` (the estimate against the true wind), `track.json` and, with
/// `--bandwidth`, `bandwidth.svg`.
pub fn run_track(args: &TrackArgs) -> Result<TrackReport> {
    let sc = Scenario::load(&args.scenario)?;
    use crate::control::spec::{ControllerKind, ControllerSpec, ModelSource};
    let spec = ControllerSpec::parse(&args.controller)?;
    // Track flies both laws on the name's model: a name that picks a law or turns adaptation
    // off is refused.
    let report = match spec.kind {
        ControllerKind::Core {
            model: ModelSource::Learned,
            adapt: true,
            law: None,
        } => track_both(
            args,
            &sc,
            crate::control::adapter::load_learned(&args.weights)?,
        )?,
        ControllerKind::Core {
            model: ModelSource::Nominal,
            adapt: true,
            law: None,
        } => track_both(args, &sc, hamflight::model::NominalModel::default())?,
        _ => anyhow::bail!(
            "--controller {}: track flies `adaptive` or `geometric-adaptive` (both laws each)",
            spec.name
        ),
    };
    std::fs::create_dir_all(&args.out)
        .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", args.out.display()))?;
    let series: Vec<(&str, &[DisturbanceSample])> = report
        .laws
        .iter()
        .map(|l| (l.law.as_str(), l.trace.as_slice()))
        .collect();
    let title = format!("{}, {}", report.scenario, report.controller);
    crate::report::plot::disturbance_svg(&title, &series, &args.out.join("disturbance.svg"))?;
    if !report.bandwidth.is_empty() {
        let pts: Vec<(&str, &[BandwidthPoint])> = report
            .bandwidth
            .iter()
            .map(|(l, p)| (l.as_str(), p.as_slice()))
            .collect();
        crate::report::plot::bandwidth_svg(
            &report.controller,
            &pts,
            &args.out.join("bandwidth.svg"),
        )?;
    }
    crate::fly::eval::write_json_atomic(&args.out.join("track.json"), &report)?;
    Ok(report)
}
