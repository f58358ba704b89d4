//! `host-train onboard`: replays the onboard Mellinger controller
//! ([`crate::control::onboard`]) along the benchmark's closed-loop logs
//! (`tools/benchmark/nanodrone.py --loop-out`) and measures how well it reproduces the logged
//! motor commands (R² per motor and per axis, per flight and pooled); tabulates which logged
//! wrench columns can be trusted; with `--fit` identifies the parameters the defaults miss, on
//! the training flights only.

pub mod fit;
pub mod replay;
pub mod stats;
pub mod trust;

use crate::control::onboard::OnboardConfig;
use crate::io::{read_loop_csv, write_json_atomic, LoopFlight};
use anyhow::{bail, Context, Result};
use replay::{active, replay, smooth, AccelSource, ReplayOptions};
use serde::Serialize;
use stats::{FitAcc, R2Summary};
use std::path::{Path, PathBuf};

/// Replay Bitcraze's Mellinger controller (our port) along logged closed-loop flights.
#[derive(clap::Args, Debug, Clone)]
#[command(after_help = "DIR holds train/*.csv and test/*.csv loop logs \
(tools/benchmark/nanodrone.py --loop-out DIR). Each row's state and reference drive the \
controller, which keeps its integrators across rows and sub-steps at 500 Hz between them; \
R² compares its motor commands with the logged m*_thrust on the flown rows (all four commands \
above zero, not all at the idle floor; the controller is reset on entering them). --fit identifies mass_thrust, the attitude gains, the rate damping, the trims and \
a command delay on train/ only and reports test/ (melon) once with them.")]
pub struct OnboardArgs {
    /// The loop-log folder (train/ and test/ subfolders, or CSVs directly).
    #[arg(long, value_name = "LOOPDIR")]
    pub data: PathBuf,
    /// The controller configuration (JSON, `OnboardConfig`); default: the firmware 2025.09
    /// defaults for the cf21bl with the benchmark's idle floor 10000/65535.
    #[arg(long, value_name = "FILE.json")]
    pub config: Option<PathBuf>,
    /// Identify the parameters on the training flights and write them to --out.
    #[arg(long)]
    pub fit: bool,
    /// Where --fit writes the identified configuration.
    #[arg(long, value_name = "FILE.json")]
    pub out: Option<PathBuf>,
    /// Write the full report (R² per flight, the trust table, the fit) as JSON.
    #[arg(long, value_name = "FILE.json")]
    pub report: Option<PathBuf>,
    /// Controller steps per log row; 0 = the configuration's rate over the log's (500/100 = 5).
    #[arg(long, default_value_t = 0)]
    pub substeps: usize,
    /// The reference acceleration the logs lack: zero, or the central difference of the
    /// reference velocity.
    #[arg(long, value_enum, default_value_t = AccelSource::Diff)]
    pub accel: AccelSource,
    /// Half-width of that central difference, rows.
    #[arg(long, default_value_t = 2)]
    pub accel_span: usize,
    /// Compare the commands after a centred moving average over this many rows (both logged
    /// and replayed; ≤ 1: raw). The logged roll and pitch commands are mostly white at 100 Hz
    /// (lag-1 autocorrelation ≈ 0.4): the gyro noise the 500 Hz controller saw, which the
    /// 100 Hz log's state does not carry; the average keeps the band the log can explain.
    #[arg(long, default_value_t = 0)]
    pub smooth: usize,
    /// Also write, per flight, `DIR/RUN.csv` with the logged and the replayed commands per row
    /// (outside the repository: it is derived from the benchmark's data).
    #[arg(long, value_name = "DIR")]
    pub dump: Option<PathBuf>,
}

/// One flight's R².
#[derive(Clone, Debug, Serialize)]
pub struct FlightR2 {
    /// The run.
    pub name: String,
    /// `train` or `test`.
    pub split: String,
    /// R² over its flown rows.
    pub r2: R2Summary,
}

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct OnboardReport {
    /// The configuration replayed (after --fit: the identified one).
    pub config: OnboardConfig,
    /// The replay's options.
    pub options: ReplayOptions,
    /// Per flight.
    pub flights: Vec<FlightR2>,
    /// Pooled over the training flights.
    pub train: R2Summary,
    /// Pooled over the test flights (melon).
    pub test: Option<R2Summary>,
    /// With --fit: the defaults' pooled training R², for comparison.
    pub train_before_fit: Option<R2Summary>,
    /// With --fit: what it found.
    pub fit: Option<fit::FitResult>,
    /// The logged wrench columns' trust table (training flights pooled).
    pub trust: Vec<trust::ColumnTrust>,
}

