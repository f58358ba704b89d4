//! Flight scenarios: TOML files describing a reference trajectory, disturbances, effects and rates.
//!
//! # Keys
//!
//! ```toml
//! name = "paper-spiral"          # optional; defaults to the file stem
//! description = "..."            # optional, free text
//! duration_s = 30.0              # flight length (s), > 0
//! control_hz = 500.0             # controller rate (Hz), default 500
//! physics_hz = 1000.0            # minimum physics rate (Hz), ≥ 1000, default 1000;
//!                                # the plant takes ceil(physics_hz / control_hz) steps per tick
//! seed = 0                       # RNG seed (state noise), default 0
//! yaw_rad = 0.0                  # desired yaw ψ*(0) (rad), default 0
//! yaw_rate_rad_s = 0.0           # ψ*(t) = yaw_rad + yaw_rate_rad_s · t, default 0
//! controller = "geometric"       # optional: the controller `eval` uses when none is given
//!
//! [trajectory]                   # required; `kind` selects the shape (positions in m, world)
//! kind = "hover"                 # p* = position_m
//! position_m = [0.0, 0.0, 1.0]
//! # kind = "step"                # p* = from_m for t < at_s, to_m after
//! # from_m = [0,0,1]; to_m = [0.5,0,1]; at_s = 2.0
//! # kind = "circle"              # p* = center_m + radius_m (cos 2πt/T, sin 2πt/T, 0)
//! # center_m = [0,0,1]; radius_m = 0.5; period_s = 10.0
//! # kind = "spiral"              # circle + (0, 0, climb_m_s · t)
//! # center_m = [0,0,0.5]; radius_m = 0.5; period_s = 10.0; climb_m_s = 0.03
//! # kind = "diamond"             # visits waypoints_m in a loop, segment_s per leg (smooth,
//! #                              # zero velocity/acceleration/jerk at each waypoint),
//! # waypoints_m = [[..],[..]]; segment_s = 2.0; hold_s = 0.0   # pausing hold_s at each
//! # kind = "figure_eight"        # p* = start_m + (a sin θ, (a/2) sin 2θ, 0), θ going 0 → 2π
//! #                              # in duration_s along the septic smooth step (at rest at
//! #                              # both ends), then p* = start_m: firmware_sitl_plant's
//! #                              # --pilot trajectory figure
//! # start_m = [0,0,1]; half_width_m = 0.5; duration_s = 10.0; start_s = 0.0  # begins then
//!
//! [disturbance]                  # optional; all defaults = none
//! wind_m_s2 = [0.75, 0.75, 0.0]  # world wind as specific force w (m/s²): force m·w
//! wind_onset_s = 0.0             # wind acts from this time (s)
//! rotor_efficiency = [0.8, 0.8, 1.0, 1.0]  # δ₁..δ₄ in [0, 2]: thrust and torque factor
//! onset_s = 0.0                  # efficiencies apply from this time (s): a mid-flight
//!                                # rotor fault is an onset_s > 0
//! [[disturbance.wind_sines]]     # optional, repeatable: w(t) += A sin(2π f t + φ)
//! amplitude_m_s2 = [0.4, 0.0, 0.0]; frequency_hz = 0.5; phase_rad = 0.0
//! [[disturbance.wind_steps]]     # optional, repeatable: w(t) += wind_m_s2 on [from_s, until_s)
//! wind_m_s2 = [0.8, 0.6, 0.0]; from_s = 6.0; until_s = 16.0   # until_s optional (to the end)
//!
//! [effects]                      # optional; all off by default
//! rotor_drag = false
//! ground_effect = false
//! motor_tau_s = 0.0              # first-order motor lag time constant (s), 0 = off
//! command_delay_s = 0.0          # added delay controller → plant (s), physics steps, 0 = off
//! command_jitter_s = 0.0         # + a seeded uniform [0, this] s per tick, 0 = off
//! [effects.residual]             # optional: what a real vehicle's flights measured beyond
//!                                # the rigid body (sim::plant::Residual; bl-real-*.toml)
//! [effects.noise]                # measurement noise σ on the controller's state
//! pos_m = 0.0; vel_m_s = 0.0; att_rad = 0.0; rate_rad_s = 0.0
//! acc_m_s2 = 0.0                 # accelerometer noise σ (m/s²), its own random stream
//!
//! [vehicle]                      # optional; default: the CF2X of docs/design.md
//! mass_kg = 0.034                # mass (kg); the motors' top speed stays the CF2X's, so the
//!                                # thrust-to-weight ratio falls as the mass grows
//! inertia_kg_m2 = [1.82e-5, 1.82e-5, 2.821e-5]  # diag(J) (kg·m²)
//! rotor_efficiency = [1.0, 1.0, 0.9, 1.0]  # the vehicle's own rotors, in (0, 2], always on;
//!                                # multiplies `disturbance.rotor_efficiency`
//! # and, for another airframe (`crate::sim::vehicle`'s keys): gravity_m_s2, arm_xy_m,
//! # kf_n_per_rad_s2, km_nm_per_rad_s2, thrust_to_weight (top thrust over weight)
//!
//! [sensors]                      # optional; absent = the controller sees the (noisy) truth
//!                                # the Crazyflie's IMU, filters, pose source and EKF in the
//!                                # loop: see `sensors` for the keys and their defaults
//! gyro_lpf_hz = 80.0
//!
//! [start]                        # optional; default: at rest, level, on p*(0) with yaw ψ*(0)
//! position_m = [0.0, 0.0, 0.5]
//! velocity_m_s = [0.0, 0.0, 0.0] # world frame
//! rpy_rad = [0.0, 0.0, 0.0]      # roll, pitch, yaw (Z-Y-X)
//! rate_rad_s = [0.0, 0.0, 0.0]   # body angular velocity
//! ```
//!
//! Unknown keys are errors; every error names the file and the offending key.

