//! Closed-loop replay: a candidate plant (any scenario's vehicle, or a blob's model:
//! [`super::plant`]) flown by the onboard
//! controller ([`crate::control::onboard`]) along a logged flight's reference, started from the
//! logged state, and compared with what the vehicle flew. The controller is known, the reference
//! is exogenous, so the plant that replays the logs best is the one the data pick (the indirect
//! approach to closed-loop identification).

use super::plant::Replayable;
use crate::control::onboard::{Mellinger, OnboardConfig, OnboardLaw};
use crate::io::{LoopFlight, MotorCommands, OnboardSetpoint, OnboardState};
use crate::pipeline::onboard::replay::{active, lerp_state, setpoints, ReplayOptions};
use crate::sim::plant::PlantState;
use anyhow::{bail, Result};
use nalgebra::UnitQuaternion;
use serde::{Deserialize, Serialize};

/// Electrical rpm per mechanical rpm of the Crazyflie 2.1 Brushless motors (12 poles, 6 pairs).
pub const ERPM_PER_RPM: f64 = 6.0;

/// A logged row counts as airborne above this height (m): below it the vehicle may touch the
/// floor, which no plant here models.
pub const AIRBORNE_Z_M: f64 = 0.15;

/// A replay whose position leaves the log by more than this (m) has diverged; its remaining
/// steps count at this error (and at [`DIVERGED_ATT_RAD`]).
pub const DIVERGED_POS_M: f64 = 1.0;

/// The attitude error a diverged replay's remaining steps count at (rad).
pub const DIVERGED_ATT_RAD: f64 = core::f64::consts::FRAC_PI_2;

/// The motors' command → speed map, rpm² = `offset_rpm2` + `rpm2_per_cmd` · command, fitted by
/// least squares on the flown rows' measured speeds (eRPM / 6).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RotorMap {
    /// rpm² at zero command.
    pub offset_rpm2: f64,
    /// rpm² per unit of normalized command.
    pub rpm2_per_cmd: f64,
}

impl RotorMap {
    /// The least-squares map over the flown rows of `flights` with finite speeds.
    ///
    /// # Errors
    /// Fewer than 100 usable samples, or commands with no spread.
    pub fn fit(flights: &[&LoopFlight]) -> Result<Self> {
        let (mut sx, mut sy, mut sxx, mut sxy, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for f in flights {
            for k in 0..f.len() {
                if !active(f, k) {
                    continue;
                }
                for (x, e) in f.cmd[k].0.iter().zip(&f.erpm[k]) {
                    let r = e / ERPM_PER_RPM;
                    if r.is_finite() {
                        let y = r * r;
                        sx += x;
                        sy += y;
                        sxx += x * x;
                        sxy += x * y;
                        n += 1.0;
                    }
                }
            }
        }
        let den = n * sxx - sx * sx;
        if n < 100.0 || den.abs() < 1e-12 {
            bail!("too few flown rows with measured rotor speeds to fit the command → speed map ({n} samples)");
        }
        let b = (n * sxy - sx * sy) / den;
        Ok(Self {
            offset_rpm2: (sy - b * sx) / n,
            rpm2_per_cmd: b,
        })
    }

    /// The rotor speeds (rpm) the commands ask for.
    pub fn rpm(&self, c: &MotorCommands) -> [f64; 4] {
        c.0.map(|x| (self.offset_rpm2 + self.rpm2_per_cmd * x).max(0.0).sqrt())
    }
}

/// How the replay flies: the controller, the motor map, the reference options and the warm-up.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct ReplayConfig {
    /// The onboard controller's configuration.
    pub controller: OnboardConfig,
    /// Commands to rotor speeds.
    pub map: RotorMap,
    /// Sub-steps per log row and the reference acceleration.
    pub options: ReplayOptions,
    /// Rows before a window's start over which the controller runs on the logged states, so its
    /// integrators hold what the vehicle's did (0: start them at zero).
    pub warmup_rows: usize,
}

/// Whether row `k` is flown and airborne.
pub fn airborne(f: &LoopFlight, k: usize) -> bool {
    active(f, k) && f.state.get(k).is_some_and(|s| s.p_m.z > AIRBORNE_Z_M)
}

fn plant_state(s: &OnboardState) -> PlantState {
    let rot = s.q.to_rotation_matrix().into_inner();
    PlantState {
        p_m: s.p_m,
        rot,
        v_body_m_s: rot.transpose() * s.v_m_s,
        w_body_rad_s: s.w_body_rad_s,
    }
}

