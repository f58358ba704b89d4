//! `host-train robustness`: the robustness matrix: the plant's rotor lag × the
//! blob's motor lag × an added command delay × a command jitter, both adaptation laws, on hover
//! and calm-spiral; per cell the position RMSE, the largest motor oscillation, limit cycle and
//! crash, and the delay margin. Writes a JSON report (atomically) and prints a table.
//!
//! Definitions (docs/envelope.md):
//! - motor oscillation: each rotor command (rpm) high-passed (first order, [`HIGH_PASS_HZ`]),
//!   its peak-to-peak in each 1 s window after the transient ([`TRANSIENT_S`]), as a fraction of
//!   the top speed; the cell's value is the largest over rotors and windows;
//! - limit cycle: every one of the last [`SUSTAIN_WINDOWS`] windows has some rotor's
//!   peak-to-peak ≥ [`LIMIT_CYCLE_FRACTION`] of the top speed (a sustained oscillation);
//! - crash: the loop's crash detection (non-finite state, below ground, or far off the path);
//! - delay margin: the smallest added delay (ms, jitter 0), searched in `--margin-step-ms`
//!   steps up to `--margin-max-ms`, at which the flight limit-cycles or crashes (none: above
//!   the search's top).

use crate::control::adapter::{gains_for, load_learned, CoreController};
use crate::control::controller::Controller;
use crate::control::spec::ControllerSpec;
use crate::fly::eval::fly;
use crate::io::flightlog::FlightLog;
use crate::sim::scenario::Scenario;
use anyhow::{Context, Result};
use clap::Args;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The high-pass corner (Hz) that separates a motor oscillation from the trajectory's trim.
pub const HIGH_PASS_HZ: f64 = 2.0;
/// Seconds of start-up transient not scored for oscillation.
pub const TRANSIENT_S: f64 = 2.0;
/// A limit cycle: peak-to-peak at least this fraction of the top speed ...
pub const LIMIT_CYCLE_FRACTION: f64 = 0.10;
/// ... in each of the last this many 1 s windows.
pub const SUSTAIN_WINDOWS: usize = 3;

/// Arguments of `host-train robustness`.
#[derive(Args, Debug, Clone)]
#[command(
    about = "The robustness matrix: plant rotor lag × blob motor lag × command delay × jitter",
    long_about = "Fly the robustness matrix: the plant's rotor lag (0/20/50/80 ms) × the blob's \
motor lag (the lag the core's compensation assumes, overriding the blob's: 0/20/50/80 ms) × an \
added command delay (0/4/8 ms, between the controller's output and the plant) × a seeded command \
jitter (0/3/6 ms), for both adaptation laws (adaptive = composite, adaptive-gradient), on \
scenarios/hover.toml and scenarios/calm-spiral.toml. Per cell: position RMSE, the largest motor \
oscillation (peak-to-peak of the 2 Hz high-passed rotor command after 2 s, per 1 s window, as a \
fraction of the top speed), limit cycle (≥ 10 % in each of the last 3 windows), crash, and the \
delay margin (smallest added delay at which it limit-cycles or crashes). Progress on stderr; \
writes the JSON report (atomic) and prints a markdown table."
)]
pub struct RobustnessArgs {
    /// Weight blob (its vehicle and model; its motor lag is overridden per cell).
    #[arg(long, default_value = crate::control::registry::DEFAULT_WEIGHTS)]
    pub weights: PathBuf,
    /// Directory of hover.toml and calm-spiral.toml.
    #[arg(long, default_value = "scenarios")]
    pub scenarios: PathBuf,
    /// Output JSON file.
    #[arg(long, default_value = "out/robustness.json")]
    pub out: PathBuf,
    /// A subset: plant and blob lags 0 and 80 ms (matched and the worst mismatches), delay
    /// 0/8 ms, jitter 0/6 ms, hover only, 10 s flights, margin in 4 ms steps.
    #[arg(long)]
    pub fast: bool,
    /// Plant rotor lags (ms), comma-separated (overrides the default list).
    #[arg(long, value_delimiter = ',')]
    pub plant_lag_ms: Option<Vec<f64>>,
    /// Blob motor lags (ms), comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub blob_lag_ms: Option<Vec<f64>>,
    /// Added delays (ms), comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub delay_ms: Option<Vec<f64>>,
    /// Jitters (ms), comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub jitter_ms: Option<Vec<f64>>,
    /// Laws (core controller names), comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub laws: Option<Vec<String>>,
    /// Scenario stems, comma-separated (files in --scenarios).
    #[arg(long, value_delimiter = ',')]
    pub scenario: Option<Vec<String>>,
    /// Cap every flight at this many seconds (0 = the scenario's own duration).
    #[arg(long, default_value_t = 0.0)]
    pub max_duration_s: f64,
    /// Delay-margin search step (ms).
    #[arg(long, default_value_t = 2.0)]
    pub margin_step_ms: f64,
    /// Delay-margin search top (ms).
    #[arg(long, default_value_t = 40.0)]
    pub margin_max_ms: f64,
    /// Skip the delay-margin search.
    #[arg(long)]
    pub no_margin: bool,
    /// Fly every cell with the core's motor-lag watch off (`Gains::lag_watch`, on by default:
    /// docs/envelope.md, "The lag watch"), to see what it removes.
    #[arg(long)]
    pub no_lag_watch: bool,
}

