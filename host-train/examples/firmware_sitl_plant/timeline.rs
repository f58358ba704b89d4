//! The flight's timeline: from the engage time, each pilot's phases (take-off; hold, or upload and
//! trajectory; landing, stop) and the setpoint of every millisecond.

use host_train::io::{poly4d_trajectory_eval, Poly4d};
use host_train::{Scenario, TrajectoryPoint};
use nalgebra::Vector3;

use crate::{Args, Pilot};

/// After the trajectory's end: its end point, held this long before the landing.
const TRAJ_TAIL_S: f64 = 1.0;

/// Smooth 0 → 1 over [0, 1] (zero velocity at both ends), with its first and second derivatives.
fn smoothstep(u: f64) -> (f64, f64, f64) {
    if !(0.0..=1.0).contains(&u) {
        return (u.clamp(0.0, 1.0), 0.0, 0.0);
    }
    (u * u * (3.0 - 2.0 * u), 6.0 * u * (1.0 - u), 6.0 - 12.0 * u)
}

/// The end of every pilot's timeline, `te_s` after the descent began from `top`: the descent
/// (`land_s`), one second landed, then the stop for 1 s + `linger_s`; `None` when it is over.
/// The descent comes to rest at the ground itself (a move to a point below it would still be
/// braking, with upward feed-forward, at touch-down and bounce the vehicle back up); once down,
/// the setpoint sinks 5 cm below the ground so that the controller lets go.
fn landing(
    top: Vector3<f64>,
    te_s: f64,
    land_s: f64,
    linger_s: f64,
    yaw: f64,
) -> Option<(&'static str, Option<TrajectoryPoint>)> {
    let touch = Vector3::new(top.x, top.y, 0.0);
    let bottom = Vector3::new(top.x, top.y, -0.05);
    if te_s < land_s {
        Some(("land", Some(smooth_move(top, touch, land_s, te_s, yaw))))
    } else if te_s < land_s + 1.0 {
        Some(("landed", Some(smooth_move(bottom, bottom, 1.0, 0.0, yaw))))
    } else if te_s < land_s + 2.0 + linger_s {
        Some(("stop", None))
    } else {
        None
    }
}

/// A smooth move from `a` to `b` over `dur_s`, at `t_s` into it: position, velocity, acceleration.
fn smooth_move(
    a: Vector3<f64>,
    b: Vector3<f64>,
    dur_s: f64,
    t_s: f64,
    yaw: f64,
) -> TrajectoryPoint {
    let (s, ds, dds) = smoothstep(t_s / dur_s);
    TrajectoryPoint {
        p_m: a + (b - a) * s,
        v_m_s: (b - a) * (ds / dur_s),
        a_m_s2: (b - a) * (dds / (dur_s * dur_s)),
        j_m_s3: Vector3::zeros(),
        yaw_rad: yaw,
        yaw_rate_rad_s: 0.0,
    }
}

/// The reference of the started trajectory: the pieces' polynomial at tau / scale, shifted so
/// that it starts at p*(0) (the commander's `relative`: its current setpoint, here the go-to's
/// end, p*(0)). No pieces (another pilot): no trajectory, of duration 0.
pub struct TrajRef {
    pub pieces: Vec<Poly4d>,
    scale: f64,
    start_m: Vector3<f64>,
    /// The started trajectory's duration, its time scale included.
    pub total_s: f64,
}

impl TrajRef {
    pub fn new(pieces: Vec<Poly4d>, scale: f64, start_m: Vector3<f64>) -> Self {
        let total_s = pieces.iter().map(|p| p.duration_s as f64).sum::<f64>() * scale;
        TrajRef {
            pieces,
            scale,
            start_m,
            total_s,
        }
    }

