//! Closed-loop evaluation: fly a scenario with a controller, log it, score it, plot it.
//!
//! The scores: [`Report`] (`report.json`, its keys in `fly/report.rs`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::control::controller::Controller;
pub use crate::fly::report::Report;
pub use crate::io::files::{write_atomic, write_json_atomic};
pub use crate::io::flightlog::FlightLog;
use crate::sim::plant::{Plant, PlantState};
use crate::sim::scenario::Scenario;
use crate::sim::trajectory::TrajectoryPoint;

/// Position error (m) above which a flight counts as crashed.
pub const CRASH_ERR_M: f64 = 1.0;
/// Start of the scoring window (s): RMSE after the adaptation transient.
pub const WINDOW_START_S: f64 = 5.0;

/// Seed offset of the accelerometer's noise stream.
const ACC_NOISE_STREAM: u64 = 0xACCE_1E20;

/// Fly `scenario` with `ctrl` (which is reset first). Stops early on a crash.
pub fn fly(scenario: &Scenario, ctrl: &mut dyn Controller) -> FlightLog {
    fly_with_progress(scenario, ctrl, None)
}

/// [`fly`], ticking an optional progress bar once per simulated second.
pub fn fly_with_progress(
    scenario: &Scenario,
    ctrl: &mut dyn Controller,
    progress: Option<&indicatif::ProgressBar>,
) -> FlightLog {
    fly_observed(scenario, ctrl, progress, |_, _, _| {})
}

/// The states of one flight beside its [`FlightLog`], one row per tick (as long as its `t_s`):
/// the true velocity and body rates (the true attitude is the log's `rpy_rad`), and the state
/// the controller was given. With a sensor chain (the scenario's `[sensors]`) that is the
/// estimator's p, v and R and the filtered gyro's ω, delayed as configured; without one, the
/// true state plus the scenario's `effects.noise` (the truth itself when that is off). At the
/// last tick (a crash's or the end's, which no control step follows) it is what the controller
/// would have been given.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct StateLog {
    /// True velocity (m/s, world).
    pub v_world_m_s: Vec<[f64; 3]>,
    /// True angular velocity ω (rad/s, body).
    pub w_body_rad_s: Vec<[f64; 3]>,
    /// The position the controller was given (m, world).
    pub est_p_m: Vec<[f64; 3]>,
    /// The velocity the controller was given (m/s, world).
    pub est_v_world_m_s: Vec<[f64; 3]>,
    /// The attitude the controller was given: roll, pitch, yaw (rad, Z-Y-X, as `rpy_rad`).
    pub est_rpy_rad: Vec<[f64; 3]>,
    /// The body rates the controller was given (rad/s, body).
    pub est_w_body_rad_s: Vec<[f64; 3]>,
}

impl StateLog {
    fn push_truth(&mut self, s: &PlantState) {
        self.v_world_m_s.push(s.v_world_m_s().into());
        self.w_body_rad_s.push(s.w_body_rad_s.into());
    }

    fn push_estimate(&mut self, s: &PlantState) {
        self.est_p_m.push(s.p_m.into());
        self.est_v_world_m_s.push(s.v_world_m_s().into());
        self.est_rpy_rad.push(s.rpy().into());
        self.est_w_body_rad_s.push(s.w_body_rad_s.into());
    }
}

/// [`fly`], also recording the flight's states ([`StateLog`]); the [`FlightLog`] is the same.
pub fn fly_with_states(scenario: &Scenario, ctrl: &mut dyn Controller) -> (FlightLog, StateLog) {
    let mut states = StateLog::default();
    let log = fly_controller(scenario, ctrl, None, |_, _, _| {}, Some(&mut states));
    (log, states)
}

/// The one SITL flight loop with a controller ([`fly`], [`fly_with_progress`], and `track`'s
/// [`super::track::track_disturbance`]): resets `ctrl`, then at every control tick measures (the
/// scenario's sensor chain, else its state and accelerometer noise on their own streams), steps
/// `ctrl` and the physics; stops early on a crash. After each control step, before the physics
/// steps, `on_tick(t, ctrl, plant)` sees the controller and the plant at tick time t.
pub fn fly_observed<C: Controller + ?Sized>(
    scenario: &Scenario,
    ctrl: &mut C,
    progress: Option<&indicatif::ProgressBar>,
    on_tick: impl FnMut(f64, &C, &Plant),
) -> FlightLog {
    fly_controller(scenario, ctrl, progress, on_tick, None)
}

