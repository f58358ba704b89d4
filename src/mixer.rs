//! The mixer: a body wrench [f; τ] to four rotor thrusts and speeds for the CF2X X layout,
//! saturating so that attitude authority is kept.
//!
//! Rotor numbering (the Crazyflie's): 1 front-right (+x, −y), 2 back-right (−x, −y),
//! 3 back-left (−x, +y), 4 front-left (+x, +y); body x forward, z up. Rotor i at (xᵢ, yᵢ) with
//! thrust Tᵢ gives τx = Σ yᵢ Tᵢ, τy = −Σ xᵢ Tᵢ and a reaction torque τz = Σ sᵢ (k_m/k_f) Tᵢ with
//! s = (−, +, −, +).

use nalgebra::Vector3;

/// A body-frame wrench u = [f; τ]: what the controller asks of the rotors (paper's u).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Wrench {
    /// Collective thrust along body z (N).
    pub thrust_n: f32,
    /// Body torques about x, y, z (N·m).
    pub torque_nm: Vector3<f32>,
}

/// Four rotor commands, rotors 1..4.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RotorCommand {
    /// Thrust of each rotor (N), within the airframe's limits.
    pub thrust_n: [f32; 4],
    /// Speed of each rotor (rpm) that gives that thrust: √(T / k_f).
    pub rpm: [f32; 4],
}

impl RotorCommand {
    /// All rotors stopped: the safe output on any fault.
    pub const OFF: Self = Self {
        thrust_n: [0.0; 4],
        rpm: [0.0; 4],
    };
}

/// What the mixer had to give up to stay within the rotor limits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Saturation {
    /// The yaw torque was scaled down to keep roll/pitch authority.
    pub yaw: bool,
    /// The roll/pitch torques were scaled down (not even they fit).
    pub roll_pitch: bool,
    /// The collective thrust was shifted to fit the torques between the limits.
    pub thrust: bool,
}

impl Saturation {
    /// True if anything saturated.
    pub fn any(&self) -> bool {
        self.yaw || self.roll_pitch || self.thrust
    }
}

/// The rotor geometry and coefficients.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Airframe {
    /// Rotor offset along body x and y (m): rotors sit at (±d, ±d).
    pub arm_xy_m: f32,
    /// Thrust coefficient k_f (N/rpm²).
    pub kf_n_per_rpm2: f32,
    /// Torque coefficient k_m (N·m/rpm²).
    pub km_nm_per_rpm2: f32,
    /// Largest rotor speed (rpm).
    pub max_rpm: f32,
}

impl Default for Airframe {
    /// The Crazyflie CF2X of gym-pybullet-drones: d = 0.028 m, k_f = 3.16e-10, k_m = 7.94e-12,
    /// max speed from thrust-to-weight 2.25 at 0.027 kg (≈ 21 702 rpm).
    fn default() -> Self {
        let kf = 3.16e-10;
        let max_thrust_per_rotor = 2.25 * 0.027 * 9.8 / 4.0;
        Self {
            arm_xy_m: 0.028,
            kf_n_per_rpm2: kf,
            km_nm_per_rpm2: 7.94e-12,
            max_rpm: libm::sqrtf(max_thrust_per_rotor / kf),
        }
    }
}

fn min_max(v: &[f32; 4]) -> (f32, f32) {
    v.iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), x| (lo.min(*x), hi.max(*x)))
}

/// Signs (a, b, c) of rotor i's share of τx, τy, τz in the inverse mixer.
const SIGNS: [[f32; 3]; 4] = [
    [-1.0, -1.0, -1.0],
    [-1.0, 1.0, 1.0],
    [1.0, 1.0, -1.0],
    [1.0, -1.0, 1.0],
];

impl Airframe {
    /// Largest thrust of one rotor (N).
    pub fn max_rotor_thrust_n(&self) -> f32 {
        self.kf_n_per_rpm2 * self.max_rpm * self.max_rpm
    }

    /// The wrench that rotor thrusts `t` (N) produce: the forward mixer.
    pub fn wrench(&self, t: &[f32; 4]) -> Wrench {
        let d = self.arm_xy_m;
        let k = self.km_nm_per_rpm2 / self.kf_n_per_rpm2;
        let mut w = Wrench::default();
        for (ti, s) in t.iter().zip(SIGNS.iter()) {
            w.thrust_n += ti;
            w.torque_nm += Vector3::new(s[0] * d, s[1] * d, s[2] * k) * *ti;
        }
        w
    }

