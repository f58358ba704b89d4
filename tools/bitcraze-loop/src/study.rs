//! The study: a 1 kHz stabilizer tick as on the Crazyflie (IMU sample, Bitcraze's filters, their
//! estimator task's iteration, the controller, their power distribution) as a stage of
//! host-train's one flight loop (`host_train::fly::fly_stage`: the SITL plant, its disturbances
//! and faults, the log, crash detection), and host-train's scores.

use std::collections::VecDeque;
use std::f64::consts::FRAC_1_SQRT_2;
use std::fmt::Write as _;

use anyhow::{Context, Result};
use hamflight::{Measurement, Setpoint, State};
use host_train::control::{core_by_name, CoreStep};
use host_train::fly::{fly_stage, Actuation, Report, Stage};
use host_train::io::FlightLog;
use host_train::sim::{gaussian, so3_exp, Plant, Scenario, SensorSpec, TrajectoryPoint};
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::ffi::{self, BcController, BcKind, BcPose, BcSetpoint, BcState, ImuFilter, Kalman};
use crate::{Args, StateSource};

/// The stabilizer's tick (Hz): IMU, estimator iteration, controller call, motors.
const TICK_HZ: f64 = 1000.0;
/// What 1 g is to Bitcraze's code (`GRAVITY_MAGNITUDE`): the accelerometer's unit.
const G_M_S2: f64 = 9.81;

/// Who flies: one of ours through the core, or one of Bitcraze's.
enum Pilot {
    Ours(Box<dyn CoreStep>),
    Bitcraze(BcController),
}

/// One flight's scores and the study-only extras.
#[derive(Clone, Debug, serde::Serialize)]
struct Flight {
    report: Report,
    /// The flight's log (written to `--out`, not to report.json).
    #[serde(skip)]
    log: FlightLog,
    /// Ticks on which the Kalman state left its bounds.
    estimator_out_of_bounds: u64,
}

fn rot_of(q: &[f32; 4]) -> Matrix3<f64> {
    let q = Quaternion::new(q[3] as f64, q[0] as f64, q[1] as f64, q[2] as f64);
    UnitQuaternion::from_quaternion(q)
        .to_rotation_matrix()
        .into_inner()
}

fn quat_of(r: &Matrix3<f64>) -> [f32; 4] {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(r));
    [q.i as f32, q.j as f32, q.k as f32, q.w as f32]
}

fn f32x3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

fn noise3(rng: &mut ChaCha8Rng, sigma: f64) -> Vector3<f64> {
    if sigma > 0.0 {
        Vector3::new(gaussian(rng), gaussian(rng), gaussian(rng)) * sigma
    } else {
        Vector3::zeros()
    }
}

/// The scenario with the Crazyflie's published rotor geometry, so that Bitcraze's power
/// distribution mixes for the plant it drives.
fn with_bitcraze_geometry(scenario: &Scenario, p: &ffi::Platform) -> Scenario {
    let mut s = scenario.clone();
    s.vehicle.arm_xy_m = p.arm_length_m as f64 * FRAC_1_SQRT_2;
    s.vehicle.km_nm_per_rpm2 = p.thrust_to_torque_m as f64 * s.vehicle.kf_n_per_rpm2;
    s
}

/// The true state in Bitcraze's `state_t` form (the legacy attitude angles as their
/// estimator writes them: pitch inverted).
fn bc_truth(s: &host_train::sim::PlantState, acc_world_g: Vector3<f64>) -> BcState {
    let rpy = s.rpy().map(f64::to_degrees);
    BcState {
        p_m: f32x3(&s.p_m),
        v_m_s: f32x3(&s.v_world_m_s()),
        q_xyzw: quat_of(&s.rot),
        rpy_deg: [rpy.x as f32, -rpy.y as f32, rpy.z as f32],
        acc_g: f32x3(&acc_world_g),
    }
}

/// The Crazyflie's stabilizer as a stage of host-train's one flight loop: at every 1 kHz tick
/// the IMU (our noise model) through Bitcraze's filters into their estimator task's iteration
/// (with the pose source), then the controller and Bitcraze's power distribution.
struct Stabilizer<'a> {
    name: &'a str,
    pilot: &'a mut Pilot,
    source: StateSource,
    spec: SensorSpec,
    kalman: Kalman,
    filter: ImuFilter,
    rng: ChaCha8Rng,
    /// Pose measurements in flight, with the tick they arrive at.
    poses: VecDeque<(u64, BcPose)>,
    /// The last `delay_samples + 1` estimates and filtered IMU readings.
    views: VecDeque<(BcState, [f32; 3], [f32; 3])>,
    motor_n: [f32; 4],
    capped: bool,
    /// Ticks on which the Kalman state left its bounds.
    out_of_bounds: u64,
    pose_every: u64,
    latency_ticks: u64,
    /// The control period our controllers are given (s).
    dt_ctrl: f64,
    kf: f64,
    max_rpm: f64,
}