/// What a [`Stage`] does until its next tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Actuation {
    /// Rotor speeds (rpm) the plant is driven with until the next tick.
    pub rpm: [f64; 4],
    /// Whether a rotor command sat at a limit (logged at control ticks).
    pub saturated: bool,
    /// The position the controller was given (m, world; logged at control ticks), if any.
    pub est_p_m: Option<[f64; 3]>,
}

/// Sensing, control and actuation from outside host-train, flown by the one loop
/// ([`fly_stage`]) in place of the scenario's sensors, a [`Controller`] and the rotor clamp:
/// at each of its ticks it reads the plant (its sensors' truth, e.g. the IMU's), estimates,
/// controls and says which rotor speeds to hold until its next tick. The plant and its
/// disturbances and faults, the log, crash detection and the scores stay the loop's.
/// (`tools/bitcraze-loop`: Bitcraze's filters, Kalman estimator, controllers and power
/// distribution at the stabilizer's 1 kHz.)
pub trait Stage {
    /// The controller's name, for the log.
    fn name(&self) -> &str;

    /// The stage's tick (Hz): a multiple of the scenario's control rate and a divisor of its
    /// physics rate (control rate × physics steps per control tick).
    fn tick_hz(&self) -> f64;

    /// The adaptation estimate logged at control ticks, if the controller adapts.
    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        None
    }

    /// Tick number `tick` (time `t_s` = tick / [`Stage::tick_hz`], which the plant is at) with
    /// the `reference` at that time; `control` is true on control ticks (every
    /// tick_hz / control_hz ticks from 0), which the loop logs. Not called on the last tick (the
    /// end's or a crash's).
    fn step(
        &mut self,
        tick: u64,
        t_s: f64,
        plant: &Plant,
        reference: &TrajectoryPoint,
        control: bool,
    ) -> Actuation;

    /// After each physics step (sensors sampled at the physics rate). Nothing by default.
    fn sampled(&mut self, plant: &Plant) {
        let _ = plant;
    }

    /// At the last tick (the end's or a crash's), which no step follows. Nothing by default.
    fn ended(&mut self, plant: &Plant) {
        let _ = plant;
    }
}

/// Fly `scenario` with an outside [`Stage`] in the one loop, at the stage's tick; stops early on
/// a crash (checked at every tick). Ticks count from 0 at t = 0, t = tick / tick_hz; the log has
/// the control ticks. Fails if the stage's tick does not divide the physics rate or is not a
/// multiple of the control rate.
pub fn fly_stage(scenario: &Scenario, stage: &mut dyn Stage) -> Result<FlightLog> {
    let clock = Clock::stage(scenario, stage.tick_hz())?;
    Ok(fly_loop(scenario, &clock, scenario.plant(), stage, None))
}

/// The loop's ticks: at the control rate (a controller), or at a [`Stage`]'s faster one.
struct Clock {
    /// The last tick (t = the scenario's duration).
    n_ticks: u64,
    /// Ticks per control tick.
    control_every: u64,
    /// Physics steps per tick, each `dt_phys` long.
    nsub: usize,
    dt_phys: f64,
    physics_hz: f64,
    /// Ticks per progress-bar second.
    ticks_per_s: u64,
    time: TickTime,
}

/// How a tick's number becomes its time.
enum TickTime {
    /// t = tick · dt.
    Times(f64),
    /// t = tick / hz.
    Over(f64),
}

impl Clock {
    /// One tick per control tick (t = k · dt), the scenario's physics steps in between.
    fn control(scenario: &Scenario) -> Self {
        let dt = scenario.control_dt_s();
        let nsub = scenario.physics_substeps();
        let dt_phys = dt / nsub as f64;
        Self {
            n_ticks: (scenario.spec.duration_s / dt).round() as u64,
            control_every: 1,
            nsub,
            dt_phys,
            physics_hz: 1.0 / dt_phys,
            ticks_per_s: (1.0 / dt).round().max(1.0) as u64,
            time: TickTime::Times(dt),
        }
    }

