//! The flight: the firmware started and answered, then the loop, one plant millisecond per IMU
//! packet (paced by the wall clock, or in lock-step with the firmware's tick): the parameters
//! set, the pilot's packets, the pose, the plant step, until the pilot's timeline ends; then the
//! flight's numbers.

use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::Parser;
use host_train::io::ext_pose_packet;
use host_train::{Plant, PlantState, Scenario};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

use crate::clock::Clock;
use crate::faults::Faults;
use crate::launch::Link;
use crate::motors::Motors;
use crate::params::Params;
use crate::pilot::{figure_pieces, Piloting};
use crate::plant::{delay_disturbances, Vehicle};
use crate::record::Sample;
use crate::summary::{self, Flown};
use crate::timeline::{Timeline, TrajRef};
use crate::Args;

pub fn run() -> Result<()> {
    let args = Args::parse();
    if !args.firmware.is_file() {
        bail!(
            "no firmware at {}: build it with tools/firmware-sitl/build.sh CHECKOUT",
            args.firmware.display()
        );
    }
    let scenario = Scenario::load(&args.scenario)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let hold_s = args.hold_s.unwrap_or(scenario.spec.duration_s);
    let target0 = scenario.reference(0.0);
    let yaw0 = target0.yaw_rad;

    let traj_pieces = figure_pieces(&args, yaw0)?;
    let mut piloting = Piloting::new(&args, &traj_pieces, target0.p_m, yaw0)?;
    let traj = TrajRef::new(traj_pieces, args.traj_time_scale, target0.p_m);
    let timeline = Timeline {
        args: &args,
        scenario: &scenario,
        hold_s,
        target0,
        traj,
    };

    let mut plant: Plant = scenario.plant();
    plant.set_state(PlantState::at_rest(timeline.ground_xy(), yaw0));
    plant.set_rotor_rpm([0.0; 4]);

    let mut link = Link::start(&args)?;
    let mut params = Params::new(&args, &plant);
    let mut motors = Motors::new(args.seed);
    let mut clock = Clock::new(&args, &link)?;

    // --- the loop: 1 ms of plant per IMU packet, paced at 1 kHz of wall clock (or lock-step) -
    let mut samples: Vec<Sample> = Vec::new();
    let mut vehicle = Vehicle::new(&plant);
    let mut faults = Faults::default();
    let mut stab_started_at: Option<f64> = None; // plant time
    let mut engage_at: Option<f64> = None;
    let mut hold_started_at: Option<f64> = None;
    let mut k: u64 = 0;
    let setpoint_every = ((1000.0 / args.setpoint_hz).round() as u64).max(1);
    let total_guard_s = 60.0
        + args.settle_s
        + args.takeoff_s
        + hold_s
        + args.land_s
        + args.linger_s
        + args.upload_s
        + timeline.traj.total_s;
    loop {
        let t = plant.t_s();
        let (mut pwm, motor_packets) = {
            let sh = link.shared.lock().unwrap();
            (sh.pwm, sh.motor_packets)
        };
        if clock.lockstep.is_some() {
            pwm = motors.reaching_plant(k);
        }
        // The stabilizer loop started: its console line, or in lock-step its first motor packet
        // (the console pipe is read on its own thread: when a line arrives is not repeatable).
        let stab_started = if args.lockstep {
            motor_packets > 0
        } else {
            link.console
                .wait_for("Starting stabilizer loop", Duration::ZERO)
                .is_some()
        };
        if stab_started_at.is_none() && stab_started {
            stab_started_at = Some(t);
            println!(
                "[{:6.2} s] stabilizer loop started (plant t = {t:.3} s)",
                link.t_start.elapsed().as_secs_f64()
            );
        }
        params.set_up(&link, &args, k, t, stab_started_at)?;
        if let (Some(t0), Some(_), None) = (stab_started_at, params.mixer_done_at, engage_at) {
            if t - t0 >= args.settle_s {
                engage_at = Some(t);
            }
        }
        // The flight's timeline, from the engage time.
        let Some((phase, setpoint)) =
            timeline.at(t, stab_started_at.is_some(), engage_at, piloting.traj_start)
        else {
            break;
        };
        if (phase == "hold" || phase == "trajectory") && hold_started_at.is_none() {
            hold_started_at = Some(t);
            delay_disturbances(&mut plant, t);
        }
        let link_up = Faults::link_up(&args, hold_started_at, t);
        faults.reset_estimator(&link, &args, k, t, hold_started_at, params.reset_id);
        faults.watch_link(link_up, t, pwm);
        motors.count_gaps(motor_packets, phase, t);
        let phase = if faults.link_lost_at.is_some() {
            "link lost"
        } else {
            phase
        };
        motors.count_rate(motor_packets, phase, t, args.lockstep);

        // Plant step with the last motor command, then the ground.
        let motors_off = faults.motors_off_at.is_some();
        let s = vehicle.step(&mut plant, pwm, t, phase, motors_off);
        faults.after_step(&s, t, phase, &setpoint);
        if !vehicle.check(&s, t, &setpoint, faults.link_lost_at.is_some()) {
            break;
        }

        // Sensors.
        let imu = vehicle.imu(&plant, &s);
        if clock.lockstep.is_none() {
            link.send(&imu);
        }
        let pose_now = k.is_multiple_of(10) && link_up;
        let setpoint_now = k % setpoint_every == 5 % setpoint_every && link_up;
        // cflib's packets: one per millisecond, and none in a millisecond that already carries a
        // pose or a setpoint. The firmware's socket link queues 5 packets and drops the rest, its
        // reader runs about once per tick, and cflib's UDP driver never resends: one packet lost
        // stalls a parameter download or a memory write for good.
        // The trajectory's upload: one packet per millisecond in the same slots, before cflib's.
        let free = !pose_now && !setpoint_now;
        let upload_pk = piloting.upload_packet(&link, k, t, phase, link_up, free)?;
        if let Some(pk) = &upload_pk {
            link.send(pk);
        } else if free && link_up {
            link.forward_cflib();
        }
        if pose_now {
            let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(s.rot));
            link.send(&ext_pose_packet(&s.p_m, &q));
        }
        piloting.high_level(&link, &args, phase, setpoint_now, link_up);
        piloting.start_trajectory(&link, &args, t, phase, link_up)?;
        piloting.stream(&link, &args, phase, &setpoint, setpoint_now);
        if k.is_multiple_of(10) {
            samples.push(Sample {
                t_s: plant.t_s(),
                phase,
                p: s.p_m,
                sp: setpoint.as_ref().map(|sp| sp.p_m).unwrap_or(Vector3::new(
                    f64::NAN,
                    f64::NAN,
                    f64::NAN,
                )),
                rpy_deg: s.rpy().map(f64::to_degrees),
                pwm,
                wall_s: clock.loop_start.elapsed().as_secs_f64(),
            });
        }
        if link.firmware_exited()? {
            bail!(
                "the firmware exited (console: {})",
                link.console_path.display()
            );
        }
        if plant.t_s() > total_guard_s {
            bail!(
                "the stabilizer loop never started (console: {})",
                link.console_path.display()
            );
        }
        k += 1;

        clock.exchange(&link, &args, &mut motors, &imu, k, plant.t_s())?;
        clock.pace();
    }
    let wall = clock.loop_start.elapsed().as_secs_f64();
    let closed = link.close();

    summary::write(&Flown {
        args: &args,
        scenario: &scenario,
        timeline: &timeline,
        samples: &samples,
        plant: &plant,
        vehicle: &vehicle,
        params: &params,
        piloting: &piloting,
        faults: &faults,
        motors: &motors,
        clock: &clock,
        closed: &closed,
        k,
        wall,
    })?;
    if vehicle.crash.is_some() || !vehicle.airborne_once {
        std::process::exit(3);
    }
    if faults.link_lost_at.is_some() && faults.motors_off_at.is_none() {
        // the supervisor's watchdog must stop the motors after a lost link
        std::process::exit(4);
    }
    Ok(())
}