fn read_split(dir: &Path) -> Result<Vec<(String, LoopFlight)>> {
    let mut out = Vec::new();
    let splits: Vec<&str> = ["train", "test"]
        .into_iter()
        .filter(|s| dir.join(s).is_dir())
        .collect();
    let folders: Vec<(String, PathBuf)> = if splits.is_empty() {
        vec![("train".into(), dir.to_path_buf())]
    } else {
        splits
            .iter()
            .map(|s| (s.to_string(), dir.join(s)))
            .collect()
    };
    for (split, folder) in folders {
        let mut files: Vec<PathBuf> = std::fs::read_dir(&folder)
            .with_context(|| format!("listing {}", folder.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "csv"))
            .collect();
        files.sort();
        for p in files {
            out.push((split.clone(), read_loop_csv(&p)?));
        }
    }
    if out.is_empty() {
        bail!("{}: no loop-log CSVs", dir.display());
    }
    Ok(out)
}

/// R² of one flight's replay over its flown rows.
#[allow(clippy::needless_range_loop)] // rows index four parallel columns
pub fn flight_r2(f: &LoopFlight, cfg: &OnboardConfig, opt: &ReplayOptions) -> (FitAcc, usize) {
    let pred = smooth(f, &replay(f, cfg, opt), opt.smooth_rows);
    let log = smooth(f, &f.cmd, opt.smooth_rows);
    let mut acc = FitAcc::default();
    let mut n = 0;
    for k in 0..f.len() {
        if active(f, k) {
            acc.add(&log[k], &pred[k]);
            n += 1;
        }
    }
    (acc, n)
}

fn evaluate(
    flights: &[(String, LoopFlight)],
    cfg: &OnboardConfig,
    opt: &ReplayOptions,
) -> (Vec<FlightR2>, R2Summary, Option<R2Summary>) {
    let mut per = Vec::new();
    let (mut tr, mut te) = (FitAcc::default(), FitAcc::default());
    let (mut ntr, mut nte) = (0, 0);
    for (split, f) in flights {
        let (acc, n) = flight_r2(f, cfg, opt);
        if split == "test" {
            te.merge(&acc);
            nte += n;
        } else {
            tr.merge(&acc);
            ntr += n;
        }
        per.push(FlightR2 {
            name: f.name.clone(),
            split: split.clone(),
            r2: acc.summary(n),
        });
    }
    let test = (nte > 0).then(|| te.summary(nte));
    (per, tr.summary(ntr), test)
}

/// Runs the subcommand.
#[allow(clippy::needless_range_loop)] // rows index four parallel columns
pub fn run(args: &OnboardArgs) -> Result<OnboardReport> {
    if args.fit && args.out.is_none() {
        bail!("--fit needs --out FILE.json for the identified configuration");
    }
    let mut cfg = match &args.config {
        Some(p) => OnboardConfig::load(p)?,
        None => OnboardConfig::cf21bl_2025_09(),
    };
    let flights = read_split(&args.data)?;
    let log_dt = flights
        .first()
        .map(|(_, f)| {
            let n = f.len().max(2);
            (f.t_s[n - 1] - f.t_s[0]) / (n - 1) as f64
        })
        .unwrap_or(0.01);
    let substeps = if args.substeps == 0 {
        (cfg.rate_hz * log_dt).round().max(1.0) as usize
    } else {
        args.substeps
    };
    let opt = ReplayOptions {
        substeps,
        accel: args.accel,
        accel_span: args.accel_span,
        smooth_rows: args.smooth,
    };
    let mut fit_result = None;
    let mut before = None;
    if args.fit {
        let train: Vec<LoopFlight> = flights
            .iter()
            .filter(|(s, _)| s == "train")
            .map(|(_, f)| f.clone())
            .collect();
        before = Some(evaluate(&flights, &cfg, &opt).1);
        let r = fit::fit(&train, &cfg, &opt);
        cfg = r.config;
        if let Some(out) = &args.out {
            cfg.save(out)?;
        }
        fit_result = Some(r);
    }
    let (per, train, test) = evaluate(&flights, &cfg, &opt);
    let train_flights: Vec<LoopFlight> = flights
        .iter()
        .filter(|(s, _)| s == "train")
        .map(|(_, f)| f.clone())
        .collect();
    let report = OnboardReport {
        config: cfg,
        options: opt,
        flights: per,
        train,
        test,
        train_before_fit: before,
        fit: fit_result,
        trust: trust::trust_table(&train_flights, true),
    };
    if let Some(p) = &args.report {
        write_json_atomic(p, &report)?;
    }
    if let Some(dir) = &args.dump {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for (_, f) in &flights {
            let pred = replay(f, &cfg, &opt);
            let mut text = String::from("t_s,active,log1,log2,log3,log4,pred1,pred2,pred3,pred4\n");
            for k in 0..f.len() {
                let (a, b) = (f.cmd[k].0, pred[k].0);
                text.push_str(&format!(
                    "{},{},{},{},{},{},{},{},{},{}\n",
                    f.t_s[k],
                    active(f, k) as u8,
                    a[0],
                    a[1],
                    a[2],
                    a[3],
                    b[0],
                    b[1],
                    b[2],
                    b[3]
                ));
            }
            crate::io::write_atomic(&dir.join(format!("{}.csv", f.name)), text.as_bytes())?;
        }
    }
    Ok(report)
}

