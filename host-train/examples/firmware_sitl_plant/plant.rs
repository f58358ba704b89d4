//! The plant as flown here: stepped 1 ms with the motor command, on a ground it lacks (below
//! z = 0 the vehicle rests at z = 0, level, still), the IMU sample it gives the firmware, and
//! the checks for a crash.

use host_train::io::{imu_packet, pwm_to_rpm};
use host_train::{Plant, PlantState, TrajectoryPoint};
use nalgebra::Vector3;

/// One plant step per IMU packet.
const DT: f64 = 1e-3;

/// Every time-based disturbance of the plant moved `offset_s` later: the scenario's clock starts
/// when the hold does, as in `host-train eval`, where the flight starts at p*(0).
pub fn delay_disturbances(plant: &mut Plant, offset_s: f64) {
    plant.disturbance.wind_onset_s += offset_s;
    plant.disturbance.efficiency_onset_s += offset_s;
    for s in &mut plant.wind_variation.steps {
        s.from_s += offset_s;
        s.until_s = s.until_s.map(|u| u + offset_s);
    }
    for s in &mut plant.wind_variation.sines {
        s.phase_rad -= core::f64::consts::TAU * s.frequency_hz * offset_s;
    }
}

/// What became of the vehicle: on the ground or not, its touch-down, a crash.
pub struct Vehicle {
    /// The plant's rotor constant and gravity, as at the start.
    kf: f64,
    g: f64,
    pub on_ground: bool,
    pub airborne_once: bool,
    pub touchdown_speed: Option<f64>,
    /// After a lost link: the speed and tilt at which the vehicle reached the ground.
    pub fall: Option<(f64, f64)>,
    pub crash: Option<(f64, String)>,
}

impl Vehicle {
    /// On the ground, never airborne yet.
    pub fn new(plant: &Plant) -> Self {
        Vehicle {
            kf: plant.params.kf_n_per_rpm2,
            g: plant.params.gravity_m_s2,
            on_ground: true,
            airborne_once: false,
            touchdown_speed: None,
            fall: None,
            crash: None,
        }
    }

    /// 1 ms of plant with the motor command `pwm` at plant time `t`, then the ground: a
    /// touch-down is a crash above 1 m/s or 30° of tilt, or with the motors off (a lost link), a
    /// fall.
    pub fn step(
        &mut self,
        plant: &mut Plant,
        pwm: [u16; 4],
        t: f64,
        phase: &str,
        motors_off: bool,
    ) -> PlantState {
        let rpm = pwm.map(|m| pwm_to_rpm(m, self.kf));
        plant.step(rpm, DT);
        let mut s = *plant.state();
        if s.p_m.z <= 0.0 {
            let vz = s.v_world_m_s().z;
            if !self.on_ground && self.airborne_once && self.touchdown_speed.is_none() {
                self.touchdown_speed = Some(-vz);
                let tilt = s.rot[(2, 2)].clamp(-1.0, 1.0).acos().to_degrees();
                if motors_off {
                    self.fall = Some((-vz, tilt));
                } else if (-vz > 1.0 || tilt > 30.0) && self.crash.is_none() {
                    self.crash = Some((
                        t,
                        format!("hit the ground at {:.2} m/s, tilt {tilt:.0} deg", -vz),
                    ));
                }
            }
            self.on_ground = true;
            let yaw = s.rpy().z;
            s = PlantState::at_rest(Vector3::new(s.p_m.x, s.p_m.y, 0.0), yaw);
            plant.set_state(s);
        } else if s.p_m.z > 0.02 {
            if self.on_ground && phase != "boot" && phase != "settle" {
                self.airborne_once = true;
                self.touchdown_speed = None;
            }
            self.on_ground = false;
        }
        s
    }

    /// The crash checks on the state `s` at plant time `t`: upside down, more than 2 m from the
    /// setpoint (unless the link is lost); `false` if the state is no longer finite (the
    /// flight ends).
    pub fn check(
        &mut self,
        s: &PlantState,
        t: f64,
        setpoint: &Option<TrajectoryPoint>,
        link_lost: bool,
    ) -> bool {
        if !s.is_finite() {
            self.crash.get_or_insert((t, "non-finite state".into()));
            return false;
        }
        if s.rot[(2, 2)] < 0.0 {
            self.crash.get_or_insert((t, "upside down".into()));
        }
        if let (Some(sp), false) = (setpoint, link_lost) {
            if (s.p_m - sp.p_m).norm() > 2.0 {
                self.crash
                    .get_or_insert((t, "more than 2 m from the setpoint".into()));
            }
        }
        true
    }

    /// The IMU packet of the state `s`: on the ground the accelerometer reads the normal force,
    /// 1 g up.
    pub fn imu(&self, plant: &Plant, s: &PlantState) -> Vec<u8> {
        let acc = if self.on_ground {
            Vector3::new(0.0, 0.0, self.g)
        } else {
            plant.accelerometer()
        };
        imu_packet(acc / self.g, s.w_body_rad_s.map(f64::to_degrees))
    }
}