fn onboard_state(s: &PlantState) -> OnboardState {
    OnboardState {
        p_m: s.p_m,
        v_m_s: s.rot * s.v_body_m_s,
        q: UnitQuaternion::from_matrix(&s.rot),
        w_body_rad_s: s.w_body_rad_s,
    }
}

/// What one replay flew: the states at rows `k0 + 1 ..= k0 + states.len()`.
#[derive(Clone, Debug, Default)]
pub struct Flown {
    /// The row it started from.
    pub start: usize,
    /// The replayed states, one per row after the start.
    pub states: Vec<OnboardState>,
    /// Whether it left the log by more than [`DIVERGED_POS_M`] (the states stop there).
    pub diverged: bool,
}

fn dt_sub(f: &LoopFlight, cfg: &ReplayConfig) -> f64 {
    let dt_row = if f.len() > 1 {
        (f.t_s[f.len() - 1] - f.t_s[0]) / (f.len() - 1) as f64
    } else {
        0.01
    };
    dt_row / cfg.options.substeps.max(1) as f64
}

/// The controller run over row `k` on the logged states interpolated between rows, as the
/// vehicle's controller saw them at its own rate (held states would make its rate derivative
/// kick at every row).
fn warm_row(
    law: &mut Mellinger,
    f: &LoopFlight,
    sps: &[OnboardSetpoint],
    k: usize,
    sub: usize,
    dt: f64,
) {
    for j in 0..sub {
        let st = lerp_state(&f.state[k], &f.state[k + 1], j as f64 / sub as f64);
        law.step(&st, &sps[k], dt);
    }
}

/// The controller as it stood at row `k0`: run on the logged states of the `warmup_rows`
/// flown rows before it (back to the start of the flown stretch at most).
pub fn warm_up(
    f: &LoopFlight,
    sps: &[OnboardSetpoint],
    cfg: &ReplayConfig,
    k0: usize,
) -> Mellinger {
    let (sub, dt) = (cfg.options.substeps.max(1), dt_sub(f, cfg));
    let mut law = Mellinger::new(cfg.controller);
    law.reset();
    let mut a = k0;
    while a > 0 && k0 - a < cfg.warmup_rows && active(f, a - 1) {
        a -= 1;
    }
    for k in a..k0 {
        warm_row(&mut law, f, sps, k, sub, dt);
    }
    law
}

/// [`warm_up`] at each of `starts` (ascending), in one pass over the flight where the warm-up
/// reaches back to the start of the flown stretch (the default), else window by window. The
/// warm-up depends on the log only, so a fit computes it once for all its candidate plants.
pub fn warm_ups(
    f: &LoopFlight,
    sps: &[OnboardSetpoint],
    cfg: &ReplayConfig,
    starts: &[usize],
) -> Vec<Mellinger> {
    let (sub, dt) = (cfg.options.substeps.max(1), dt_sub(f, cfg));
    let mut out = Vec::with_capacity(starts.len());
    let mut law = Mellinger::new(cfg.controller);
    law.reset();
    let mut seg_start = 0;
    let mut k = 0;
    for &k0 in starts {
        while k < k0 {
            if active(f, k) {
                warm_row(&mut law, f, sps, k, sub, dt);
            } else {
                law = Mellinger::new(cfg.controller);
                law.reset();
                seg_start = k + 1;
            }
            k += 1;
        }
        if k0 - seg_start <= cfg.warmup_rows {
            out.push(law.clone());
        } else {
            out.push(warm_up(f, sps, cfg, k0));
        }
    }
    out
}

/// Flies `plant` from the logged state at row `k0` for `steps` rows under the controller along
/// `sps` (the reference with its acceleration, [`setpoints`]). The controller first runs on the
/// logged states of the `warmup_rows` flown rows before `k0`.
pub fn fly<P: Replayable + ?Sized>(
    f: &LoopFlight,
    sps: &[OnboardSetpoint],
    plant: &P,
    cfg: &ReplayConfig,
    k0: usize,
    steps: usize,
) -> Flown {
    fly_warm(f, sps, plant, cfg, warm_up(f, sps, cfg, k0), k0, steps)
}

