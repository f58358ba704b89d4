//! One cell of the robustness matrix with the motor-lag watch traced: when it switches and to
//! which lag, and the cell's score (docs/envelope.md, "The lag watch").
//!
//!     cargo run --release -p host-train --example lag_watch_trace -- \
//!         [SCENARIO] [LAW] [PLANT_LAG_MS] [BLOB_LAG_MS] [DELAY_MS] [JITTER_MS]
//!
//! Defaults: hover, adaptive, plant 80 ms, blob 0 ms, no delay, no jitter. The watch is on
//! (`Gains::lag_watch`) unless `NO_WATCH` is set; `TRACE=1` prints its scores every 50 ms;
//! `WEIGHTS=FILE.hfw` flies another blob (default weights/default.hfw).
use host_train::control::{gains_for, load_learned, Controller, ControllerSpec, CoreController};
use host_train::fly::{fly_scenario, FlightLog};
use host_train::pipeline::load_robustness_scenario;
use host_train::sim::{PlantState, TrajectoryPoint};
use std::path::Path;

/// The core controller, its lag recorded at every change.
struct Traced {
    inner: CoreController<hamflight::model::LearnedModel>,
    lag_s: f32,
    switches: Vec<(f64, f32)>,
}

impl Controller for Traced {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn reset(&mut self) {
        self.inner.reset();
    }
    fn step(&mut self, t: f64, s: &PlantState, r: &TrajectoryPoint, dt: f64) -> [f64; 4] {
        self.step_measured(t, s, None, r, dt)
    }
    fn step_measured(
        &mut self,
        t: f64,
        s: &PlantState,
        acc: Option<&nalgebra::Vector3<f64>>,
        r: &TrajectoryPoint,
        dt: f64,
    ) -> [f64; 4] {
        let rpm = self.inner.step_measured(t, s, acc, r, dt);
        let lag = self.inner.inner().motor_lag_s();
        let w = self.inner.inner().lag_watch();
        let k = (t / dt).round() as i64;
        if std::env::var_os("TRACE").is_some() && k % 25 == 0 {
            let u = w.unexplained();
            println!(
                "    {t:6.3} X {:.2e} shares {}",
                w.excitation_nm2(),
                u.iter()
                    .map(|x| format!("{x:.3}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
        }
        if lag != self.lag_s {
            self.switches.push((t, lag));
            self.lag_s = lag;
        }
        rpm
    }
}

fn main() -> anyhow::Result<()> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, d: &str| a.get(i).cloned().unwrap_or_else(|| d.to_owned());
    let num = |i: usize, d: &str| -> anyhow::Result<f64> { Ok(arg(i, d).parse()?) };
    let (stem, law) = (arg(0, "hover"), arg(1, "adaptive"));
    let (plant, blob, delay, jitter) = (num(2, "80")?, num(3, "0")?, num(4, "0")?, num(5, "0")?);
    let mut sc = load_robustness_scenario(Path::new("scenarios"), &stem, 0.0)?;
    sc.spec.effects.motor_tau_s = plant * 1e-3;
    sc.spec.effects.command_delay_s = delay * 1e-3;
    sc.spec.effects.command_jitter_s = jitter * 1e-3;
    let spec = ControllerSpec::parse_core(&law)?;
    let weights = std::env::var("WEIGHTS");
    let weights = weights
        .as_deref()
        .unwrap_or(host_train::control::DEFAULT_WEIGHTS);
    let mut model = load_learned(Path::new(weights))?;
    model.set_motor_tau_s((blob * 1e-3) as f32);
    let gains = hamflight::Gains {
        lag_watch: std::env::var_os("NO_WATCH").is_none(),
        ..spec.gains(gains_for(&model))
    };
    let lag_s = gains.composite.motor_tau_s;
    let mut c = Traced {
        inner: CoreController::new(spec.name, model, gains),
        lag_s,
        switches: Vec::new(),
    };
    let log: FlightLog = fly_scenario(&sc, &mut c);
    let max_rpm = sc.plant().params.max_rpm();
    let score = host_train::pipeline::robustness_score(&log, max_rpm);
    println!("{stem} {law}: plant {plant} ms, blob {blob} ms, delay {delay} + {jitter} ms");
    for (t, lag) in &c.switches {
        println!("  t = {t:6.3} s: lag watch -> {:.1} ms", lag * 1e3);
    }
    println!(
        "  RMSE {:.4} m, oscillation {:.3}, limit cycle {}, crash {:?}",
        score.rmse_m, score.oscillation, score.limit_cycle, log.crash_time_s
    );
    Ok(())
}