    /// Ticks at `hz` (t = tick / hz), a multiple of the control rate dividing the physics rate.
    fn stage(scenario: &Scenario, hz: f64) -> Result<Self> {
        let control_hz = scenario.spec.control_hz;
        let physics_hz = control_hz * scenario.physics_substeps() as f64;
        let nsub = (physics_hz / hz).round() as usize;
        if nsub == 0 || (nsub as f64 * hz - physics_hz).abs() > 1e-6 {
            anyhow::bail!(
                "{}: physics at {physics_hz} Hz is not a multiple of the stage's {hz} Hz tick",
                scenario.name
            );
        }
        let control_every = (hz / control_hz).round() as u64;
        if control_every == 0 || (control_every as f64 * control_hz - hz).abs() > 1e-6 {
            anyhow::bail!(
                "{}: control at {control_hz} Hz does not divide the stage's {hz} Hz tick",
                scenario.name
            );
        }
        Ok(Self {
            n_ticks: (scenario.spec.duration_s * hz).round() as u64,
            control_every,
            nsub,
            dt_phys: 1.0 / physics_hz,
            physics_hz,
            ticks_per_s: hz.round().max(1.0) as u64,
            time: TickTime::Over(hz),
        })
    }

    fn t(&self, tick: u64) -> f64 {
        match self.time {
            TickTime::Times(dt) => tick as f64 * dt,
            TickTime::Over(hz) => tick as f64 / hz,
        }
    }
}

/// A [`Controller`] behind the scenario's sensors as a [`Stage`]: the sensor chain (sampled at
/// every physics step) when the scenario has one, else its state and accelerometer noise on
/// their own streams; the rotor clamp; `on_tick` and the [`StateLog`] when given.
struct Sensed<'a, C: ?Sized, F> {
    ctrl: &'a mut C,
    on_tick: F,
    states: Option<&'a mut StateLog>,
    chain: Option<crate::sim::sensors::SensorChain>,
    rng: ChaCha8Rng,
    rng_acc: ChaCha8Rng,
    dt: f64,
    max_rpm: f64,
    control_wall_s: f64,
}

impl<C: Controller + ?Sized, F: FnMut(f64, &C, &Plant)> Stage for Sensed<'_, C, F> {
    fn name(&self) -> &str {
        self.ctrl.name()
    }

    fn tick_hz(&self) -> f64 {
        1.0 / self.dt
    }

    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        self.ctrl.adaptation_estimate()
    }

    fn step(
        &mut self,
        _tick: u64,
        t: f64,
        plant: &Plant,
        r: &TrajectoryPoint,
        _control: bool,
    ) -> Actuation {
        let (meas, acc, est_p_m) = match self.chain.as_ref().and_then(|c| c.view()) {
            Some(view) => (view.state, view.acc_body_m_s2, Some(view.state.p_m.into())),
            None => (
                plant.measure(&mut self.rng),
                plant.measure_accelerometer(&mut self.rng_acc),
                None,
            ),
        };
        if let Some(s) = self.states.as_deref_mut() {
            s.push_truth(plant.state());
            s.push_estimate(&meas);
        }
        let c0 = Instant::now();
        let cmd = self.ctrl.step_measured(t, &meas, Some(&acc), r, self.dt);
        self.control_wall_s += c0.elapsed().as_secs_f64();
        let saturated = cmd
            .iter()
            .any(|&c| !(c > 0.0 && c < self.max_rpm * (1.0 - 1e-9)));
        let rpm = plant.params.clamp_rpm(cmd);
        (self.on_tick)(t, &*self.ctrl, plant);
        Actuation {
            rpm,
            saturated,
            est_p_m,
        }
    }

    fn sampled(&mut self, plant: &Plant) {
        if let Some(c) = self.chain.as_mut() {
            c.sample(plant);
        }
    }

    fn ended(&mut self, plant: &Plant) {
        if let Some(s) = self.states.as_deref_mut() {
            // What the controller would be given; the noise streams are not used again.
            let est = match self.chain.as_ref().and_then(|c| c.view()) {
                Some(view) => view.state,
                None => plant.measure(&mut self.rng),
            };
            s.push_truth(plant.state());
            s.push_estimate(&est);
        }
    }
}