impl<'a> Stabilizer<'a> {
    fn new(
        scenario: &Scenario,
        name: &'a str,
        pilot: &'a mut Pilot,
        source: StateSource,
    ) -> Result<Self> {
        let spec = scenario.spec.sensors.clone().unwrap_or_default();
        let plant = scenario.plant();
        let ctrl_every = (TICK_HZ / scenario.spec.control_hz).round() as u64;
        let s0 = *plant.state();
        let yaw0 = s0.rpy().z;
        let kalman = Kalman::new(0, f32x3(&s0.p_m), yaw0 as f32)?;
        let filter = ImuFilter::new(
            TICK_HZ as f32,
            spec.gyro_lpf_hz as f32,
            spec.acc_lpf_hz as f32,
        )?;
        Ok(Self {
            name,
            pilot,
            source,
            pose_every: (TICK_HZ / spec.pose_hz).round().max(1.0) as u64,
            latency_ticks: (spec.pose_latency_s * TICK_HZ).round() as u64,
            rng: ChaCha8Rng::seed_from_u64(spec.seed ^ scenario.spec.seed),
            spec,
            kalman,
            filter,
            poses: VecDeque::new(),
            views: VecDeque::new(),
            motor_n: [0.0; 4],
            capped: false,
            out_of_bounds: 0,
            dt_ctrl: ctrl_every as f64 / TICK_HZ,
            kf: plant.params.kf_n_per_rpm2,
            max_rpm: plant.params.max_rpm(),
        })
    }
}

impl Stage for Stabilizer<'_> {
    fn name(&self) -> &str {
        self.name
    }

    fn tick_hz(&self) -> f64 {
        TICK_HZ
    }

    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        match &*self.pilot {
            Pilot::Ours(c) => c.adaptation_estimate(),
            Pilot::Bitcraze(_) => None,
        }
    }

    fn step(
        &mut self,
        tick: u64,
        _t_s: f64,
        plant: &Plant,
        r: &TrajectoryPoint,
        control: bool,
    ) -> Actuation {
        let truth = *plant.state();
        let spec = &self.spec;
        // The IMU (our noise model), through Bitcraze's filters, into their estimator.
        let gyro = truth.w_body_rad_s
            + Vector3::from(spec.gyro_bias_rad_s)
            + noise3(&mut self.rng, spec.gyro_noise_rad_s);
        let acc = plant.accelerometer()
            + Vector3::from(spec.acc_bias_m_s2)
            + noise3(&mut self.rng, spec.acc_noise_m_s2);
        let mut acc_g = f32x3(&(acc / G_M_S2));
        let mut gyro_dps = f32x3(&gyro.map(f64::to_degrees));
        self.filter.apply(&mut acc_g, &mut gyro_dps);
        self.kalman.imu(&acc_g, &gyro_dps);
        if tick.is_multiple_of(self.pose_every) {
            let p = truth.p_m + noise3(&mut self.rng, spec.pose_pos_noise_m);
            let rot = truth.rot * so3_exp(&noise3(&mut self.rng, spec.pose_att_noise_rad));
            self.poses.push_back((
                tick + self.latency_ticks,
                BcPose {
                    p_m: f32x3(&p),
                    q_xyzw: quat_of(&rot),
                    std_pos_m: spec.ekf_pos_std_m as f32,
                    std_quat: spec.ekf_att_std_rad as f32,
                    with_attitude: spec.pose_attitude as i32,
                },
            ));
        }
        let pose = match self.poses.front() {
            Some((arrive, _)) if *arrive <= tick => self.poses.pop_front().map(|(_, p)| p),
            _ => None,
        };
        let (mut est, ok) = self.kalman.step(tick as u32, true, pose.as_ref());
        if !ok {
            self.out_of_bounds += 1;
        }
        if self.source == StateSource::Truth {
            est = bc_truth(&truth, Vector3::from(est.acc_g).cast::<f64>());
        }
        self.views.push_back((est, acc_g, gyro_dps));
        while self.views.len() > spec.delay_samples + 1 {
            self.views.pop_front();
        }
        let (seen, acc_seen, gyro_seen) = self.views[0];

        // The controller, then Bitcraze's power distribution.
        match &mut *self.pilot {
            Pilot::Bitcraze(c) => {
                let sp = BcSetpoint {
                    p_m: f32x3(&r.p_m),
                    v_m_s: f32x3(&r.v_m_s),
                    a_m_s2: f32x3(&r.a_m_s2),
                    j_m_s3: f32x3(&r.j_m_s3),
                    yaw_deg: r.yaw_rad.to_degrees() as f32,
                };
                self.capped = c.step(
                    &sp,
                    &acc_seen,
                    &gyro_seen,
                    &seen,
                    tick as u32,
                    &mut self.motor_n,
                );
            }
            Pilot::Ours(c) => {
                if control {
                    let rot = rot_of(&seen.q_xyzw);
                    let v_world = Vector3::from(seen.v_m_s).cast::<f64>();
                    let state = State {
                        p_m: Vector3::from(seen.p_m),
                        rot: rot.cast::<f32>(),
                        v_body_m_s: (rot.transpose() * v_world).cast::<f32>(),
                        w_body_rad_s: Vector3::from(gyro_seen).map(f32::to_radians),
                    };
                    let meas = Measurement {
                        acc_body_m_s2: Some(Vector3::from(acc_seen) * G_M_S2 as f32),
                    };
                    let out = c.core_step(&state, &Setpoint::from(r), &meas, self.dt_ctrl as f32);
                    // The command (with the motor-lag lead), as the Crazyflie app hands it over.
                    let w = out.command;
                    self.capped = ffi::power_force_torque(
                        w.thrust_n,
                        [w.torque_nm.x, w.torque_nm.y, w.torque_nm.z],
                        &mut self.motor_n,
                    );
                }
            }
        }
        let (kf, max_rpm) = (self.kf, self.max_rpm);
        Actuation {
            rpm: self
                .motor_n
                .map(|f| ((f.max(0.0) as f64) / kf).sqrt().min(max_rpm)),
            saturated: self.capped,
            est_p_m: Some(seen.p_m.map(f64::from)),
        }
    }
}