/// [`fly`] with the controller already warmed up at `k0` ([`warm_up`]).
#[allow(clippy::needless_range_loop)] // rows index the log, the reference and the states together
pub fn fly_warm<P: Replayable + ?Sized>(
    f: &LoopFlight,
    sps: &[OnboardSetpoint],
    plant: &P,
    cfg: &ReplayConfig,
    mut law: Mellinger,
    k0: usize,
    steps: usize,
) -> Flown {
    let (sub, dt) = (cfg.options.substeps.max(1), dt_sub(f, cfg));
    let measured = start_rpm(f, k0);
    let start_rpm = if measured.iter().all(|r| r.is_finite()) {
        measured
    } else {
        cfg.map.rpm(&f.cmd[k0])
    };
    let mut p = plant.start(plant_state(&f.state[k0]), start_rpm);
    let mut out = Flown {
        start: k0,
        ..Flown::default()
    };
    for k in k0..(k0 + steps).min(f.len().saturating_sub(1)) {
        for _ in 0..sub {
            let st = onboard_state(p.state());
            let c = law.step(&st, &sps[k], dt);
            p.step(cfg.map.rpm(&c), dt);
        }
        let s = onboard_state(p.state());
        let bad = !p.state().is_finite() || (s.p_m - f.state[k + 1].p_m).norm() > DIVERGED_POS_M;
        if bad {
            out.diverged = true;
            break;
        }
        out.states.push(s);
    }
    out
}

/// Logged speeds above this (eRPM) are telemetry glitches: the motors reach about 1.45e5.
pub const MAX_ERPM: f64 = 1.6e5;

/// Rows either side of a window's start over which the logged rotor speeds are averaged.
pub const START_RPM_HALF_ROWS: usize = 2;

/// The rotor speeds a replay starts from: the logged ones (eRPM / 6) averaged over
/// ±[`START_RPM_HALF_ROWS`] rows, glitches left out. The telemetry's noise (several percent of
/// hover) would otherwise kick every window, and bias a fit that the windows' errors drive.
pub fn start_rpm(f: &LoopFlight, k0: usize) -> [f64; 4] {
    let a = k0.saturating_sub(START_RPM_HALF_ROWS);
    let b = (k0 + START_RPM_HALF_ROWS).min(f.len().saturating_sub(1));
    let mut sum = [0.0; 4];
    let mut n = 0.0;
    for e in f.erpm.get(a..=b).unwrap_or(&[]) {
        if e.iter().all(|x| x.is_finite() && *x < MAX_ERPM) {
            for (s, x) in sum.iter_mut().zip(e) {
                *s += x / ERPM_PER_RPM;
            }
            n += 1.0;
        }
    }
    if n > 0.0 {
        sum.map(|s| s / n)
    } else {
        [f64::NAN; 4]
    }
}

/// Squared errors pooled over replays.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorAcc {
    /// Replays pooled.
    pub windows: usize,
    /// Replays that diverged.
    pub diverged: usize,
    /// Steps pooled.
    pub steps: usize,
    /// Σ |p − p_log|² (m²).
    pub pos_sq_m2: f64,
    /// Σ angle(q, q_log)² (rad²).
    pub att_sq_rad2: f64,
}

impl ErrorAcc {
    /// Adds one replay of `steps` rows started at `k0`; a diverged one's missing steps count at
    /// the caps.
    pub fn add(&mut self, f: &LoopFlight, k0: usize, steps: usize, flown: &Flown) {
        self.windows += 1;
        for (j, s) in flown.states.iter().enumerate() {
            let log = &f.state[k0 + 1 + j];
            self.pos_sq_m2 += (s.p_m - log.p_m).norm_squared();
            self.att_sq_rad2 += s.q.angle_to(&log.q).powi(2);
        }
        self.steps += flown.states.len();
        if flown.diverged {
            self.diverged += 1;
            let miss = steps.saturating_sub(flown.states.len());
            self.pos_sq_m2 += miss as f64 * DIVERGED_POS_M.powi(2);
            self.att_sq_rad2 += miss as f64 * DIVERGED_ATT_RAD.powi(2);
            self.steps += miss;
        }
    }

    /// Pools another accumulator in.
    pub fn merge(&mut self, o: &ErrorAcc) {
        self.windows += o.windows;
        self.diverged += o.diverged;
        self.steps += o.steps;
        self.pos_sq_m2 += o.pos_sq_m2;
        self.att_sq_rad2 += o.att_sq_rad2;
    }