/// The matrix to fly.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Grid {
    /// The plant's rotor lag (ms).
    pub plant_lag_ms: Vec<f64>,
    /// The blob's motor lag the core compensates (ms).
    pub blob_lag_ms: Vec<f64>,
    /// Added command delay (ms).
    pub delay_ms: Vec<f64>,
    /// Command jitter, the top of the uniform extra delay (ms).
    pub jitter_ms: Vec<f64>,
    /// Core controller names.
    pub laws: Vec<String>,
    /// Scenario stems.
    pub scenarios: Vec<String>,
    /// Flight length cap (s), 0 = none.
    pub max_duration_s: f64,
    /// Delay-margin search step (ms).
    pub margin_step_ms: f64,
    /// Delay-margin search top (ms).
    pub margin_max_ms: f64,
    /// Whether the delay margin is searched.
    pub margin: bool,
}

impl Grid {
    /// The full matrix (every lag, delay and jitter).
    pub fn full() -> Self {
        Self {
            plant_lag_ms: vec![0.0, 20.0, 50.0, 80.0],
            blob_lag_ms: vec![0.0, 20.0, 50.0, 80.0],
            delay_ms: vec![0.0, 4.0, 8.0],
            jitter_ms: vec![0.0, 3.0, 6.0],
            laws: vec!["adaptive".into(), "adaptive-gradient".into()],
            scenarios: vec!["hover".into(), "calm-spiral".into()],
            max_duration_s: 0.0,
            margin_step_ms: 2.0,
            margin_max_ms: 40.0,
            margin: true,
        }
    }

    /// `--fast`'s subset.
    pub fn fast() -> Self {
        Self {
            plant_lag_ms: vec![0.0, 80.0],
            blob_lag_ms: vec![0.0, 80.0],
            delay_ms: vec![0.0, 8.0],
            jitter_ms: vec![0.0, 6.0],
            scenarios: vec!["hover".into()],
            max_duration_s: 10.0,
            margin_step_ms: 4.0,
            ..Self::full()
        }
    }

    fn from_args(a: &RobustnessArgs) -> Self {
        let mut g = if a.fast { Self::fast() } else { Self::full() };
        let set = |dst: &mut Vec<f64>, src: &Option<Vec<f64>>| {
            if let Some(v) = src {
                dst.clone_from(v);
            }
        };
        set(&mut g.plant_lag_ms, &a.plant_lag_ms);
        set(&mut g.blob_lag_ms, &a.blob_lag_ms);
        set(&mut g.delay_ms, &a.delay_ms);
        set(&mut g.jitter_ms, &a.jitter_ms);
        if let Some(l) = &a.laws {
            g.laws.clone_from(l);
        }
        if let Some(s) = &a.scenario {
            g.scenarios.clone_from(s);
        }
        if a.max_duration_s > 0.0 {
            g.max_duration_s = a.max_duration_s;
        }
        if !a.fast || a.margin_step_ms != 2.0 {
            g.margin_step_ms = a.margin_step_ms;
        }
        g.margin_max_ms = a.margin_max_ms;
        g.margin = !a.no_margin;
        g
    }
}

/// One flight's scores.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct FlightScore {
    /// Position RMSE over the flight (m).
    pub rmse_m: f64,
    /// Largest motor oscillation (peak-to-peak / top speed) after the transient.
    pub oscillation: f64,
    /// Sustained oscillation ([`LIMIT_CYCLE_FRACTION`]).
    pub limit_cycle: bool,
    /// The loop detected a crash.
    pub crashed: bool,
}

