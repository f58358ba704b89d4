//! The reference of each trajectory kind: position and its derivatives at a time.

use nalgebra::Vector3;

use super::Trajectory;
use crate::sim::trajectory::TrajectoryPoint;

fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::from(a)
}

/// Position and derivatives of a trajectory at `t` (yaw left at 0).
pub fn trajectory_point(tr: &Trajectory, t: f64) -> TrajectoryPoint {
    let z = Vector3::zeros();
    match tr {
        Trajectory::Hover { position_m } => TrajectoryPoint::hover(v3(*position_m), 0.0),
        Trajectory::Step { from_m, to_m, at_s } => {
            TrajectoryPoint::hover(v3(if t < *at_s { *from_m } else { *to_m }), 0.0)
        }
        Trajectory::Circle {
            center_m,
            radius_m,
            period_s,
        } => circle(v3(*center_m), *radius_m, *period_s, z, t),
        Trajectory::Spiral {
            center_m,
            radius_m,
            period_s,
            climb_m_s,
        } => circle(
            v3(*center_m),
            *radius_m,
            *period_s,
            Vector3::new(0.0, 0.0, *climb_m_s),
            t,
        ),
        Trajectory::Diamond {
            waypoints_m,
            segment_s,
            hold_s,
        } => {
            let n = waypoints_m.len();
            let leg = segment_s + hold_s;
            let tt = t.max(0.0) % (n as f64 * leg);
            let k = ((tt / leg).floor() as usize).min(n - 1);
            let a = v3(waypoints_m[k]);
            let b = v3(waypoints_m[(k + 1) % n]);
            let tau = ((tt - k as f64 * leg - hold_s) / segment_s).clamp(0.0, 1.0);
            let in_motion = tt - k as f64 * leg >= *hold_s;
            let (s, s1, s2, s3) = septic(tau);
            let d = b - a;
            let (s1, s2, s3) = if in_motion {
                (s1, s2, s3)
            } else {
                (0.0, 0.0, 0.0)
            };
            TrajectoryPoint {
                p_m: a + d * s,
                v_m_s: d * (s1 / segment_s),
                a_m_s2: d * (s2 / segment_s.powi(2)),
                j_m_s3: d * (s3 / segment_s.powi(3)),
                yaw_rad: 0.0,
                yaw_rate_rad_s: 0.0,
            }
        }
        Trajectory::FigureEight {
            start_m,
            half_width_m,
            duration_s,
            start_s,
        } => figure_eight(v3(*start_m), *half_width_m, *duration_s, t - start_s),
    }
}

/// The figure of eight of [`Trajectory::FigureEight`] at `t` (before 0 and after the end: at
/// rest on `start`).
pub fn figure_eight(start: Vector3<f64>, a: f64, dur: f64, t: f64) -> TrajectoryPoint {
    let (s0, s1, s2, s3) = septic((t / dur).clamp(0.0, 1.0));
    let tau = core::f64::consts::TAU;
    // θ and its first three time derivatives
    let th = [
        tau * s0,
        tau * s1 / dur,
        tau * s2 / dur.powi(2),
        tau * s3 / dur.powi(3),
    ];
    // f(θ) with its θ-derivatives, then the chain rule to the third time derivative
    let chain = |f: [f64; 4]| {
        [
            f[0],
            f[1] * th[1],
            f[2] * th[1] * th[1] + f[1] * th[2],
            f[3] * th[1].powi(3) + 3.0 * f[2] * th[1] * th[2] + f[1] * th[3],
        ]
    };
    let (sn, cs) = th[0].sin_cos();
    let (s2t, c2t) = (2.0 * th[0]).sin_cos();
    let b = a / 2.0;
    let x = chain([a * sn, a * cs, -a * sn, -a * cs]);
    let y = chain([b * s2t, 2.0 * b * c2t, -4.0 * b * s2t, -8.0 * b * c2t]);
    TrajectoryPoint {
        p_m: start + Vector3::new(x[0], y[0], 0.0),
        v_m_s: Vector3::new(x[1], y[1], 0.0),
        a_m_s2: Vector3::new(x[2], y[2], 0.0),
        j_m_s3: Vector3::new(x[3], y[3], 0.0),
        yaw_rad: 0.0,
        yaw_rate_rad_s: 0.0,
    }
}