use std::path::{Path, PathBuf};

mod reference;
mod validate;
pub use reference::{figure_eight, septic, trajectory_point};
use validate::validate;

use anyhow::{Context, Result};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::sim::plant::{
    rot_from_rpy, Disturbance, Effects, Plant, PlantState, VehicleParams, WindSine, WindStep,
    WindVariation,
};
use crate::sim::trajectory::TrajectoryPoint;

/// The reference trajectory's shape.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Trajectory {
    /// Hold a position.
    Hover {
        /// Position (m, world).
        position_m: [f64; 3],
    },
    /// Jump from one position to another at `at_s`.
    Step {
        /// Position before the step (m).
        from_m: [f64; 3],
        /// Position after the step (m).
        to_m: [f64; 3],
        /// Time of the step (s).
        at_s: f64,
    },
    /// Horizontal circle, counter-clockwise seen from above, starting at center + (radius, 0, 0).
    Circle {
        /// Center (m).
        center_m: [f64; 3],
        /// Radius (m).
        radius_m: f64,
        /// Period of one revolution (s).
        period_s: f64,
    },
    /// Circle climbing at a constant rate.
    Spiral {
        /// Center at t = 0 (m).
        center_m: [f64; 3],
        /// Radius (m).
        radius_m: f64,
        /// Period of one revolution (s).
        period_s: f64,
        /// Climb rate (m/s).
        climb_m_s: f64,
    },
    /// Smooth legs between waypoints, looping back to the first.
    Diamond {
        /// Waypoints (m), at least two.
        waypoints_m: Vec<[f64; 3]>,
        /// Duration of each leg (s).
        segment_s: f64,
        /// Pause at each waypoint (s).
        #[serde(default)]
        hold_s: f64,
    },
    /// One figure of eight from rest to rest: x = a sin θ, y = (a/2) sin 2θ about `start_m`,
    /// θ = 2π s(t / duration_s) with the septic smooth step s; `start_m` before and after.
    FigureEight {
        /// Start and end point, the figure's crossing (m).
        start_m: [f64; 3],
        /// a: half the figure's extent along x (m); along y it is a / 2.
        half_width_m: f64,
        /// Duration of the figure (s).
        duration_s: f64,
        /// When the figure begins (s); `start_m` until then.
        #[serde(default)]
        start_s: f64,
    },
}

