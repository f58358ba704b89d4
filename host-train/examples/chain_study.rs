//! The sensor chain's table: every core controller on the Crazyflie-chain scenarios
//! (`scenarios/cf-*.toml`), with the attitude oscillation, saturation, the estimate's bias and
//! the tracking error.
//!
//! `cargo run --release -p host-train --example chain_study -- [SCENARIO.toml ...]`
//! (default: every `scenarios/cf-*.toml`). `--controllers a,b` picks controllers; `--lag-ms N`
//! overrides the scenarios' motor lag; `--truth` flies the same scenarios without the chain.

use hamflight::model::NominalModel;
use hamflight::{Gains, VehicleFacts};
use host_train::control::{by_name, load_learned, Controller, CoreController, DEFAULT_WEIGHTS};
use host_train::fly::{fly_scenario, Report};
use host_train::sim::Scenario;
use host_train::{ControllerSpec, ModelSource};
use std::path::PathBuf;

/// Gain overrides for experiments (`--set key=value`).
#[derive(Default, Clone)]
struct Overrides(Vec<(String, f32)>);

impl Overrides {
    fn apply(&self, g: &mut Gains) {
        for (k, v) in &self.0 {
            match k.as_str() {
                "k_r" => g.k_r = *v,
                "k_w" => g.k_w = *v,
                "k_p" => g.k_p = *v,
                "k_v" => g.k_v = *v,
                "lag_tau" => g.lag.motor_tau_s = *v,
                "lag_target" => g.lag.target_tau_s = *v,
                "vc_tau" => g.velocity_consistency_tau_s = *v,
                "motor_tau" => g.composite.motor_tau_s = *v,
                "c_p" => g.rates.c_p = *v,
                "c_v" => g.rates.c_v = *v,
                "c_r" => g.rates.c_r = *v,
                "c_w" => g.rates.c_w = *v,
                "q_t" => g.composite.q_torque = *v,
                "accel_lag" => g.composite.accel_lag_s = *v,
                "gyro_lag" => g.composite.gyro_lag_s = *v,
                "trs" => g.composite.torque_rate_scale = *v,
                "filter_tau" => g.composite.torque_filter_tau_s = *v,
                "r_t" => g.composite.r_torque = *v,
                "q_f" => g.composite.q_force = *v,
                "r_f" => g.composite.r_force = *v,
                "filter_f" => g.composite.filter_tau_s = *v,
                "q" => {
                    g.composite.q_force = *v;
                    g.composite.q_torque = *v
                }
                _ => panic!("unknown override {k}"),
            }
        }
    }
}

/// `--weights PATH`: the blob the learned controllers fly (default: the shipped one).
static WEIGHTS: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();

fn weights() -> PathBuf {
    WEIGHTS
        .get()
        .cloned()
        .unwrap_or_else(|| PathBuf::from(DEFAULT_WEIGHTS))
}

fn build(name: &str, sc: &Scenario, o: &Overrides, facts_tau: Option<f32>) -> Box<dyn Controller> {
    if o.0.is_empty() && facts_tau.is_none() && WEIGHTS.get().is_none() {
        return by_name(name, sc, None).expect("controller");
    }
    let spec = ControllerSpec::parse(name).expect("controller name");
    let mk = |model_facts: VehicleFacts| {
        let mut f = model_facts;
        if let Some(t) = facts_tau {
            f.motor_tau_s = t;
        }
        let mut g = spec.gains(Gains::for_vehicle(&f));
        o.apply(&mut g);
        g
    };
    match spec.model() {
        Some(ModelSource::Learned) => {
            let m = load_learned(&weights()).expect("blob");
            let g = mk(VehicleFacts::of(&m));
            Box::new(CoreController::new(name, m, g))
        }
        Some(ModelSource::Nominal) => {
            let m = NominalModel::default();
            let g = mk(VehicleFacts::of(&m));
            Box::new(CoreController::new(name, m, g))
        }
        None => by_name(name, sc, None).expect("controller"),
    }
}

