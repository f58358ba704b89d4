//! The flight's numbers: the position error per phase, the upload, the faults, the timing and the
//! motor packets, printed; flight.csv, flight.svg, and summary.json (for
//! tools/firmware-sitl/study.sh).

use std::sync::atomic::Ordering;

use anyhow::Result;
use host_train::{Plant, Scenario};

use crate::clock::Clock;
use crate::faults::Faults;
use crate::launch::Closed;
use crate::motors::Motors;
use crate::params::Params;
use crate::pilot::Piloting;
use crate::plant::Vehicle;
use crate::record::{plot, write_csv, Sample};
use crate::timeline::Timeline;
use crate::Args;

/// Everything the flight left, for its numbers.
pub struct Flown<'a> {
    pub args: &'a Args,
    pub scenario: &'a Scenario,
    pub timeline: &'a Timeline<'a>,
    pub samples: &'a [Sample],
    pub plant: &'a Plant,
    pub vehicle: &'a Vehicle,
    pub params: &'a Params,
    pub piloting: &'a Piloting,
    pub faults: &'a Faults,
    pub motors: &'a Motors,
    pub clock: &'a Clock,
    pub closed: &'a Closed,
    /// Loop steps (IMU packets), and the loop's wall-clock seconds.
    pub k: u64,
    pub wall: f64,
}

/// The distance to the setpoint over the samples `f` selects (those with a setpoint): RMSE, max,
/// RMSE of z, how many samples; none if there are none.
fn stats(samples: &[Sample], f: impl Fn(&Sample) -> bool) -> Option<(f64, f64, f64, usize)> {
    let errs: Vec<(f64, f64)> = samples
        .iter()
        .filter(|s| f(s) && s.sp.x.is_finite())
        .map(|s| ((s.p - s.sp).norm(), (s.p.z - s.sp.z).abs()))
        .collect();
    if errs.is_empty() {
        return None;
    }
    let n = errs.len() as f64;
    let rmse = (errs.iter().map(|e| e.0 * e.0).sum::<f64>() / n).sqrt();
    let max = errs.iter().map(|e| e.0).fold(0.0, f64::max);
    let rmse_z = (errs.iter().map(|e| e.1 * e.1).sum::<f64>() / n).sqrt();
    Some((rmse, max, rmse_z, errs.len()))
}

fn report(name: &str, st: Option<(f64, f64, f64, usize)>) {
    match st {
        Some((rmse, max, rz, n)) => println!(
            "{name:<34} RMSE {:6.2} cm   max {:6.2} cm   RMSE z {:6.2} cm   ({n} samples)",
            rmse * 100.0,
            max * 100.0,
            rz * 100.0
        ),
        None => println!("{name:<34} no samples"),
    }
}