/// One flight of `pilot` through host-train's loop, behind the [`Stabilizer`].
fn fly(scenario: &Scenario, name: &str, pilot: &mut Pilot, source: StateSource) -> Result<Flight> {
    let mut stage = Stabilizer::new(scenario, name, pilot, source)?;
    let log = fly_stage(scenario, &mut stage)?;
    Ok(Flight {
        report: Report::from_flight(&log, scenario, scenario.path.as_deref()),
        log,
        estimator_out_of_bounds: stage.out_of_bounds,
    })
}

fn pilot(name: &str, args: &Args, mass_kg: f32) -> Result<Pilot> {
    Ok(match BcKind::by_name(name) {
        Some(kind) => Pilot::Bitcraze(BcController::new(kind, mass_kg)?),
        None => Pilot::Ours(
            core_by_name(name, Some(&args.weights))
                .with_context(|| format!("controller `{name}`"))?,
        ),
    })
}

fn cell(r: &Report) -> String {
    match (r.crash_time_s, r.rmse_pos_window_m) {
        (Some(t), _) => format!("crash at {t:.1} s"),
        (None, Some(e)) => format!("{:.2}", e * 100.0),
        (None, None) => "–".into(),
    }
}

/// A markdown table: one row per scenario, one column per controller, `f` of each flight.
fn table(
    md: &mut String,
    controllers: &[String],
    scenarios: &[Scenario],
    flights: &[Flight],
    f: impl Fn(&Report) -> String,
) -> std::fmt::Result {
    write!(md, "| scenario |")?;
    for c in controllers {
        write!(md, " `{c}` |")?;
    }
    write!(md, "\n| --- |")?;
    for _ in controllers {
        write!(md, " --- |")?;
    }
    writeln!(md)?;
    for (s, row) in scenarios
        .iter()
        .zip(flights.chunks(controllers.len().max(1)))
    {
        write!(md, "| {} |", s.name)?;
        for flight in row {
            write!(md, " {} |", f(&flight.report))?;
        }
        writeln!(md)?;
    }
    Ok(())
}

/// One flight's scores in `--scores`' file.
#[derive(serde::Serialize)]
struct Scores<'a> {
    scenario: &'a str,
    controller: &'a str,
    /// Position RMSE over t ≥ 5 s (m).
    rmse_pos_window_m: Option<f64>,
    max_err_m: f64,
    crash_time_s: Option<f64>,
    /// Largest roll/pitch standard deviation over t ≥ 5 s (deg).
    att_std_deg: Option<f64>,
    /// Fraction of control ticks whose power distribution capped.
    saturated_fraction: f64,
    /// Mean estimate − truth over t ≥ 5 s (m, world).
    est_pos_bias_m: Option<[f64; 3]>,
    /// Mean truth − reference over t ≥ 5 s (m, world).
    pos_err_mean_m: Option<[f64; 3]>,
    estimator_out_of_bounds: u64,
}

