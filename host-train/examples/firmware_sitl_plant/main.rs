//! The whole Crazyflie firmware in the loop: CrazySim's SITL build of Bitcraze's firmware, with
//! hamflight as its out-of-tree controller (tools/firmware-sitl/build.sh), flies host-train's SITL
//! plant over CrazySim's UDP protocol.
//!
//!     cargo run --release -p host-train --example firmware_sitl_plant -- \
//!         [--firmware target/firmware-sitl/cmake/cf2_sitl/cf2] [--scenario scenarios/hover.toml]
//!
//! This program plays the part of CrazySim's Gazebo plugin (`crazysim_plugin.cpp`), with the
//! plant in place of Gazebo, and the part of the pilot (CRTP setpoints). It starts the firmware
//! (`cf2 PORT 127.0.0.1`), answers its handshake (`0xF3`), and every millisecond of wall clock
//! steps the plant by 1 ms with the last motor command and sends the firmware one IMU sample (port
//! 9, channel 0, type 0: specific force in units of 32 g / 65536, body rates in 4000 °/s / 65536),
//! every 10 ms the true pose as a motion-capture system would (`EXT_POSE`, localization port 6,
//! channel 1), every 20 ms a position setpoint (generic commander, port 7, type 7, as cflib's
//! `send_position_setpoint`). The setpoints: on the ground until the firmware's estimator has
//! settled, a smooth climb to the scenario's reference p*(0), the reference for the hold, a smooth
//! descent to the ground, then the stop setpoint.
//!
//! PWM → rotor: the firmware's SITL power distribution (`power_distribution_sitl.c`, the one our
//! controller's force/torque command goes through) turns the per-rotor force F into the PWM ratio
//! p = pwm / 65535 by inverting F = A p² + B p (A = 0.091492681, B = 0.067673604, its
//! `pwmToThrustA/B`). The plant inverts that same map, so each rotor makes the force the firmware
//! meant, and runs at rpm = √(F / kf) with the scenario vehicle's kf. (CrazySim's own plugin maps
//! PWM to a rotor speed, ω = 0.0408 pwm + 380.8 rad/s, for Gazebo's rotor with its own motor
//! constant 1.7965e-8 N/(rad/s)²; with our plant's kf that map would not give the firmware's
//! forces.)
//!
//! Mixer: the firmware's mixer constants are the CF2's (`quadSysId.armLength` 0.046 m,
//! `thrustToTorque` 0.005964552 m); the CF2X plant's arm is 0.028 m and its km/kf 0.0251 m, so the
//! plant would make 0.86 × the commanded roll/pitch torque and 4.2 × the yaw torque (the yaw loop
//! then limit-cycles at saturation). Before the take-off this program sets both to the scenario
//! vehicle's over CRTP (it reads the parameter TOC, writes by id and waits for the echo);
//! `--stock-mixer` keeps the firmware's.
//!
//! Ground: the plant has no ground, so this program adds one: below z = 0 the vehicle rests at
//! z = 0, level, still (the accelerometer then reads the normal force, 1 g up).
//!
//! Timing, two ways. Wall clock (the default): the firmware's FreeRTOS ticks on a wall-clock
//! timer, its stabilizer runs once per IMU packet, and this program paces the IMU stream at 1 kHz
//! of wall clock (one plant millisecond per packet, never bursting to catch up); it reports how
//! well it kept pace. Lock-step (`--lockstep`, the firmware built with
//! tools/firmware-sitl/patches/cf-lockstep.patch): the firmware's tick advances once per IMU
//! packet; each millisecond this program sends the pose, setpoint and cflib packets due, then the
//! IMU sample, waits for the firmware's tick-done packet (the motor packet of that tick, if any,
//! came before it), and steps the plant 1 ms. Then a run is repeatable and faster than real time.
//!
//! Pilots (`--pilot`): the streamed setpoints above; the firmware's high-level commander
//! (take-off, go-to, land, stop); or the commander flying a figure of eight uploaded to its
//! trajectory memory (`trajectory.rs`: the memory TOC, acknowledged writes of poly4d pieces,
//! define, start relative to the hover point), scored against the trajectory's own polynomial.
//!
//! Every other CRTP packet is relayed to a cflib client on `--cflib-port` (udp://127.0.0.1:19850),
//! as smoke.py does, so cflib can watch the flight (or 0: no relay).
//!
//! Output: the flight's numbers on stdout, and in `--out` (default target/firmware-sitl/flight):
//! flight.csv (every 10 ms), flight.svg (z and the setpoint, the position error) and console.log
//! (the firmware's stdout), summary.json (the numbers, for tools/firmware-sitl/study.sh).

use std::path::PathBuf;

use clap::Parser;

mod clock;
mod crtp;
mod faults;
mod flight;
mod launch;
mod motors;
mod params;
mod pilot;
mod plant;
mod record;
mod summary;
mod timeline;
mod trajectory;

