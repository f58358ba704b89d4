//! The Lee–Leok–McClamroch geometric tracking controller on SE(3) (Lee et al., CDC 2010), on the
//! true (nominal) constants, without adaptation.
//!
//! ```text
//! e_x = p − p*,  e_v = Rv − v*                       (world)
//! F   = −k_x e_x − k_v e_v + m g e₃ + m a*           (world, N)
//! f   = F · R e₃,  b₃* = F/|F|,  b₂* ∝ b₃* × [cos ψ*, sin ψ*, 0],  b₁* = b₂* × b₃*
//! e_R = ½ (R*ᵀR − RᵀR*)^∨,  e_ω = ω − RᵀR* ω*
//! τ   = −k_R e_R − k_ω e_ω + ω × Jω − J (ω̂ RᵀR* ω* − RᵀR* ω̇*)
//! ```
//!
//! `ω*` comes from differentiating `R*` analytically (through `Ḟ`, with the jerk of the reference
//! and the acceleration the nominal model predicts); `ω̇*` is a finite difference of `ω*` between
//! ticks. The wrench goes to the rotors through the nominal mixer inverse with attitude-preserving
//! saturation ([`VehicleParams::wrench_to_rpm`]). The tilt of `b₃*` is limited to `max_tilt_rad`.
//!
//! [`Geometric::with_motor_lag`] adds a lead on the torques for motors slower than the gains
//! fly behind ([`GEOMETRIC_MAX_UNCOMPENSATED_LAG_S`]), as the core's `LagCompensation` does: the
//! gains stay Lee's, the motors look faster.

use nalgebra::{Matrix3, Vector3};

use crate::control::controller::Controller;

use crate::sim::plant::{hat, vee, PlantState, VehicleParams};
use crate::sim::trajectory::TrajectoryPoint;

/// Gains of the geometric controller.
#[derive(Clone, Debug)]
pub struct GeometricGains {
    /// Position gain k_x (N/m).
    pub kx: f64,
    /// Velocity gain k_v (N·s/m).
    pub kv: f64,
    /// Attitude gains k_R per body axis (N·m/rad).
    pub kr: [f64; 3],
    /// Rate gains k_ω per body axis (N·m·s/rad).
    pub kw: [f64; 3],
    /// Largest angle between b₃* and world z (rad).
    pub max_tilt_rad: f64,
}

impl GeometricGains {
    /// Gains for a vehicle: k_x = 16 m, k_v = 6 m (ω_n = 4 rad/s, ζ = 0.75),
    /// attitude critically damped at 40 rad/s in roll/pitch and 20 rad/s in yaw
    /// (k_R = J ω_n², k_ω = 2 J ω_n; for the CF2X k_R ≈ 0.022 N·m/rad, k_ω ≈ 0.0011 N·m·s/rad).
    pub fn for_vehicle(p: &VehicleParams) -> Self {
        let j = p.inertia_kg_m2;
        let wn = [40.0, 40.0, 20.0];
        Self {
            kx: 16.0 * p.mass_kg,
            kv: 6.0 * p.mass_kg,
            kr: core::array::from_fn(|i| j[i] * wn[i] * wn[i]),
            kw: core::array::from_fn(|i| 2.0 * j[i] * wn[i]),
            max_tilt_rad: 0.6,
        }
    }
}

/// The longest first-order motor lag (s) the gains of [`GeometricGains::for_vehicle`] are flown
/// behind uncompensated: the heavy (20 ms) and asymmetric (30 ms) study vehicles' logging flights
/// are Lee's own. At 70 ms (the light study vehicle) the attitude loop, crossing over near
/// 80 rad/s, has no phase margin left and the vehicle rolls over within 2 s.
pub const GEOMETRIC_MAX_UNCOMPENSATED_LAG_S: f64 = 0.03;

/// The lag (s) [`Geometric::with_motor_lag`] makes slower motors look like: led only to 30 ms,
/// the light vehicle still crashes a logging flight; to 20 ms all fly (docs/vehicles.md, "Three
/// vehicles").
pub const GEOMETRIC_LAG_TARGET_S: f64 = 0.02;

/// The geometric controller.
#[derive(Clone, Debug)]
pub struct Geometric {
    /// Gains.
    pub gains: GeometricGains,
    params: VehicleParams,
    last_wd: Option<(f64, Vector3<f64>)>,
    /// Lag lead: (motor τ_m, target τ_t) in s, τ_m > τ_t; `None`: off.
    lag: Option<(f64, f64)>,
    /// The delivered wrench's first-order model (the lead's state).
    u_model: Option<[f64; 4]>,
}

impl Geometric {
    /// The controller for a vehicle with `params` and [`GeometricGains::for_vehicle`].
    pub fn new(params: VehicleParams) -> Self {
        Self {
            gains: GeometricGains::for_vehicle(&params),
            params,
            last_wd: None,
            lag: None,
            u_model: None,
        }
    }