    /// Rotor thrusts and speeds for a wrench, within [0, max] per rotor.
    ///
    /// Priorities when the wrench does not fit: roll/pitch torque first, then collective thrust,
    /// then yaw torque. Roll/pitch is scaled down only if it alone spans more than the rotor
    /// range; the collective moves as little as possible to make room for it; yaw is scaled to
    /// what is left. A non-finite wrench gives [`RotorCommand::OFF`].
    pub fn mix(&self, u: &Wrench) -> (RotorCommand, Saturation) {
        let mut sat = Saturation::default();
        let d4 = 4.0 * self.arm_xy_m;
        let k4 = 4.0 * self.km_nm_per_rpm2 / self.kf_n_per_rpm2;
        let t_max = self.max_rotor_thrust_n();
        let finite = u.thrust_n.is_finite() && u.torque_nm.iter().all(|v| v.is_finite());
        let valid_airframe = d4 > 0.0 && k4 > 0.0 && t_max > 0.0;
        if !(finite && valid_airframe) {
            return (RotorCommand::OFF, sat);
        }
        let tx = u.torque_nm.x / d4;
        let ty = u.torque_nm.y / d4;
        let tz = u.torque_nm.z / k4;
        let mut rp = [0.0f32; 4];
        let mut yaw = [0.0f32; 4];
        for ((r, y), sg) in rp.iter_mut().zip(yaw.iter_mut()).zip(SIGNS.iter()) {
            *r = sg[0] * tx + sg[1] * ty;
            *y = sg[2] * tz;
        }
        // 1. Roll/pitch alone must fit between the limits.
        let (lo, hi) = min_max(&rp);
        if hi - lo > t_max {
            let k = t_max / (hi - lo);
            rp.iter_mut().for_each(|r| *r *= k);
            sat.roll_pitch = true;
        }
        // 2. The collective moves as little as possible to make room for roll/pitch.
        let (lo, hi) = min_max(&rp);
        let wanted = u.thrust_n / 4.0;
        // max/min rather than clamp: no panic path even for bounds that cross.
        let mean = wanted.min(t_max - hi).max(-lo);
        sat.thrust = mean != wanted;
        // 3. Yaw gets what is left at that collective.
        let mut yaw_scale = 1.0f32;
        for (r, y) in rp.iter().zip(yaw.iter()) {
            let base = mean + r;
            if *y > 0.0 {
                yaw_scale = yaw_scale.min((t_max - base) / y);
            } else if *y < 0.0 {
                yaw_scale = yaw_scale.min(base / -y);
            }
        }
        let yaw_scale = yaw_scale.clamp(0.0, 1.0); // constant bounds: the check folds away
        sat.yaw = yaw_scale < 1.0;
        let mut share = [0.0f32; 4];
        for ((s, r), y) in share.iter_mut().zip(rp.iter()).zip(yaw.iter()) {
            *s = r + yaw_scale * y;
        }
        let mut cmd = RotorCommand::OFF;
        for ((t, r), s) in cmd
            .thrust_n
            .iter_mut()
            .zip(cmd.rpm.iter_mut())
            .zip(share.iter())
        {
            *t = (mean + s).max(0.0).min(t_max);
            *r = crate::fpu::sqrt(*t / self.kf_n_per_rpm2);
        }
        (cmd, sat)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mix_inverts_the_forward_mixer_when_feasible() {
        let af = Airframe::default();
        let u = Wrench {
            thrust_n: 0.3,
            torque_nm: Vector3::new(1e-3, -5e-4, 2e-4),
        };
        let (cmd, sat) = af.mix(&u);
        assert!(!sat.any());
        let back = af.wrench(&cmd.thrust_n);
        assert!((back.thrust_n - u.thrust_n).abs() < 1e-6);
        assert!((back.torque_nm - u.torque_nm).norm() < 1e-8);
    }

    #[test]
    fn rotor_one_front_right_raises_roll_negative() {
        let af = Airframe::default();
        let w = af.wrench(&[1.0, 0.0, 0.0, 0.0]);
        // Rotor 1 at (+x, −y): τx = y T < 0, τy = −x T < 0, reaction torque negative.
        assert!(w.torque_nm.x < 0.0 && w.torque_nm.y < 0.0 && w.torque_nm.z < 0.0);
    }

    #[test]
    fn saturation_keeps_roll_pitch_over_yaw() {
        let af = Airframe::default();
        let u = Wrench {
            thrust_n: 0.26,
            torque_nm: Vector3::new(2e-3, 0.0, 5e-3),
        };
        let (cmd, sat) = af.mix(&u);
        assert!(sat.yaw);
        let back = af.wrench(&cmd.thrust_n);
        assert!((back.torque_nm.x - 2e-3).abs() < 1e-6);
        assert!(cmd
            .thrust_n
            .iter()
            .all(|t| *t >= 0.0 && *t <= af.max_rotor_thrust_n()));
    }
}