#[derive(Parser, Debug)]
#[command(
    about = "Fly host-train's plant with the SITL Crazyflie firmware (hamflight as its controller)"
)]
struct Args {
    /// The SITL firmware (tools/firmware-sitl/build.sh).
    #[arg(long, default_value = "target/firmware-sitl/cmake/cf2_sitl/cf2")]
    firmware: PathBuf,
    /// The scenario: its vehicle, effects and disturbance; its reference is the hold.
    #[arg(long, default_value = "scenarios/hover.toml")]
    scenario: PathBuf,
    /// UDP port the firmware connects to.
    #[arg(long, default_value_t = 19950)]
    port: u16,
    /// UDP port a cflib client may connect to (CRTP relay); 0: no relay.
    #[arg(long, default_value_t = 19850)]
    cflib_port: u16,
    /// Seconds on the ground after the stabilizer loop starts (the Kalman estimator settles).
    #[arg(long, default_value_t = 2.0)]
    settle_s: f64,
    /// Seconds of the climb to p*(0).
    #[arg(long, default_value_t = 2.5)]
    takeoff_s: f64,
    /// Seconds of the hold (default: the scenario's duration).
    #[arg(long)]
    hold_s: Option<f64>,
    /// Seconds of the descent.
    #[arg(long, default_value_t = 2.5)]
    land_s: f64,
    /// Seconds into the hold before the "settled" statistics start.
    #[arg(long, default_value_t = 2.0)]
    window_s: f64,
    /// Keep the firmware's own mixer constants (the CF2's quadSysId.armLength 0.046 m and
    /// thrustToTorque 0.005964552 m) instead of setting them to the scenario vehicle's.
    #[arg(long)]
    stock_mixer: bool,
    /// The setpoint cflib streams: `full-state` (`send_full_state_setpoint`: the reference's
    /// position, velocity, acceleration, yaw and yaw rate), `full-state-rates` (the same with
    /// the body rates of the reference's jerk, as Crazyswarm sends them) or `position`
    /// (`send_position_setpoint`: position and yaw only, no feed-forward).
    #[arg(long, value_enum, default_value_t = SetpointKind::FullState)]
    setpoint: SetpointKind,
    /// Who flies: `stream` (cflib's streamed setpoints along the scenario's reference, `--setpoint`)
    /// or `high-level` (the firmware's high-level commander, as cflib's `HighLevelCommander`: take-off
    /// to p*(0)'s height, go-to p*(0), land, stop; the scenario's reference is then only the score's
    /// yardstick: use a hover scenario), or `trajectory` (the high-level commander flies an
    /// uploaded figure of eight from p*(0): `--traj-*`, `--upload-s`; use a hover scenario).
    #[arg(long, value_enum, default_value_t = Pilot::Stream)]
    pilot: Pilot,
    /// With `--pilot trajectory`: the figure of eight's duration (s).
    #[arg(long, default_value_t = 10.0)]
    traj_s: f64,
    /// With `--pilot trajectory`: the figure's half-width along x (m; along y half of it).
    #[arg(long, default_value_t = 0.5)]
    traj_size_m: f64,
    /// With `--pilot trajectory`: poly4d pieces of the figure (1..=31, the memory's room).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u8).range(1..=31))]
    traj_pieces: u8,
    /// With `--pilot trajectory`: start_trajectory's time scale (1: as uploaded, 2: twice as long).
    #[arg(long, default_value_t = 1.0)]
    traj_time_scale: f64,
    /// With `--pilot trajectory`: seconds of hover after the take-off in which the trajectory is
    /// uploaded and defined (the flight fails if the firmware has not answered every write and
    /// the definition by then), before it is started.
    #[arg(long, default_value_t = 2.0)]
    upload_s: f64,
    /// Setpoints per second (cflib users stream 10–100 Hz).
    #[arg(long, default_value_t = 100.0, value_parser = positive_hz)]
    setpoint_hz: f64,
    /// Lose the radio link this many seconds into the hold: no setpoint and no pose from then on
    /// (with cflib, motion capture reaches the vehicle over the same link). Bitcraze's supervisor
    /// levels the vehicle after 0.5 s without a setpoint and stops the motors after 2 s; exit 4 if
    /// the motors never stop.
    #[arg(long)]
    link_loss_s: Option<f64>,
    /// Seconds to stay on the ground after the stop setpoint that ends the flight, the firmware
    /// still running (for a cflib client that waits for something the landing allows, e.g. a
    /// deferred weight swap).
    #[arg(long, default_value_t = 0.0)]
    linger_s: f64,
    /// Reset the firmware's Kalman estimator this many seconds into the hold
    /// (`kalman.resetEstimation = 1` over CRTP, as cflib's `reset_estimator` does); the peak
    /// error after it and the time back within 1 cm are reported.
    #[arg(long)]
    estimator_reset_s: Option<f64>,
    /// Lock-step timing: the firmware (built with tools/firmware-sitl/patches/cf-lockstep.patch)
    /// is run with CF2_LOCKSTEP=1 and its FreeRTOS tick advances once per IMU packet; after each
    /// one this program waits for the firmware's tick-done packet, then steps the plant 1 ms. No
    /// wall clock: a run is repeatable and as fast as the firmware computes.
    #[arg(long)]
    lockstep: bool,
    /// With --lockstep: still pace the ticks at 1 kHz of wall clock (for a cflib client, whose
    /// timeouts are wall-clock).
    #[arg(long, requires = "lockstep")]
    realtime: bool,
    /// With --lockstep: seconds the firmware may take for one tick before the run fails.
    #[arg(long, default_value_t = 10.0)]
    tick_timeout_s: f64,
    /// With --lockstep: the motor commands reach the plant this many milliseconds late (a
    /// transport delay, repeatable; for studying the loop's timing margin).
    #[arg(long, default_value_t = 0, requires = "lockstep")]
    motor_delay_ms: u32,
    /// With --lockstep: each motor command is further delayed by 0..=N ms, drawn per command
    /// (`--seed`), order kept: the irregular delivery of a wall-clock run, repeatable.
    #[arg(long, default_value_t = 0, requires = "lockstep")]
    motor_jitter_ms: u32,
    /// With --lockstep: the fraction of motor packets lost (the plant holds the last), drawn per
    /// packet (`--seed`).
    #[arg(long, default_value_t = 0.0, requires = "lockstep")]
    motor_drop: f64,
    /// Seed of --motor-jitter-ms and --motor-drop.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Set a firmware parameter before the take-off, as the mixer's are (repeatable):
    /// `GROUP.NAME=VALUE` writes a float, `GROUP.NAME=VALUE:u8` an 8-bit integer; e.g.
    /// `hamflight.maxTilt=0.8`, `stabilizer.controller=2:u8` (Bitcraze's Mellinger).
    #[arg(long = "param", value_name = "GROUP.NAME=VALUE[:u8]", value_parser = parse_param)]
    params: Vec<(String, f32, bool)>,
    /// Directory for flight.csv, flight.svg, console.log, summary.json.
    #[arg(long, default_value = "target/firmware-sitl/flight")]
    out: PathBuf,
}