/// `--scores`: every flight's scores, without wall-clock times.
fn scores_json(
    args: &Args,
    commit: &str,
    platform: &ffi::Platform,
    scenarios: &[Scenario],
    flights: &[Flight],
) -> serde_json::Value {
    let rows: Vec<Scores> = flights
        .iter()
        .map(|f| {
            let r = &f.report;
            Scores {
                scenario: &r.scenario,
                controller: &r.controller,
                rmse_pos_window_m: r.rmse_pos_window_m,
                max_err_m: r.max_err_m,
                crash_time_s: r.crash_time_s,
                att_std_deg: r.att_std_deg,
                saturated_fraction: r.saturated_fraction,
                est_pos_bias_m: r.est_pos_bias_m,
                pos_err_mean_m: r.pos_err_mean_m,
                estimator_out_of_bounds: f.estimator_out_of_bounds,
            }
        })
        .collect();
    serde_json::json!({
        "tool": "tools/bitcraze-loop (regenerate: tools/bitcraze-loop/doc-data.sh)",
        "crazyflie_firmware_commit": commit,
        "platform": platform,
        "state": args.state,
        "controllers": args.controllers,
        "scenarios": scenarios.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(),
        "flights": rows,
    })
}

/// Flies every scenario with every controller and prints (and writes) the tables.
pub fn run(args: &Args) -> Result<()> {
    let platform = ffi::platform();
    let commit = env!("BITCRAZE_COMMIT");
    let mut scenarios = Vec::new();
    for path in &args.scenarios {
        let s = Scenario::load(path).with_context(|| format!("scenario `{path}`"))?;
        scenarios.push(with_bitcraze_geometry(&s, &platform));
    }
    for name in &args.controllers {
        pilot(name, args, hamflight::model::MASS_KG)?;
    }
    let mut flights: Vec<Flight> = Vec::new();
    for s in &scenarios {
        for name in &args.controllers {
            let mut p = pilot(name, args, s.vehicle.mass_kg as f32)?;
            let f = fly(s, name, &mut p, args.state)?;
            eprintln!(
                "{:<18} {:<22} {:>16} cm  att σ {:>5} deg  capped {:>5.1} %",
                s.name,
                name,
                cell(&f.report),
                f.report
                    .att_std_deg
                    .map_or("–".into(), |x| format!("{x:.2}")),
                f.report.saturated_fraction * 100.0
            );
            flights.push(f);
        }
    }
    let mut md = String::new();
    writeln!(
        md,
        "Position RMSE over t ≥ 5 s (cm), behind Bitcraze's filters, Kalman estimator and power \
         distribution (crazyflie-firmware {commit}; ARM_LENGTH {} m, THRUST_MAX {} N, \
         THRUST2TORQUE {}):\n",
        platform.arm_length_m, platform.thrust_max_n, platform.thrust_to_torque_m
    )?;
    table(&mut md, &args.controllers, &scenarios, &flights, cell)?;
    writeln!(
        md,
        "\nLargest roll/pitch standard deviation over t ≥ 5 s (deg) / ticks capped (%):\n"
    )?;
    table(&mut md, &args.controllers, &scenarios, &flights, |r| {
        let sd = r.att_std_deg.map_or("–".into(), |x| format!("{x:.2}"));
        format!("{sd} / {:.1}", r.saturated_fraction * 100.0)
    })?;
    print!("{md}");
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let report = serde_json::json!({
            "crazyflie_firmware_commit": commit,
            "platform": platform,
            "flights": flights,
        });
        host_train::io::write_atomic(
            &dir.join("report.json"),
            serde_json::to_string_pretty(&report)?.as_bytes(),
        )?;
        host_train::io::write_atomic(&dir.join("table.md"), md.as_bytes())?;
        let logs = dir.join("logs");
        std::fs::create_dir_all(&logs)?;
        for f in &flights {
            let file = logs.join(format!(
                "{}-{}.json",
                f.report.scenario, f.report.controller
            ));
            host_train::io::write_json_atomic(&file, &f.log)?;
        }
        eprintln!("wrote {}/report.json, table.md and logs/", dir.display());
    }
    if let Some(path) = &args.scores {
        let json = scores_json(args, commit, &platform, &scenarios, &flights);
        let mut text = serde_json::to_string_pretty(&json)?;
        text.push('\n');
        host_train::io::write_atomic(path, text.as_bytes())?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