fn main() -> anyhow::Result<()> {
    let mut files: Vec<PathBuf> = Vec::new();
    let mut controllers: Vec<String> = [
        "adaptive",
        "learned",
        "geometric-adaptive",
        "ida-pbc",
        "adaptive-composite",
        "geometric-adaptive-composite",
    ]
    .map(String::from)
    .to_vec();
    let mut lag_ms: Option<f64> = None;
    let mut truth = false;
    let mut trace = false;
    let mut margins = false;
    let mut o = Overrides::default();
    let mut facts_tau: Option<f32> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--controllers" => {
                controllers = args
                    .next()
                    .unwrap_or_default()
                    .split(',')
                    .map(String::from)
                    .collect()
            }
            "--lag-ms" => lag_ms = args.next().and_then(|s| s.parse().ok()),
            "--truth" => truth = true,
            "--weights" => {
                let w = args.next().map(PathBuf::from).expect("--weights PATH");
                WEIGHTS.set(w).ok();
            }
            "--trace" => trace = true,
            "--margins" => margins = true,
            "--facts-tau-ms" => {
                facts_tau = args
                    .next()
                    .and_then(|s| s.parse::<f32>().ok())
                    .map(|x| x / 1000.0)
            }
            "--set" => {
                let kv = args.next().unwrap_or_default();
                let (k, v) = kv.split_once('=').expect("key=value");
                o.0.push((k.to_string(), v.parse().expect("number")));
            }
            _ => files.push(PathBuf::from(a)),
        }
    }
    if files.is_empty() {
        let mut v: Vec<PathBuf> = std::fs::read_dir("scenarios")?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("cf-") && n.ends_with(".toml"))
            })
            .collect();
        v.sort();
        files = v;
    }
    println!("| scenario | controller | crashed | RMSE t ≥ 5 s (cm) | att σ (deg) | saturated (%) | est. bias (cm) | mean error (cm) |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for f in &files {
        let mut sc = Scenario::load(f)?;
        if let Some(l) = lag_ms {
            sc.spec.effects.motor_tau_s = l / 1000.0;
        }
        if truth {
            sc.spec.sensors = None;
        }
        for c in &controllers {
            let mut ctrl = build(c, &sc, &o, facts_tau);
            if margins {
                use host_train::fly::{margins_of, measure_point, LoopPoint};
                for point in [LoopPoint::Roll, LoopPoint::X] {
                    let sweep = point
                        .default_frequencies_hz()
                        .into_iter()
                        .map(|f| {
                            measure_point(&sc, ctrl.as_mut(), point, f, point.default_amplitude())
                        })
                        .collect();
                    let m = margins_of(sweep);
                    println!(
                        "margins {} {c} {point:?}: crossover {:?} Hz PM {:?} GM {:?} dB",
                        sc.name,
                        m.crossover_hz.map(|x| (x * 100.0).round() / 100.0),
                        m.phase_margin_deg.map(|x| (x * 10.0).round() / 10.0),
                        m.gain_margin_db.map(|x| (x * 10.0).round() / 10.0)
                    );
                }
                continue;
            }
            let log = fly_scenario(&sc, ctrl.as_mut());
            let r = Report::from_flight(&log, &sc, None);
            for e in &r.events {
                println!(
                    "event {} {c} t {:.1} s: peak {:.2} cm, recovery {:?} s, RMSE after {:?} cm",
                    sc.name,
                    e.t_s,
                    100.0 * e.peak_err_m,
                    e.recovery_s.map(|x| (x * 100.0).round() / 100.0),
                    e.rmse_after_m.map(|x| (x * 1e4).round() / 100.0)
                );
            }
            if trace {
                for (i, t) in log.t_s.iter().enumerate().step_by(100) {
                    let a = log.adaptation.get(i).cloned().unwrap_or_default();
                    println!(
                        "t {t:5.2} rpy {:?} p {:?} a {:?}",
                        log.rpy_rad[i].map(|x| (x.to_degrees() * 100.0).round() / 100.0),
                        log.p_m[i].map(|x| (x * 1000.0).round() / 1000.0),
                        a.iter()
                            .map(|x| (x * 100.0).round() / 100.0)
                            .collect::<Vec<_>>()
                    );
                }
            }
            let norm = |v: Option<[f64; 3]>| {
                v.map_or("—".into(), |v| {
                    format!("{:.2}", 100.0 * (v[0] * v[0] + v[1] * v[1]).sqrt())
                })
            };
            println!(
                "| {} | {} | {} | {} | {} | {:.2} | {} | {} |",
                sc.name,
                c,
                r.crash_time_s
                    .map_or("no".into(), |t| format!("at {t:.2} s")),
                r.rmse_pos_window_m
                    .filter(|_| !r.crashed)
                    .map_or("—".into(), |x| format!("{:.4}", 100.0 * x)),
                r.att_std_deg.map_or("—".into(), |x| format!("{x:.3}")),
                100.0 * r.saturated_fraction,
                norm(r.est_pos_bias_m),
                norm(r.pos_err_mean_m),
            );
        }
    }
    Ok(())
}