    /// Position RMSE (m); NaN with no steps.
    pub fn pos_rmse_m(&self) -> f64 {
        (self.pos_sq_m2 / self.steps as f64).sqrt()
    }

    /// Attitude RMSE (rad); NaN with no steps.
    pub fn att_rmse_rad(&self) -> f64 {
        (self.att_sq_rad2 / self.steps as f64).sqrt()
    }
}

/// The start rows of the `steps`-row windows of `f`, every `stride` rows, wholly airborne.
pub fn window_starts(f: &LoopFlight, steps: usize, stride: usize) -> Vec<usize> {
    let stride = stride.max(1);
    let mut out = Vec::new();
    let mut k0 = 0;
    while k0 + steps < f.len() {
        if (k0..=k0 + steps).all(|k| airborne(f, k)) {
            out.push(k0);
        }
        k0 += stride;
    }
    out
}

/// The pooled errors of `plant` over every `steps`-row window of `flights` (every `stride`
/// The windows of a set of flights with the controller warmed up at each start: what every
/// candidate plant is flown from.
pub struct Warmed<'a> {
    flights: Vec<WarmedFlight<'a>>,
    steps: usize,
}

struct WarmedFlight<'a> {
    f: &'a LoopFlight,
    sps: Vec<OnboardSetpoint>,
    starts: Vec<usize>,
    laws: Vec<Mellinger>,
}

impl<'a> Warmed<'a> {
    /// `steps`-row windows every `stride` rows of `flights`, warmed up.
    pub fn new(
        flights: &[&'a LoopFlight],
        cfg: &ReplayConfig,
        steps: usize,
        stride: usize,
    ) -> Self {
        let one = |f: &'a LoopFlight| {
            let sps = setpoints(f, &cfg.options);
            let starts = window_starts(f, steps, stride);
            let laws = warm_ups(f, &sps, cfg, &starts);
            WarmedFlight {
                f,
                sps,
                starts,
                laws,
            }
        };
        Self {
            flights: par_map(flights, &one),
            steps,
        }
    }

    /// `plant`'s pooled errors over the windows.
    pub fn score<P: Replayable + ?Sized>(&self, plant: &P, cfg: &ReplayConfig) -> ErrorAcc {
        let one = |w: &WarmedFlight| {
            let mut acc = ErrorAcc::default();
            for (k0, law) in w.starts.iter().zip(&w.laws) {
                let flown = fly_warm(w.f, &w.sps, plant, cfg, law.clone(), *k0, self.steps);
                acc.add(w.f, *k0, self.steps, &flown);
            }
            acc
        };
        let refs: Vec<&WarmedFlight> = self.flights.iter().collect();
        let mut total = ErrorAcc::default();
        for a in par_map(&refs, &|w: &WarmedFlight| one(w)) {
            total.merge(&a);
        }
        total
    }
}

/// `g` over `items` on up to 4 threads, in order.
fn par_map<T: Sync + Copy, R: Send>(items: &[T], g: &(impl Fn(T) -> R + Sync)) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get().min(4))
        .min(items.len().max(1));
    let mut out: Vec<Option<R>> = (0..items.len()).map(|_| None).collect();
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                s.spawn(move || {
                    items
                        .iter()
                        .enumerate()
                        .skip(t)
                        .step_by(threads)
                        .map(|(i, x)| (i, g(*x)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        for h in handles {
            if let Ok(v) = h.join() {
                for (i, r) in v {
                    out[i] = Some(r);
                }
            }
        }
    });
    out.into_iter().flatten().collect()
}

/// `plant`'s pooled errors over `steps`-row windows every `stride` rows of `flights`.
pub fn score_windows<P: Replayable + ?Sized>(
    flights: &[&LoopFlight],
    plant: &P,
    cfg: &ReplayConfig,
    steps: usize,
    stride: usize,
) -> ErrorAcc {
    Warmed::new(flights, cfg, steps, stride).score(plant, cfg)
}

/// The longest airborne stretch of `f`: (first row, rows).
pub fn longest_airborne(f: &LoopFlight) -> Option<(usize, usize)> {
    let mut best: Option<(usize, usize)> = None;
    let mut k = 0;
    while k < f.len() {
        if airborne(f, k) {
            let a = k;
            while k < f.len() && airborne(f, k) {
                k += 1;
            }
            if best.is_none_or(|(_, n)| k - a > n) {
                best = Some((a, k - a));
            }
        } else {
            k += 1;
        }
    }
    best
}