impl FlightScore {
    /// A limit cycle or a crash.
    pub fn failed(&self) -> bool {
        self.limit_cycle || self.crashed
    }
}

/// One cell of the matrix.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Cell {
    /// Core controller name.
    pub law: String,
    /// Scenario stem.
    pub scenario: String,
    /// The plant's rotor lag (ms).
    pub plant_lag_ms: f64,
    /// The blob's motor lag the core compensates (ms).
    pub blob_lag_ms: f64,
    /// Added command delay (ms).
    pub delay_ms: f64,
    /// Command jitter, the top of the uniform extra delay (ms).
    pub jitter_ms: f64,
    /// The flight's scores.
    #[serde(flatten)]
    pub score: FlightScore,
}

/// The delay margin of one (law, scenario, plant lag, blob lag).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Margin {
    /// Core controller name.
    pub law: String,
    /// Scenario stem.
    pub scenario: String,
    /// The plant's rotor lag (ms).
    pub plant_lag_ms: f64,
    /// The blob's motor lag the core compensates (ms).
    pub blob_lag_ms: f64,
    /// Smallest failing delay (ms); None: none up to `searched_to_ms`.
    pub margin_ms: Option<f64>,
    /// The search's top (ms).
    pub searched_to_ms: f64,
}

/// The report written to `--out`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RobustnessReport {
    /// The weight blob flown.
    pub weights: String,
    /// The matrix flown.
    pub grid: Grid,
    /// Every cell.
    pub cells: Vec<Cell>,
    /// Every delay margin.
    pub margins: Vec<Margin>,
    /// Wall time of the run (s).
    pub elapsed_s: f64,
}

/// One flight of a law on `scenario` with the plant's rotor lag, the blob's motor lag, an added
/// delay and a jitter (all ms), the lag watch as the core's default has it
/// ([`hamflight::gains::LAG_WATCH`]).
pub fn fly_cell(
    weights: &Path,
    law: &str,
    scenario: &Scenario,
    plant_lag_ms: f64,
    blob_lag_ms: f64,
    delay_ms: f64,
    jitter_ms: f64,
) -> Result<(FlightScore, FlightLog)> {
    let lags = (plant_lag_ms, blob_lag_ms);
    let watch = hamflight::gains::LAG_WATCH;
    fly_cell_watched(weights, law, scenario, lags, delay_ms, jitter_ms, watch)
}

/// [`fly_cell`] with the core's motor-lag watch on or off (`Gains::lag_watch`); `lags_ms` is
/// (plant, blob).
pub fn fly_cell_watched(
    weights: &Path,
    law: &str,
    scenario: &Scenario,
    (plant_lag_ms, blob_lag_ms): (f64, f64),
    delay_ms: f64,
    jitter_ms: f64,
    lag_watch: bool,
) -> Result<(FlightScore, FlightLog)> {
    let mut sc = scenario.clone();
    sc.spec.effects.motor_tau_s = plant_lag_ms * 1e-3;
    sc.spec.effects.command_delay_s = delay_ms * 1e-3;
    sc.spec.effects.command_jitter_s = jitter_ms * 1e-3;
    let spec = ControllerSpec::parse_core(law)?;
    let mut model = load_learned(weights)?;
    model.set_motor_tau_s((blob_lag_ms * 1e-3) as f32);
    let gains = hamflight::Gains {
        lag_watch,
        ..spec.gains(gains_for(&model))
    };
    let mut ctrl = CoreController::new(spec.name, model, gains);
    let log = fly(&sc, &mut ctrl as &mut dyn Controller);
    let max_rpm = sc.plant().params.max_rpm();
    Ok((score(&log, max_rpm), log))
}