/// The printed table.
pub fn table(r: &OnboardReport) -> String {
    let mut s = String::new();
    let line = |name: &str, split: &str, x: &R2Summary| {
        format!(
            "{name:28} {split:5} {:6} {:7.3} {:7.3} {:7.3} {:7.3} | {:6.3} {:6.3} {:6.3} {:6.3}\n",
            x.rows,
            x.r2_collective,
            x.r2_roll,
            x.r2_pitch,
            x.r2_yaw,
            x.r2_motor[0],
            x.r2_motor[1],
            x.r2_motor[2],
            x.r2_motor[3]
        )
    };
    s.push_str(&format!(
        "{:28} {:5} {:>6} {:>7} {:>7} {:>7} {:>7} | {:>6} {:>6} {:>6} {:>6}\n",
        "flight", "split", "rows", "coll", "roll", "pitch", "yaw", "m1", "m2", "m3", "m4"
    ));
    for f in &r.flights {
        s.push_str(&line(&f.name, &f.split, &f.r2));
    }
    if let Some(b) = &r.train_before_fit {
        s.push_str(&line("ALL train (defaults)", "train", b));
    }
    s.push_str(&line("ALL train", "train", &r.train));
    if let Some(t) = &r.test {
        s.push_str(&line("ALL test", "test", t));
    }
    if let Some(f) = &r.fit {
        s.push_str(&format!(
            "fit on {} training rows, {} iterations, cost {:.4} -> {:.4}; delay {:.0} ms\n",
            f.rows,
            f.iterations,
            f.cost_start,
            f.cost_end,
            f.cmd_delay_s * 1e3
        ));
        for (n, v) in &f.params {
            s.push_str(&format!("  {n:12} {v:.4}\n"));
        }
    }
    s.push_str("logged columns (training flights):\n");
    for t in r.trust.iter().filter(|t| t.column.ends_with("(all)")) {
        s.push_str(&format!("  {:32} {}\n", t.column, t.verdict));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::onboard::{Mellinger, OnboardLaw};
    use crate::io::{MotorCommands, OnboardSetpoint, OnboardState};
    use nalgebra::{UnitQuaternion, Vector3};

    /// A synthetic loop log whose commands are the port's own (defaults, one step per row).
    fn synthetic(cfg: &OnboardConfig) -> LoopFlight {
        let mut law = Mellinger::new(*cfg);
        let mut f = LoopFlight {
            name: "synthetic".into(),
            ..LoopFlight::default()
        };
        for k in 0..800 {
            let t = k as f64 * 0.01;
            let s = OnboardState {
                p_m: Vector3::new(
                    0.3 * (0.9 * t).sin(),
                    0.2 * (1.3 * t).cos(),
                    1.0 + 0.1 * t.sin(),
                ),
                v_m_s: Vector3::new(
                    0.27 * (0.9 * t).cos(),
                    -0.26 * (1.3 * t).sin(),
                    0.1 * t.cos(),
                ),
                q: UnitQuaternion::from_euler_angles(
                    0.05 * (2.0 * t).sin(),
                    0.04 * (1.7 * t).cos(),
                    0.1 * (0.5 * t).sin(),
                ),
                w_body_rad_s: Vector3::new(0.1 * (2.0 * t).cos(), -0.07 * (1.7 * t).sin(), 0.05),
            };
            let sp = OnboardSetpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0);
            let c = law.step(&s, &sp, 0.01);
            f.t_s.push(t);
            f.state.push(s);
            f.setpoint.push(sp);
            f.cmd.push(MotorCommands(c.0));
            f.erpm.push([0.0; 4]);
            f.vbat_v.push(4.0);
        }
        f
    }

    #[test]
    fn replay_reproduces_its_own_commands_and_the_fit_recovers_a_gain() {
        let cfg = OnboardConfig::cf21bl_2025_09();
        let f = synthetic(&cfg);
        let opt = ReplayOptions {
            substeps: 1,
            accel: AccelSource::Zero,
            accel_span: 1,
            smooth_rows: 0,
        };
        let (acc, n) = flight_r2(&f, &cfg, &opt);
        let s = acc.summary(n);
        assert_eq!(n, 800);
        assert!(
            s.r2_collective > 0.999_999 && s.r2_roll > 0.999_999,
            "{s:?}"
        );
        // Start the fit from a wrong mass_thrust and wrong attitude gains.
        let mut start = cfg;
        start.mass_thrust = 110_000.0;
        start.gains.kr_xy = 50_000.0;
        let r = fit::fit(std::slice::from_ref(&f), &start, &opt);
        let rel = (r.config.mass_thrust - 132_000.0).abs() / 132_000.0;
        assert!(rel < 0.01, "mass_thrust {}: {r:?}", r.config.mass_thrust);
        assert!(
            (r.config.gains.kr_xy - 70_000.0).abs() < 3_500.0,
            "kr_xy {}",
            r.config.gains.kr_xy
        );
        assert!(
            r.cost_end < 1e-3 * r.cost_start,
            "{} -> {}",
            r.cost_start,
            r.cost_end
        );
    }
}