/// Who sends the setpoints.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Pilot {
    /// This program streams them along the reference (generic commander).
    Stream,
    /// The firmware's high-level commander plans them from take-off, go-to and land commands.
    HighLevel,
    /// The high-level commander flies an uploaded trajectory: take-off, go-to p*(0), upload a
    /// figure of eight (poly4d pieces) to its trajectory memory, define it, start it relative
    /// to the hover point, land, stop. Scored against the trajectory's own polynomial.
    Trajectory,
}

/// The setpoint type streamed over the generic commander.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SetpointKind {
    /// Generic commander type 6: position, velocity and acceleration, attitude, rates.
    FullState,
    /// Type 6 with the reference's body rates from its acceleration, jerk and yaw rate
    /// (`flatness_body_rates`, as Crazyswarm's `cmdFullState` sends them); the jerk itself
    /// cannot be sent.
    FullStateRates,
    /// Generic commander type 7: position and yaw.
    Position,
}

fn positive_hz(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x > 0.0 && x <= 1000.0 => Ok(x),
        _ => Err(format!("{s}: a rate in (0, 1000] Hz")),
    }
}

/// `GROUP.NAME=VALUE[:u8]` -> (name, value, written as u8).
fn parse_param(s: &str) -> Result<(String, f32, bool), String> {
    let (name, v) = s
        .split_once('=')
        .filter(|(n, _)| n.contains('.'))
        .ok_or_else(|| format!("{s}: expected GROUP.NAME=VALUE[:u8]"))?;
    let (v, u8) = v.strip_suffix(":u8").map_or((v, false), |v| (v, true));
    let x: f32 = v.parse().map_err(|_| format!("{s}: {v} is not a number"))?;
    if u8 && !(x.fract() == 0.0 && (0.0..=255.0).contains(&x)) {
        return Err(format!("{s}: {v} is not a u8"));
    }
    Ok((name.to_string(), x, u8))
}

fn main() {
    if let Err(e) = flight::run() {
        eprintln!("firmware_sitl_plant: {e:#}");
        std::process::exit(1);
    }
}

#[cfg(test)]
mod tests {
    use super::parse_param;

    #[test]
    fn params_parse() {
        assert_eq!(
            parse_param("hamflight.maxTilt=0.8"),
            Ok(("hamflight.maxTilt".into(), 0.8, false))
        );
        assert_eq!(
            parse_param("stabilizer.controller=2:u8"),
            Ok(("stabilizer.controller".into(), 2.0, true))
        );
        for bad in ["maxTilt=0.8", "a.b", "a.b=x", "a.b=2.5:u8", "a.b=300:u8"] {
            assert!(parse_param(bad).is_err(), "{bad}");
        }
    }
}