/// The `[disturbance]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DisturbanceSpec {
    /// Wind specific force w (m/s², world).
    pub wind_m_s2: [f64; 3],
    /// Wind onset (s).
    pub wind_onset_s: f64,
    /// Rotor efficiencies δ₁..δ₄.
    pub rotor_efficiency: [f64; 4],
    /// Efficiency onset (s).
    pub onset_s: f64,
    /// Sinusoidal wind components (added).
    pub wind_sines: Vec<WindSine>,
    /// Wind steps (added).
    pub wind_steps: Vec<WindStep>,
}

impl Default for DisturbanceSpec {
    fn default() -> Self {
        Self {
            wind_m_s2: [0.0; 3],
            wind_onset_s: 0.0,
            rotor_efficiency: [1.0; 4],
            onset_s: 0.0,
            wind_sines: Vec::new(),
            wind_steps: Vec::new(),
        }
    }
}

impl DisturbanceSpec {
    /// The times (s) at which the disturbance changes abruptly, sorted: the wind onset and the
    /// efficiency onset when after t = 0, and each wind step's edges.
    pub fn event_times_s(&self) -> Vec<f64> {
        let mut t = Vec::new();
        if self.wind_onset_s > 0.0 && self.wind_m_s2 != [0.0; 3] {
            t.push(self.wind_onset_s);
        }
        if self.onset_s > 0.0 && self.rotor_efficiency != [1.0; 4] {
            t.push(self.onset_s);
        }
        for s in &self.wind_steps {
            t.push(s.from_s);
            t.extend(s.until_s);
        }
        t.sort_by(f64::total_cmp);
        t.dedup();
        t
    }
}

/// The `[vehicle]` table: what differs from the CF2X (every key optional).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VehicleSpec {
    /// Mass (kg).
    pub mass_kg: Option<f64>,
    /// Principal moments of inertia diag(J) (kg·m²).
    pub inertia_kg_m2: Option<[f64; 3]>,
    /// The vehicle's own rotor efficiencies (always on).
    pub rotor_efficiency: Option<[f64; 4]>,
    /// Gravity (m/s²).
    pub gravity_m_s2: Option<f64>,
    /// Rotor offset along each body axis (m), X layout.
    pub arm_xy_m: Option<f64>,
    /// Thrust coefficient k_F (N per (rad/s)²).
    pub kf_n_per_rad_s2: Option<f64>,
    /// Reaction-torque coefficient k_M (N·m per (rad/s)²).
    pub km_nm_per_rad_s2: Option<f64>,
    /// Top total thrust over weight (sets the top rotor speed). Without it a new mass keeps
    /// the CF2X's top rotor speed.
    pub thrust_to_weight: Option<f64>,
}

impl VehicleSpec {
    /// The CF2X with this table's changes. A new mass keeps the motors: the top rotor speed
    /// ([`VehicleParams::max_rpm`]) stays the CF2X's, so the thrust-to-weight ratio scales by
    /// 0.027 kg / mass.
    pub fn params(&self) -> VehicleParams {
        let mut v = VehicleParams::cf2x();
        if let Some(m) = self.mass_kg {
            v.thrust_to_weight *= v.mass_kg / m;
            v.mass_kg = m;
        }
        if let Some(j) = self.inertia_kg_m2 {
            v.inertia_kg_m2 = j;
        }
        if let Some(e) = self.rotor_efficiency {
            v.rotor_efficiency = e;
        }
        let per_rad = crate::sim::vehicle::RPM_PER_RAD_S.powi(2);
        if let Some(g) = self.gravity_m_s2 {
            v.gravity_m_s2 = g;
        }
        if let Some(a) = self.arm_xy_m {
            v.arm_xy_m = a;
        }
        if let Some(kf) = self.kf_n_per_rad_s2 {
            // The top thrust (thrust_to_weight) stays; the top rotor speed follows k_F.
            v.kf_n_per_rpm2 = kf / per_rad;
        }
        if let Some(km) = self.km_nm_per_rad_s2 {
            v.km_nm_per_rpm2 = km / per_rad;
        }
        if let Some(t) = self.thrust_to_weight {
            v.thrust_to_weight = t;
        }
        v
    }
}