    /// [`Geometric::new`] for motors with first-order lag `motor_tau_s` (s): above
    /// [`GEOMETRIC_MAX_UNCOMPENSATED_LAG_S`], the torque command is led from a model û of the
    /// delivered wrench, τ_cmd = û + (τ_m / τ_t)(τ − û), so the attitude loop sees
    /// τ_t = [`GEOMETRIC_LAG_TARGET_S`] instead of τ_m; at or below it (or non-finite), exactly
    /// [`Geometric::new`].
    pub fn with_motor_lag(params: VehicleParams, motor_tau_s: f64) -> Self {
        let mut g = Self::new(params);
        if motor_tau_s.is_finite() && motor_tau_s > GEOMETRIC_MAX_UNCOMPENSATED_LAG_S {
            g.lag = Some((motor_tau_s, GEOMETRIC_LAG_TARGET_S));
        }
        g
    }

    /// Desired wrench `[f; τ]` (N, N·m) for one tick (also updates the ω* history).
    pub fn wrench(&mut self, t_s: f64, s: &PlantState, r: &TrajectoryPoint) -> [f64; 4] {
        let g = &self.gains;
        let m = self.params.mass_kg;
        let grav = self.params.gravity_m_s2;
        let e3 = Vector3::z();
        let rot = s.rot;
        let ex = s.p_m - r.p_m;
        let ev = s.v_world_m_s() - r.v_m_s;
        let mut force = -g.kx * ex - g.kv * ev + m * grav * e3 + m * r.a_m_s2;
        // Tilt limit: keep the horizontal part within tan(max_tilt) of the vertical part.
        let fz = force.z.max(0.1 * m * grav);
        let fh = Vector3::new(force.x, force.y, 0.0);
        let fh_max = fz * g.max_tilt_rad.tan();
        let fh = if fh.norm() > fh_max {
            fh * (fh_max / fh.norm())
        } else {
            fh
        };
        force = Vector3::new(fh.x, fh.y, fz);
        let b3 = rot * e3;
        let f = force.dot(&b3);

        // Ḟ with the model's acceleration (nominal, no disturbance).
        let acc = -grav * e3 + (f / m) * b3;
        let ea = acc - r.a_m_s2;
        let fdot = -g.kx * ev - g.kv * ea + m * r.j_m_s3;

        let nf = force.norm();
        let b3d = force / nf;
        let b3d_dot = (fdot - b3d * b3d.dot(&fdot)) / nf;
        let (sy, cy) = r.yaw_rad.sin_cos();
        let b1c = Vector3::new(cy, sy, 0.0);
        let b1c_dot = r.yaw_rate_rad_s * Vector3::new(-sy, cy, 0.0);
        let c = b3d.cross(&b1c);
        let c_dot = b3d_dot.cross(&b1c) + b3d.cross(&b1c_dot);
        let nc = c.norm().max(1e-9);
        let b2d = c / nc;
        let b2d_dot = (c_dot - b2d * b2d.dot(&c_dot)) / nc;
        let b1d = b2d.cross(&b3d);
        let b1d_dot = b2d_dot.cross(&b3d) + b2d.cross(&b3d_dot);
        let rd = Matrix3::from_columns(&[b1d, b2d, b3d]);
        let rd_dot = Matrix3::from_columns(&[b1d_dot, b2d_dot, b3d_dot]);
        let wd = vee(&(rd.transpose() * rd_dot));
        let wd_dot = match self.last_wd {
            Some((t0, w0)) if t_s > t0 => (wd - w0) / (t_s - t0),
            _ => Vector3::zeros(),
        };
        self.last_wd = Some((t_s, wd));

        // vee takes the skew part: vee(R*ᵀR) = ½ (R*ᵀR − RᵀR*)^∨ = e_R.
        let er = vee(&(rd.transpose() * rot));
        let w = s.w_body_rad_s;
        let rtrd = rot.transpose() * rd;
        let ew = w - rtrd * wd;
        let j = self.params.inertia();
        let tau = -Vector3::from(g.kr).component_mul(&er) - Vector3::from(g.kw).component_mul(&ew)
            + w.cross(&(j * w))
            - j * (hat(&w) * rtrd * wd - rtrd * wd_dot);
        [f, tau.x, tau.y, tau.z]
    }
}

impl Controller for Geometric {
    fn name(&self) -> &str {
        "geometric"
    }

    fn reset(&mut self) {
        self.last_wd = None;
        self.u_model = None;
    }

    fn step(&mut self, t_s: f64, s: &PlantState, r: &TrajectoryPoint, dt: f64) -> [f64; 4] {
        let u = self.wrench(t_s, s, r);
        let Some((tau_m, tau_t)) = self.lag else {
            return self.params.wrench_to_rpm(u);
        };
        // The torques only, as the core: a lead on the thrust would spend the thrust margin.
        let ratio = tau_m / tau_t;
        let cmd = match self.u_model {
            Some(m) => [
                u[0],
                m[1] + ratio * (u[1] - m[1]),
                m[2] + ratio * (u[2] - m[2]),
                m[3] + ratio * (u[3] - m[3]),
            ],
            None => u,
        };
        let rpm = self.params.wrench_to_rpm(cmd);
        let delivered = self.params.nominal_wrench(rpm);
        let beta = if dt.is_finite() && dt > 0.0 {
            dt / (tau_m + dt)
        } else {
            1.0
        };
        let next: [f64; 4] = match self.u_model {
            Some(m) => core::array::from_fn(|i| m[i] + beta * (delivered[i] - m[i])),
            None => delivered,
        };
        self.u_model = next.iter().all(|x| x.is_finite()).then_some(next);
        rpm
    }
}