fn circle(c: Vector3<f64>, r: f64, period: f64, climb: Vector3<f64>, t: f64) -> TrajectoryPoint {
    let w = core::f64::consts::TAU / period;
    let (s, co) = (w * t).sin_cos();
    TrajectoryPoint {
        p_m: c + Vector3::new(r * co, r * s, 0.0) + climb * t,
        v_m_s: Vector3::new(-r * w * s, r * w * co, 0.0) + climb,
        a_m_s2: Vector3::new(-r * w * w * co, -r * w * w * s, 0.0),
        j_m_s3: Vector3::new(r * w.powi(3) * s, -r * w.powi(3) * co, 0.0),
        yaw_rad: 0.0,
        yaw_rate_rad_s: 0.0,
    }
}

/// The septic smooth step s(τ) = 35τ⁴ − 84τ⁵ + 70τ⁶ − 20τ⁷ and its first three derivatives in τ
/// (zero velocity, acceleration and jerk at both ends).
pub fn septic(t: f64) -> (f64, f64, f64, f64) {
    let t2 = t * t;
    let t3 = t2 * t;
    let t4 = t3 * t;
    (
        t4 * (35.0 - 84.0 * t + 70.0 * t2 - 20.0 * t3),
        t3 * (140.0 - 420.0 * t + 420.0 * t2 - 140.0 * t3),
        t2 * (420.0 - 1680.0 * t + 2100.0 * t2 - 840.0 * t3),
        t * (840.0 - 5040.0 * t + 8400.0 * t2 - 4200.0 * t3),
    )
}

#[cfg(test)]
mod tests {
    use super::super::Scenario;
    use nalgebra::Vector3;

    /// `kind = "figure_eight"`: parsed, at rest on `start_m` before `start_s` and after the end,
    /// each derivative the finite difference of the one below, the figure's extent a × a/2.
    #[test]
    fn figure_eight_kind() {
        let s = Scenario::from_toml_str(
            "duration_s = 12.0\n[trajectory]\nkind = \"figure_eight\"\nstart_m = [0.0, 0.0, 1.0]\n\
             half_width_m = 0.5\nduration_s = 10.0\nstart_s = 1.0\n",
            "test",
            "fig8",
        )
        .unwrap();
        let start = Vector3::new(0.0, 0.0, 1.0);
        for t in [0.0, 0.5, 1.0, 11.0, 12.0] {
            let r = s.reference(t);
            assert!((r.p_m - start).norm() < 1e-12, "t {t}: {:?}", r.p_m);
            assert!(
                r.v_m_s.norm() + r.a_m_s2.norm() + r.j_m_s3.norm() < 1e-9,
                "t {t}"
            );
        }
        let (mut xmax, mut ymax) = (0.0f64, 0.0f64);
        let h = 1e-5;
        for i in 1..200 {
            let t = 1.0 + 10.0 * i as f64 / 200.0;
            let (a, r, b) = (s.reference(t - h), s.reference(t), s.reference(t + h));
            let d = |x: Vector3<f64>, y: Vector3<f64>| (y - x) / (2.0 * h);
            assert!((d(a.p_m, b.p_m) - r.v_m_s).norm() < 1e-6, "v at {t}");
            assert!((d(a.v_m_s, b.v_m_s) - r.a_m_s2).norm() < 1e-5, "a at {t}");
            assert!((d(a.a_m_s2, b.a_m_s2) - r.j_m_s3).norm() < 1e-4, "j at {t}");
            assert_eq!(r.p_m.z, 1.0);
            xmax = xmax.max(r.p_m.x.abs());
            ymax = ymax.max(r.p_m.y.abs());
        }
        assert!(
            (xmax - 0.5).abs() < 1e-3 && (ymax - 0.25).abs() < 1e-3,
            "{xmax} {ymax}"
        );
        let bad =
            "duration_s = 1.0\n[trajectory]\nkind = \"figure_eight\"\nstart_m = [0.0, 0.0, 1.0]\n\
                   half_width_m = 0.5\nduration_s = 10.0\nstart_s = -1.0\n";
        let e = Scenario::from_toml_str(bad, "test", "fig8").unwrap_err();
        assert!(format!("{e:#}").contains("start_s"), "{e:#}");
    }
}