/// The `[start]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartSpec {
    /// Initial position (m, world).
    pub position_m: [f64; 3],
    /// Initial velocity (m/s, world).
    #[serde(default)]
    pub velocity_m_s: [f64; 3],
    /// Initial roll, pitch, yaw (rad).
    #[serde(default)]
    pub rpy_rad: [f64; 3],
    /// Initial body angular velocity (rad/s).
    #[serde(default)]
    pub rate_rad_s: [f64; 3],
}

fn default_control_hz() -> f64 {
    500.0
}
fn default_physics_hz() -> f64 {
    1000.0
}

/// The file's contents, as parsed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioSpec {
    /// Scenario name.
    pub name: Option<String>,
    /// Free text.
    pub description: Option<String>,
    /// Flight length (s).
    pub duration_s: f64,
    /// Controller rate (Hz).
    #[serde(default = "default_control_hz")]
    pub control_hz: f64,
    /// Minimum physics rate (Hz).
    #[serde(default = "default_physics_hz")]
    pub physics_hz: f64,
    /// RNG seed.
    #[serde(default)]
    pub seed: u64,
    /// Desired yaw at t = 0 (rad).
    #[serde(default)]
    pub yaw_rad: f64,
    /// Desired yaw rate (rad/s).
    #[serde(default)]
    pub yaw_rate_rad_s: f64,
    /// Default controller name for `eval`.
    pub controller: Option<String>,
    /// Reference trajectory.
    pub trajectory: Trajectory,
    /// Disturbance.
    #[serde(default)]
    pub disturbance: DisturbanceSpec,
    /// Optional effects.
    #[serde(default)]
    pub effects: Effects,
    /// The vehicle, where it differs from the CF2X.
    #[serde(default)]
    pub vehicle: VehicleSpec,
    /// The sensor chain and estimator in the loop ([`crate::sim::sensors`]); none = the truth.
    #[serde(default)]
    pub sensors: Option<crate::sim::sensors::SensorSpec>,
    /// Initial state.
    pub start: Option<StartSpec>,
}

impl ScenarioSpec {
    /// A scenario built in code: `trajectory` for `duration_s` seconds, every other key at the
    /// default a file that leaves it out gets (500 Hz control, 1 kHz physics, seed 0, no
    /// disturbance, no effects, the CF2X, the true state).
    pub fn new(duration_s: f64, trajectory: Trajectory) -> Self {
        Self {
            name: None,
            description: None,
            duration_s,
            control_hz: default_control_hz(),
            physics_hz: default_physics_hz(),
            seed: 0,
            yaw_rad: 0.0,
            yaw_rate_rad_s: 0.0,
            controller: None,
            trajectory,
            disturbance: DisturbanceSpec::default(),
            effects: Effects::default(),
            vehicle: VehicleSpec::default(),
            sensors: None,
            start: None,
        }
    }
}

/// A validated scenario.
#[derive(Clone, Debug, PartialEq)]
pub struct Scenario {
    /// Name (the `name` key, else the file stem).
    pub name: String,
    /// The file it came from, if any.
    pub path: Option<PathBuf>,
    /// The parsed keys.
    pub spec: ScenarioSpec,
    /// Vehicle constants (the CF2X with the `[vehicle]` table's changes).
    pub vehicle: VehicleParams,
}