/// [`fly_observed`], recording into `states` when given (which changes nothing else).
fn fly_controller<C: Controller + ?Sized>(
    scenario: &Scenario,
    ctrl: &mut C,
    progress: Option<&indicatif::ProgressBar>,
    on_tick: impl FnMut(f64, &C, &Plant),
    states: Option<&mut StateLog>,
) -> FlightLog {
    ctrl.reset();
    let clock = Clock::control(scenario);
    let plant = scenario.plant();
    // The Crazyflie's sensor chain and estimator, sampled at every physics step.
    let mut chain = scenario
        .spec
        .sensors
        .as_ref()
        .map(|s| crate::sim::sensors::SensorChain::new(s, plant.state(), 1.0 / clock.dt_phys));
    if let Some(c) = chain.as_mut() {
        c.sample(&plant);
    }
    let mut stage = Sensed {
        max_rpm: plant.params.max_rpm(),
        ctrl,
        on_tick,
        states,
        chain,
        rng: ChaCha8Rng::seed_from_u64(scenario.spec.seed),
        // The accelerometer's noise has its own stream, so the state noise is the same with or
        // without it.
        rng_acc: ChaCha8Rng::seed_from_u64(scenario.spec.seed ^ ACC_NOISE_STREAM),
        dt: scenario.control_dt_s(),
        control_wall_s: 0.0,
    };
    let mut log = fly_loop(scenario, &clock, plant, &mut stage, progress);
    log.control_wall_s = stage.control_wall_s;
    log
}

/// The one SITL flight loop: at every tick of `clock` sets the plant's time, logs (on control
/// ticks), checks for a crash, lets `stage` sense, control and actuate, and steps the physics;
/// stops early on a crash.
fn fly_loop<S: Stage + ?Sized>(
    scenario: &Scenario,
    clock: &Clock,
    mut plant: Plant,
    stage: &mut S,
    progress: Option<&indicatif::ProgressBar>,
) -> FlightLog {
    let wall0 = Instant::now();
    let mut log = FlightLog {
        scenario: scenario.name.clone(),
        controller: stage.name().to_string(),
        planned_duration_s: scenario.spec.duration_s,
        control_hz: scenario.spec.control_hz,
        physics_hz: clock.physics_hz,
        ..Default::default()
    };
    let mut last_rpm = [0.0; 4];
    let mut line = DelayLine::new(scenario, clock.dt_phys);
    let mut phys_step: u64 = 0;
    for k in 0..=clock.n_ticks {
        let t = clock.t(k);
        plant.set_t_s(t);
        let truth = *plant.state();
        let r = scenario.reference(t);
        let err = (truth.p_m - r.p_m).norm();
        let control = k % clock.control_every == 0;
        if control {
            log.t_s.push(t);
            log.p_m.push(truth.p_m.into());
            log.p_ref_m.push(r.p_m.into());
            log.err_m
                .push(if err.is_finite() { err } else { f64::INFINITY });
            log.adaptation
                .push(stage.adaptation_estimate().unwrap_or_default());
            log.rpy_rad.push(truth.rpy().into());
        }
        let err_ok = err.is_finite() && err <= CRASH_ERR_M;
        let crashed = !truth.is_finite() || !err_ok || truth.p_m.z < 0.0;
        if crashed || k == clock.n_ticks {
            stage.ended(&plant);
            if control {
                log.rpm.push(last_rpm);
            }
            if crashed {
                log.crash_time_s = Some(t);
            }
            break;
        }
        let act = stage.step(k, t, &plant, &r, control);
        last_rpm = act.rpm;
        if control {
            log.rpm.push(act.rpm);
            log.saturated.push(act.saturated);
            if let Some(p) = act.est_p_m {
                log.est_p_m.push(p);
            }
            log.control_steps += 1;
        }
        line.push(phys_step, act.rpm);
        for _ in 0..clock.nsub {
            let rpm = line.at(phys_step);
            phys_step += 1;
            plant.step(rpm, clock.dt_phys);
            stage.sampled(&plant);
        }
        if let Some(pb) = progress {
            if k % clock.ticks_per_s == 0 {
                pb.inc(1);
            }
        }
    }
    log.wall_s = wall0.elapsed().as_secs_f64();
    log
}

/// The added command delay and jitter of the scenario's effects (`command_delay_s`,
/// `command_jitter_s`): commands queued with the physics step they reach the plant at; with
/// neither, a pass-through (the command acts at once, as before).
struct DelayLine {
    delay_steps: u64,
    jitter_steps: u64,
    rng: ChaCha8Rng,
    /// Pending commands (physics step they act from, rpm), in order.
    queue: std::collections::VecDeque<(u64, [f64; 4])>,
    /// The command acting now (the first one until any arrives: the plant starts trimmed).
    current: Option<[f64; 4]>,
    last_due: u64,
}