/// The scores of one flight log ([`FlightScore`]; definitions in the module's doc).
pub fn score(log: &FlightLog, max_rpm: f64) -> FlightScore {
    let n = log.err_m.len().max(1) as f64;
    let rmse_m = (log.err_m.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
    let crashed = log.crash_time_s.is_some();
    let dt = 1.0 / log.control_hz.max(1.0);
    let alpha = 1.0 / (1.0 + 2.0 * std::f64::consts::PI * HIGH_PASS_HZ * dt);
    let per_window = (1.0 / dt).round().max(1.0) as usize;
    let skip = (TRANSIENT_S / dt).round() as usize;
    // High-passed rotor commands, y[k] = α (y[k-1] + x[k] − x[k-1]).
    let mut hp: Vec<[f64; 4]> = Vec::with_capacity(log.rpm.len());
    let mut y = [0.0; 4];
    for (k, r) in log.rpm.iter().enumerate() {
        if k > 0 {
            let prev = log.rpm[k - 1];
            for i in 0..4 {
                y[i] = alpha * (y[i] + r[i] - prev[i]);
            }
        }
        hp.push(y);
    }
    let windows: Vec<f64> = hp
        .get(skip.min(hp.len())..)
        .unwrap_or(&[])
        .chunks(per_window)
        .filter(|w| w.len() == per_window)
        .map(|w| {
            (0..4)
                .map(|i| {
                    let (lo, hi) = w
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                            (l.min(v[i]), h.max(v[i]))
                        });
                    (hi - lo) / max_rpm
                })
                .fold(0.0, f64::max)
        })
        .collect();
    let oscillation = windows.iter().copied().fold(0.0, f64::max);
    let limit_cycle = windows.len() >= SUSTAIN_WINDOWS
        && windows[windows.len() - SUSTAIN_WINDOWS..]
            .iter()
            .all(|&p| p >= LIMIT_CYCLE_FRACTION);
    FlightScore {
        rmse_m,
        oscillation,
        limit_cycle,
        crashed,
    }
}

/// The smallest added delay (ms, in `step_ms` steps from `step_ms` to `max_ms`, jitter 0) at
/// which the flight fails; None when none does.
#[allow(clippy::too_many_arguments)]
pub fn delay_margin_ms(
    weights: &Path,
    law: &str,
    scenario: &Scenario,
    plant_lag_ms: f64,
    blob_lag_ms: f64,
    step_ms: f64,
    max_ms: f64,
    lag_watch: bool,
) -> Result<Option<f64>> {
    let mut d = step_ms;
    while d <= max_ms + 1e-9 {
        let lags = (plant_lag_ms, blob_lag_ms);
        let (s, _) = fly_cell_watched(weights, law, scenario, lags, d, 0.0, lag_watch)?;
        if s.failed() {
            return Ok(Some(d));
        }
        d += step_ms;
    }
    Ok(None)
}

/// Load a scenario stem from `dir`, capped at `max_duration_s` (0 = not capped).
pub fn load_scenario(dir: &Path, stem: &str, max_duration_s: f64) -> Result<Scenario> {
    let mut sc = Scenario::load(dir.join(format!("{stem}.toml")))?;
    if max_duration_s > 0.0 && sc.spec.duration_s > max_duration_s {
        sc.spec.duration_s = max_duration_s;
    }
    Ok(sc)
}