impl Scenario {
    /// Read and validate a scenario file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read scenario file `{}`", path.display()))?;
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scenario".into());
        let mut s = Self::from_toml_str(&text, &path.display().to_string(), &stem)?;
        s.path = Some(path.to_path_buf());
        Ok(s)
    }

    /// Parse and validate scenario TOML; `origin` names the source in errors, `default_name` is
    /// used when the file has no `name`.
    pub fn from_toml_str(text: &str, origin: &str, default_name: &str) -> Result<Self> {
        let spec: ScenarioSpec = toml::from_str(text)
            .map_err(|e| anyhow::anyhow!("bad scenario file `{origin}`: {e}"))?;
        validate(&spec).with_context(|| format!("bad scenario file `{origin}`"))?;
        Ok(Self {
            name: spec
                .name
                .clone()
                .unwrap_or_else(|| default_name.to_string()),
            path: None,
            vehicle: spec.vehicle.params(),
            spec,
        })
    }

    /// Build a scenario from a spec in code (validated).
    pub fn from_spec(name: &str, spec: ScenarioSpec) -> Result<Self> {
        validate(&spec).with_context(|| format!("bad scenario `{name}`"))?;
        Ok(Self {
            name: name.to_string(),
            path: None,
            vehicle: spec.vehicle.params(),
            spec,
        })
    }

    /// Control tick period (s).
    pub fn control_dt_s(&self) -> f64 {
        1.0 / self.spec.control_hz
    }

    /// Physics steps per control tick: ceil(physics_hz / control_hz), at least 1.
    pub fn physics_substeps(&self) -> usize {
        ((self.spec.physics_hz / self.spec.control_hz) - 1e-9)
            .ceil()
            .max(1.0) as usize
    }

    /// The disturbance the plant feels.
    pub fn disturbance(&self) -> Disturbance {
        let d = &self.spec.disturbance;
        Disturbance {
            wind_m_s2: d.wind_m_s2,
            wind_onset_s: d.wind_onset_s,
            rotor_efficiency: d.rotor_efficiency,
            efficiency_onset_s: d.onset_s,
        }
    }

    /// The initial state: the `[start]` table, else at rest on p*(0) with yaw ψ*(0).
    pub fn initial_state(&self) -> PlantState {
        match &self.spec.start {
            Some(st) => {
                let rot = rot_from_rpy(Vector3::from(st.rpy_rad));
                PlantState {
                    p_m: Vector3::from(st.position_m),
                    rot,
                    v_body_m_s: rot.transpose() * Vector3::from(st.velocity_m_s),
                    w_body_rad_s: Vector3::from(st.rate_rad_s),
                }
            }
            None => {
                let r = self.reference(0.0);
                PlantState::at_rest(r.p_m, r.yaw_rad)
            }
        }
    }

    /// The time-varying part of the wind.
    pub fn wind_variation(&self) -> WindVariation {
        WindVariation {
            sines: self.spec.disturbance.wind_sines.clone(),
            steps: self.spec.disturbance.wind_steps.clone(),
        }
    }

    /// A fresh plant at t = 0 in the initial state.
    pub fn plant(&self) -> Plant {
        let mut p = Plant::new(
            self.vehicle.clone(),
            self.disturbance(),
            self.spec.effects.clone(),
            self.initial_state(),
        );
        p.wind_variation = self.wind_variation();
        p
    }

    /// The reference at time `t_s`, with analytic derivatives up to jerk.
    pub fn reference(&self, t_s: f64) -> TrajectoryPoint {
        let mut tp = trajectory_point(&self.spec.trajectory, t_s);
        tp.yaw_rad = self.spec.yaw_rad + self.spec.yaw_rate_rad_s * t_s;
        tp.yaw_rate_rad_s = self.spec.yaw_rate_rad_s;
        tp
    }
}