/// Prints the numbers, writes flight.csv, flight.svg and summary.json into `--out`.
pub fn write(f: &Flown) -> Result<()> {
    let Flown {
        args,
        scenario,
        timeline,
        samples,
        plant,
        vehicle,
        params,
        piloting,
        faults,
        motors,
        clock,
        closed,
        k,
        wall,
    } = *f;
    let (hold_s, target0) = (timeline.hold_s, &timeline.target0);
    let (traj_pieces, traj_total_s) = (&timeline.traj.pieces, timeline.traj.total_s);
    let traj_scale = args.traj_time_scale;
    let (motor_packets, last_pwm) = (closed.motor_packets, closed.last_pwm);
    let (on_ground, airborne_once, touchdown_speed) = (
        vehicle.on_ground,
        vehicle.airborne_once,
        vehicle.touchdown_speed,
    );
    let (crash, fall) = (&vehicle.crash, vehicle.fall);
    let (link_lost_at, motors_off_at) = (faults.link_lost_at, faults.motors_off_at);
    let (reset_sent_at, reset_echoed_at) = (faults.reset_sent_at, faults.reset_echoed_at);
    let (upload, upload_done_at, upload_began_at) = (
        &piloting.upload,
        piloting.upload_done_at,
        piloting.upload_began_at,
    );
    let (traj_start, traj_start_answered) = (piloting.traj_start, piloting.traj_start_answered);
    let engage_motor_rate = motors.rate_in_flight;
    let motor_digest = motors.digest;
    let (max_late_ms, late_resets) = (clock.max_late_ms, clock.late_resets);

    let hold_t0 = samples
        .iter()
        .find(|s| s.phase == "hold")
        .map(|s| s.t_s)
        .unwrap_or(f64::NAN);
    println!(
        "scenario {} (hold at p*(0) = [{:.2}, {:.2}, {:.2}] m for {hold_s} s), firmware {}",
        scenario.name,
        target0.p_m.x,
        target0.p_m.y,
        target0.p_m.z,
        args.firmware.display()
    );
    if args.stock_mixer {
        println!(
            "mixer: the firmware's own (quadSysId armLength 0.046 m, thrustToTorque 0.005964552 m)"
        );
    }
    for ((name, v, u8), id) in params.mixer.iter().zip(&params.mixer_ids) {
        let echo = id
            .and_then(|id| closed.param_written.iter().find(|w| w.0 == id))
            .map(|w| match u8 {
                true => format!("firmware echoed {}", w.1[0]),
                false => format!("firmware echoed {:.6}", f32::from_le_bytes(w.1)),
            })
            .unwrap_or_else(|| "NOT SET".into());
        println!("param: {name} (id {id:?}) = {v:.6}: {echo}");
    }
    for l in &closed.hamflight_lines {
        println!("  console: {l}");
    }
    report(
        "take-off (vs the streamed setpoint)",
        stats(samples, |s| s.phase == "takeoff"),
    );
    report("hold, whole", stats(samples, |s| s.phase == "hold"));
    report(
        &format!("hold, from {} s in", args.window_s),
        stats(samples, |s| {
            s.phase == "hold" && s.t_s >= hold_t0 + args.window_s
        }),
    );
    report("landing", stats(samples, |s| s.phase == "land"));
    let traj_stats = stats(samples, |s| s.phase == "trajectory");
    if let Some(up) = upload {
        report(
            "hover while uploading",
            stats(samples, |s| s.phase == "upload"),
        );
        report("trajectory (vs its polynomial)", traj_stats);
        println!(
            "trajectory upload: memory id {} ({} B), {} B in {} writes, {} packets ({} repeats), \
             done {} after the hover began; start_trajectory sent at plant t = {}, answered {}",
            up.mem_id.map_or("-".into(), |i| i.to_string()),
            up.mem_size,
            up.bytes(),
            up.writes(),
            up.packets,
            up.repeats,
            match (upload_done_at, upload_began_at) {
                (Some(d), Some(b)) => format!("{:.0} ms", (d - b) * 1e3),
                _ => "NEVER".into(),
            },
            traj_start.map_or("-".into(), |s| format!("{:.3} s ({} sends)", s.0, s.1)),
            match (traj_start_answered, traj_start) {
                (Some(a), Some(s)) => format!("{:.0} ms later", (a - s.0) * 1e3),
                _ => "NEVER".into(),
            }
        );
    }
    let hold: Vec<&Sample> = samples.iter().filter(|s| s.phase == "hold").collect();
    if let Some(last) = hold.last() {
        let mean_z = hold.iter().map(|s| s.p.z).sum::<f64>() / hold.len() as f64;
        let max_tilt = hold
            .iter()
            .map(|s| s.rpy_deg.x.abs().max(s.rpy_deg.y.abs()))
            .fold(0.0, f64::max);
        println!(
            "hold: mean z {mean_z:.3} m, max |roll|,|pitch| {max_tilt:.1} deg, yaw at the end {:.1} deg, PWM at the end {:?}",
            last.rpy_deg.z, last.pwm
        );
    }
    let final_state = plant.state();
    println!(
        "end: z = {:.3} m, on the ground: {on_ground}, touch-down speed {}, last PWM {last_pwm:?}",
        final_state.p_m.z,
        touchdown_speed
            .map(|v| format!("{v:.2} m/s"))
            .unwrap_or_else(|| "-".into())
    );
    if let Some(tr) = reset_sent_at {
        println!(
            "estimator reset written at plant t = {tr:.3} s ({} s into the hold), echoed {}; then, to the hold's end: peak error {:.2} cm, back within 1 cm {}",
            args.estimator_reset_s.unwrap_or(0.0),
            reset_echoed_at
                .map(|e| format!("{:.0} ms later", (e - tr) * 1e3))
                .unwrap_or_else(|| "NEVER".into()),
            faults.reset_peak_m * 100.0,
            faults
                .reset_last_over_1cm
                .map(|e| format!("{:.2} s after", e - tr))
                .unwrap_or_else(|| "throughout".into())
        );
    }
    if let Some(tl) = link_lost_at {
        let off = motors_off_at.map(|t| format!("{:.3} s after", t - tl));
        println!(
            "link lost at plant t = {tl:.3} s ({} s into the hold): motors stopped {}; drift until then {:.1} cm; reached the ground at {}",
            args.link_loss_s.unwrap_or(0.0),
            off.unwrap_or_else(|| "NEVER".into()),
            faults.drift_m * 100.0,
            fall.map(|(v, tilt)| format!("{v:.2} m/s, tilt {tilt:.0} deg"))
                .unwrap_or_else(|| "- (still airborne)".into())
        );
    }
    match crash {
        Some((t, why)) => println!("CRASHED at plant t = {t:.2} s: {why}"),
        None => println!(
            "crashed: no (airborne: {airborne_once}, landed: {})",
            on_ground && airborne_once
        ),
    }
    if let Some(link) = &clock.lockstep {
        println!(
            "timing: lock-step{}: {:.3} s of plant in {wall:.3} s of wall clock ({:.3} plant s per \
             wall s, {:.1} us of wall clock per tick); ticks {} = IMU packets {k}; motor packets \
             {motor_packets} ({engage_motor_rate:.1} per plant s in flight), digest {motor_digest:016x}; \
             CRTP relayed to cflib {}, from cflib {} (at most {} waiting)",
            if args.realtime { " paced in real time" } else { "" },
            plant.t_s(),
            plant.t_s() / wall,
            wall / k as f64 * 1e6,
            link.ticks(),
            closed.relayed.load(Ordering::Relaxed),
            closed.cflib_sent,
            closed.from_cflib_max
        );
    } else {
        println!(
            "timing: {:.3} s of plant in {wall:.3} s of wall clock ({:.4} plant s per wall s); IMU \
             packets {k} ({:.1} /s); motor packets {motor_packets} ({:.1} /s overall, {engage_motor_rate:.1} /s \
             in flight); max lateness {max_late_ms:.2} ms, {late_resets} pacing resets; CRTP relayed \
             to cflib {}, from cflib {} (at most {} waiting)",
            plant.t_s(),
            plant.t_s() / wall,
            k as f64 / wall,
            motor_packets as f64 / wall,
            closed.relayed.load(Ordering::Relaxed),
            closed.cflib_sent,
            closed.from_cflib_max
        );
    }
    println!(
        "motor packets in flight: largest gap {:.1} ms, {} gaps of 4 ms or more",
        motors.gap_max_s * 1e3,
        motors.gaps_4ms
    );
    write_csv(&args.out.join("flight.csv"), samples)?;
    plot(&args.out.join("flight.svg"), samples, &scenario.name)?;
    let cm = |x: f64| (x * 1e4).round() / 100.0;
    let settled = stats(samples, |s| {
        s.phase == "hold" && s.t_s >= hold_t0 + args.window_s
    });
    let link = &clock.lockstep;
    let summary = serde_json::json!({
        "scenario": scenario.name,
        "setpoint": format!("{:?}", args.setpoint),
        "setpoint_hz": args.setpoint_hz,
        "window_s": args.window_s,
        "hold_rmse_cm": settled.map(|x| cm(x.0)),
        "hold_max_cm": settled.map(|x| cm(x.1)),
        "takeoff_rmse_cm": stats(samples, |s| s.phase == "takeoff").map(|x| cm(x.0)),
        "landing_rmse_cm": stats(samples, |s| s.phase == "land").map(|x| cm(x.0)),
        "pilot": format!("{:?}", args.pilot),
        "trajectory": upload.as_ref().map(|up| serde_json::json!({
            "shape": "figure of eight",
            "size_m": [2.0 * args.traj_size_m, args.traj_size_m],
            "duration_s": traj_total_s,
            "time_scale": traj_scale,
            "pieces": traj_pieces.len(),
            "bytes": up.bytes(),
            "mem_id": up.mem_id,
            "writes": up.writes(),
            "packets": up.packets,
            "repeats": up.repeats,
            "upload_ms": upload_done_at.zip(upload_began_at).map(|(d, b)| (d - b) * 1e3),
            "started_at_s": traj_start.map(|s| s.0),
            "start_answered": traj_start_answered.is_some(),
            "rmse_cm": traj_stats.map(|x| cm(x.0)),
            "max_cm": traj_stats.map(|x| cm(x.1)),
            "rmse_z_cm": traj_stats.map(|x| cm(x.2)),
        })),
        "touchdown_m_s": touchdown_speed,
        "crashed": crash.as_ref().map(|(t, why)| format!("at {t:.2} s: {why}")),
        "airborne": airborne_once,
        "link_loss": link_lost_at.map(|tl| serde_json::json!({
            "at_hold_s": args.link_loss_s,
            "motors_off_after_s": motors_off_at.map(|t| t - tl),
            "drift_cm": cm(faults.drift_m),
            "ground_speed_m_s": fall.map(|f| f.0),
            "ground_tilt_deg": fall.map(|f| f.1),
        })),
        "estimator_reset": reset_sent_at.map(|tr| serde_json::json!({
            "at_hold_s": args.estimator_reset_s,
            "echoed_after_s": reset_echoed_at.map(|e| e - tr),
            "peak_cm": cm(faults.reset_peak_m),
            "back_within_1cm_after_s": faults.reset_last_over_1cm.map(|e| e - tr),
        })),
        "timing": if args.lockstep { "lockstep" } else { "wall-clock" },
        "ticks": link.as_ref().map(|l| l.ticks()),
        "motor_digest": link.as_ref().map(|_| format!("{motor_digest:016x}")),
        "plant_s_per_wall_s": plant.t_s() / wall,
        "max_late_ms": max_late_ms,
        "pacing_resets": late_resets,
        "motor_packets_per_s_in_flight": engage_motor_rate,
        "motor_gap_max_ms": motors.gap_max_s * 1e3,
        "motor_gaps_4ms": motors.gaps_4ms,
        "motor_impairment": (args.motor_delay_ms > 0 || args.motor_jitter_ms > 0 || args.motor_drop > 0.0)
            .then(|| serde_json::json!({
                "delay_ms": args.motor_delay_ms,
                "jitter_ms": args.motor_jitter_ms,
                "drop": args.motor_drop,
                "seed": args.seed,
                "dropped": motors.dropped,
            })),
    });
    host_train::io::write_json_atomic(&args.out.join("summary.json"), &summary)?;
    println!(
        "wrote {}/flight.csv, flight.svg, console.log, summary.json",
        args.out.display()
    );
    Ok(())
}