/// Fly the matrix ([`RobustnessArgs`]); progress on stderr; writes `--out`.
pub fn run(args: &RobustnessArgs) -> Result<RobustnessReport> {
    if !(args.margin_step_ms > 0.0 && args.margin_step_ms.is_finite()) {
        anyhow::bail!("--margin-step-ms: expected a step > 0 ms");
    }
    let grid = Grid::from_args(args);
    for (name, v) in [
        ("--plant-lag-ms", &grid.plant_lag_ms),
        ("--blob-lag-ms", &grid.blob_lag_ms),
        ("--delay-ms", &grid.delay_ms),
        ("--jitter-ms", &grid.jitter_ms),
    ] {
        if v.iter()
            .any(|x| !(x.is_finite() && (0.0..=1000.0).contains(x)))
        {
            anyhow::bail!("{name}: expected values in [0, 1000] ms, got {v:?}");
        }
    }
    for l in &grid.laws {
        ControllerSpec::parse_core(l).with_context(|| format!("--laws: `{l}`"))?;
    }
    let t0 = Instant::now();
    let mut cells = Vec::new();
    let mut margins = Vec::new();
    let total = grid.scenarios.len()
        * grid.laws.len()
        * grid.plant_lag_ms.len()
        * grid.blob_lag_ms.len()
        * grid.delay_ms.len()
        * grid.jitter_ms.len();
    let mut done = 0;
    for stem in &grid.scenarios {
        let sc = load_scenario(&args.scenarios, stem, grid.max_duration_s)?;
        for law in &grid.laws {
            for &pl in &grid.plant_lag_ms {
                for &bl in &grid.blob_lag_ms {
                    for &d in &grid.delay_ms {
                        for &j in &grid.jitter_ms {
                            let (s, _) = fly_cell_watched(
                                &args.weights,
                                law,
                                &sc,
                                (pl, bl),
                                d,
                                j,
                                !args.no_lag_watch,
                            )?;
                            done += 1;
                            eprintln!(
                                "[{done}/{total} {:.0} s] {stem} {law} plant {pl} ms blob {bl} ms \
                                 delay {d} ms jitter {j} ms: rmse {:.3} m osc {:.3} {}{}",
                                t0.elapsed().as_secs_f64(),
                                s.rmse_m,
                                s.oscillation,
                                if s.limit_cycle { "LIMIT-CYCLE " } else { "" },
                                if s.crashed { "CRASH" } else { "" },
                            );
                            cells.push(Cell {
                                law: law.clone(),
                                scenario: stem.clone(),
                                plant_lag_ms: pl,
                                blob_lag_ms: bl,
                                delay_ms: d,
                                jitter_ms: j,
                                score: s,
                            });
                        }
                    }
                    if grid.margin {
                        let m = delay_margin_ms(
                            &args.weights,
                            law,
                            &sc,
                            pl,
                            bl,
                            grid.margin_step_ms,
                            grid.margin_max_ms,
                            !args.no_lag_watch,
                        )?;
                        eprintln!(
                            "[{:.0} s] {stem} {law} plant {pl} ms blob {bl} ms: delay margin {}",
                            t0.elapsed().as_secs_f64(),
                            m.map_or(format!("> {} ms", grid.margin_max_ms), |m| format!(
                                "{m} ms"
                            ))
                        );
                        margins.push(Margin {
                            law: law.clone(),
                            scenario: stem.clone(),
                            plant_lag_ms: pl,
                            blob_lag_ms: bl,
                            margin_ms: m,
                            searched_to_ms: grid.margin_max_ms,
                        });
                    }
                }
            }
        }
    }
    let report = RobustnessReport {
        weights: args.weights.display().to_string(),
        grid,
        cells,
        margins,
        elapsed_s: t0.elapsed().as_secs_f64(),
    };
    write_atomic(&args.out, &serde_json::to_string_pretty(&report)?)?;
    Ok(report)
}

fn write_atomic(path: &Path, text: &str) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create `{}`", dir.display()))?;
    }
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, text).with_context(|| format!("cannot write `{}`", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot rename to `{}`", path.display()))
}

/// The markdown table of a report: per law and scenario, the worst cell of each (plant lag,
/// blob lag) over delays ≤ 8 ms and jitters, and the delay margin.
pub fn table(r: &RobustnessReport) -> String {
    let mut s = String::from(
        "| law | scenario | plant lag (ms) | blob lag (ms) | worst RMSE (m) | worst oscillation | \
         failing cells (delay ≤ 8 ms) | delay margin (ms) |\n| --- | --- | ---: | ---: | ---: | ---: | --- | ---: |\n",
    );
    let mut keys: Vec<(String, String, f64, f64)> = Vec::new();
    for c in &r.cells {
        let k = (
            c.law.clone(),
            c.scenario.clone(),
            c.plant_lag_ms,
            c.blob_lag_ms,
        );
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    for (law, sc, pl, bl) in keys {
        let cs: Vec<&Cell> = r
            .cells
            .iter()
            .filter(|c| {
                c.law == law && c.scenario == sc && c.plant_lag_ms == pl && c.blob_lag_ms == bl
            })
            .collect();
        let rmse = cs.iter().map(|c| c.score.rmse_m).fold(0.0, f64::max);
        let osc = cs.iter().map(|c| c.score.oscillation).fold(0.0, f64::max);
        let fails: Vec<String> = cs
            .iter()
            .filter(|c| c.delay_ms <= 8.0 && c.score.failed())
            .map(|c| {
                format!(
                    "{}+{} ms{}",
                    c.delay_ms,
                    c.jitter_ms,
                    if c.score.crashed { " crash" } else { " cycle" }
                )
            })
            .collect();
        let m = r
            .margins
            .iter()
            .find(|m| {
                m.law == law && m.scenario == sc && m.plant_lag_ms == pl && m.blob_lag_ms == bl
            })
            .map_or("–".to_string(), |m| {
                m.margin_ms
                    .map_or(format!("> {}", m.searched_to_ms), |v| format!("{v}"))
            });
        s.push_str(&format!(
            "| {law} | {sc} | {pl} | {bl} | {rmse:.3} | {osc:.3} | {} | {m} |\n",
            if fails.is_empty() {
                "none".to_string()
            } else {
                fails.join(", ")
            }
        ));
    }
    s
}