/// The jitter's random stream (independent of the noise streams).
const JITTER_STREAM: u64 = 0x6a17_7e12_d31a_7000;

impl DelayLine {
    fn new(scenario: &Scenario, dt_phys: f64) -> Self {
        let e = &scenario.spec.effects;
        let steps = |s: f64| (s / dt_phys).round().max(0.0) as u64;
        Self {
            delay_steps: steps(e.command_delay_s),
            jitter_steps: steps(e.command_jitter_s),
            rng: ChaCha8Rng::seed_from_u64(scenario.spec.seed ^ JITTER_STREAM),
            queue: std::collections::VecDeque::new(),
            current: None,
            last_due: 0,
        }
    }

    /// The command given at physics step `now`.
    fn push(&mut self, now: u64, rpm: [f64; 4]) {
        use rand::Rng;
        let jitter = if self.jitter_steps > 0 {
            self.rng.gen_range(0..=self.jitter_steps)
        } else {
            0
        };
        let due = (now + self.delay_steps + jitter).max(self.last_due);
        self.last_due = due;
        if self.current.is_none() {
            self.current = Some(rpm);
        }
        self.queue.push_back((due, rpm));
    }

    /// The command acting at physics step `now`.
    fn at(&mut self, now: u64) -> [f64; 4] {
        while let Some(&(due, rpm)) = self.queue.front() {
            if due > now {
                break;
            }
            self.current = Some(rpm);
            self.queue.pop_front();
        }
        self.current.unwrap_or([0.0; 4])
    }
}

/// Arguments of `host-train eval`.
#[derive(Args, Debug, Clone)]
pub struct EvalArgs {
    /// Scenario TOML file to fly (see scenarios/*.toml for the keys).
    #[arg(long, value_name = "FILE")]
    pub scenario: PathBuf,
    /// Controller to fly (default: the scenario's `controller` key, else `geometric`).
    #[arg(long, value_name = "NAME", value_parser = crate::control::spec::parser())]
    pub controller: Option<String>,
    /// Weight blob of the learned model, for `learned` and `adaptive*`.
    #[arg(long, value_name = "FILE", default_value = crate::control::registry::DEFAULT_WEIGHTS)]
    pub weights: PathBuf,
    /// Output directory for report.json, path.svg and error.svg (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Also write the flight as a Bitcraze uSD-card deck log (version 2, the variables of
    /// tools/usd/config.txt at the control rate; see `usdrecord`), for `host-train import`.
    #[arg(long, value_name = "FILE")]
    pub log_usd: Option<PathBuf>,
}

/// Run `host-train eval`: fly, write `report.json`, `path.svg`, `error.svg`; return the report.
pub fn run(args: &EvalArgs) -> Result<Report> {
    let scenario = Scenario::load(&args.scenario)?;
    let name = args
        .controller
        .clone()
        .or_else(|| scenario.spec.controller.clone())
        .unwrap_or_else(|| "geometric".into());
    let mut ctrl = crate::control::registry::by_name(&name, &scenario, Some(&args.weights))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output directory `{}`", args.out.display()))?;
    let pb = indicatif::ProgressBar::new(scenario.spec.duration_s.ceil() as u64);
    pb.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} s simulated")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    pb.set_message(format!("{} / {}", scenario.name, name));
    let log = match &args.log_usd {
        Some(path) => {
            let params = scenario.plant().params.clone();
            let mut rec = crate::fly::usdrecord::UsdRecorder::new(ctrl.as_mut(), params);
            let log = fly_with_progress(&scenario, &mut rec, Some(&pb));
            rec.write(path)?;
            log
        }
        None => fly_with_progress(&scenario, ctrl.as_mut(), Some(&pb)),
    };
    pb.finish_and_clear();
    let report = Report::from_flight(&log, &scenario, Some(&args.scenario));
    write_json_atomic(&args.out.join("report.json"), &report)?;
    crate::report::plot::path_svg(&[(name.as_str(), &log)], &args.out.join("path.svg"))?;
    crate::report::plot::error_svg(&[(name.as_str(), &log)], &args.out.join("error.svg"))?;
    Ok(report)
}