    /// The reference `tau_s` after the trajectory's start.
    pub fn at(&self, tau_s: f64) -> TrajectoryPoint {
        let e0 = poly4d_trajectory_eval(&self.pieces, 0.0).expect("pieces");
        let e = poly4d_trajectory_eval(&self.pieces, tau_s / self.scale).expect("pieces");
        TrajectoryPoint {
            p_m: self.start_m + e.p_m - e0.p_m,
            v_m_s: e.v_m_s / self.scale,
            a_m_s2: e.a_m_s2 / (self.scale * self.scale),
            j_m_s3: Vector3::zeros(),
            yaw_rad: e.yaw_rad,
            yaw_rate_rad_s: e.yaw_rate_rad_s / self.scale,
        }
    }
}

/// Each pilot's phases and setpoints, from the ground at p*(0)'s x, y to p*(0) and back.
pub struct Timeline<'a> {
    pub args: &'a Args,
    pub scenario: &'a Scenario,
    /// Seconds of the hold (`--hold-s`, or the scenario's duration).
    pub hold_s: f64,
    /// p*(0): the hold's start, the high-level commander's hover point.
    pub target0: TrajectoryPoint,
    pub traj: TrajRef,
}

impl Timeline<'_> {
    /// Below p*(0), on the ground.
    pub fn ground_xy(&self) -> Vector3<f64> {
        Vector3::new(self.target0.p_m.x, self.target0.p_m.y, 0.0)
    }

    /// The phase and the setpoint at plant time `t`, or `None` once the flight is over. Before
    /// the engage time: "boot" until the stabilizer loop starts, then "settle". `traj_start`:
    /// when start_trajectory was (last) sent.
    pub fn at(
        &self,
        t: f64,
        stab_started: bool,
        engage_at: Option<f64>,
        traj_start: Option<(f64, u32)>,
    ) -> Option<(&'static str, Option<TrajectoryPoint>)> {
        let args = self.args;
        let (target0, yaw0, ground_xy) = (&self.target0, self.target0.yaw_rad, self.ground_xy());
        let (hold_s, traj_total_s) = (self.hold_s, self.traj.total_s);
        let traj_ref = |tau_s: f64| self.traj.at(tau_s);
        Some(match engage_at {
            None if !stab_started => ("boot", None),
            None => ("settle", None),
            Some(t_engage) if args.pilot == Pilot::Trajectory => {
                // take-off, hover at p*(0) while the trajectory is uploaded, the trajectory,
                // its end point held, the landing there, the stop
                let te = t - t_engage;
                let up_end = args.takeoff_s + args.upload_s;
                let tr_end = up_end + traj_total_s + TRAJ_TAIL_S;
                if te < args.takeoff_s {
                    let sp = smooth_move(ground_xy, target0.p_m, args.takeoff_s, te, yaw0);
                    ("takeoff", Some(sp))
                } else if te < up_end {
                    let sp = smooth_move(target0.p_m, target0.p_m, 1.0, 0.0, yaw0);
                    ("upload", Some(sp))
                } else if te < tr_end {
                    let t0 = traj_start.map_or(t, |s| s.0);
                    ("trajectory", Some(traj_ref(t - t0)))
                } else {
                    let top = traj_ref(traj_total_s).p_m;
                    return landing(top, te - tr_end, args.land_s, args.linger_s, yaw0);
                }
            }
            Some(t_engage) => {
                let te = t - t_engage;
                let hold_end = args.takeoff_s + hold_s;
                let hold_ref = |tau: f64| self.scenario.reference(tau.clamp(0.0, hold_s));
                if te < args.takeoff_s {
                    let sp = smooth_move(ground_xy, target0.p_m, args.takeoff_s, te, yaw0);
                    ("takeoff", Some(sp))
                } else if te < hold_end {
                    ("hold", Some(hold_ref(te - args.takeoff_s)))
                } else {
                    let top = hold_ref(hold_s).p_m;
                    return landing(top, te - hold_end, args.land_s, args.linger_s, yaw0);
                }
            }
        })
    }
}
