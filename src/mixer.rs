//! The mixer: a body wrench [f; τ] to four rotor thrusts and speeds for the CF2X X layout,
//! saturating so that attitude authority is kept: roll/pitch first, then yaw, then collective
//! thrust within a band.
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

/// The smaller of two finite values: a compare and a select (`f32::min` is a library call on
/// the Cortex-M4F, whose FPU has no min instruction; the mixer's inputs are checked finite).
#[inline(always)]
fn lesser(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// The larger of two finite values (see [`lesser`]).
#[inline(always)]
fn greater(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

fn min_max(v: &[f32; 4]) -> (f32, f32) {
    let [a, b, c, d] = *v;
    (
        lesser(lesser(a, b), lesser(c, d)),
        greater(greater(a, b), greater(c, d)),
    )
}

/// The share of the wanted collective thrust that the collective may give up (or gain) to make
/// room for the yaw torque ([`Airframe::mix`], step 3): beyond it yaw gives way.
pub const YAW_COLLECTIVE_BAND: f32 = 0.25;

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
    /// Priorities when the wrench does not fit the rotors' range: roll/pitch torque first, then
    /// yaw torque, then collective thrust, within a band.
    /// 1. Roll/pitch is scaled down only if it alone spans more than the rotor range.
    /// 2. The collective moves as little as possible to make room for roll/pitch.
    /// 3. Yaw gets what fits with the collective free to move by up to
    ///    [`YAW_COLLECTIVE_BAND`] of the wanted one (so a vehicle that cannot hold its heading
    ///    still does not fall out of the sky for it); what does not fit is scaled away.
    /// 4. The collective is the one nearest the wanted one at which that yaw fits.
    ///
    /// A weak rotor (a rotor loss) needs yaw before the collective: its diagonal partner must
    /// slow down with it to hold roll and pitch, which leaves a yaw torque that only the
    /// other pair can answer. A non-finite wrench gives [`RotorCommand::OFF`].
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
        for (r, sg) in rp.iter_mut().zip(SIGNS.iter()) {
            *r = sg[0] * tx + sg[1] * ty;
        }
        // 1. Roll/pitch alone must fit between the limits.
        let (lo, hi) = min_max(&rp);
        if hi - lo > t_max {
            let k = t_max / (hi - lo);
            rp.iter_mut().for_each(|r| *r *= k);
            sat.roll_pitch = true;
        }
        // 2. The collective nearest the wanted one that roll/pitch leaves room for.
        let (lo, hi) = min_max(&rp);
        let wanted = u.thrust_n / 4.0;
        // max/min rather than clamp: no panic path even for bounds that cross.
        let mean_rp = greater(lesser(wanted, t_max - hi), -lo);
        // 3. Yaw: every rotor's share moves by ±e (e = |τz| / 4k at full yaw), up on the
        // rotors whose reaction torque has τz's sign (`up`), down on the others. With the
        // collective m in the band [band_lo, band_hi], the largest e that fits is
        // max over m of min(t_max − hi_up − m, m + lo_down): the two meet at m*.
        let band = YAW_COLLECTIVE_BAND * greater(wanted, 0.0);
        let band_lo = greater(mean_rp - band, -lo);
        let band_hi = lesser(mean_rp + band, t_max - hi);
        let c = tz.abs();
        let (mut hi_up, mut lo_down) = (f32::MIN, f32::MAX);
        let mut dir = [0.0f32; 4];
        for ((d, r), sg) in dir.iter_mut().zip(rp.iter()).zip(SIGNS.iter()) {
            *d = if sg[2] * tz >= 0.0 { 1.0 } else { -1.0 };
            if *d > 0.0 {
                hi_up = greater(hi_up, *r);
            } else {
                lo_down = lesser(lo_down, *r);
            }
        }
        let m_star = greater(lesser((t_max - hi_up - lo_down) * 0.5, band_hi), band_lo);
        let e = greater(
            lesser(lesser(t_max - hi_up - m_star, m_star + lo_down), c),
            0.0,
        );
        sat.yaw = e < c;
        // 4. The collective nearest the wanted one at which that yaw fits.
        let mean = greater(
            lesser(mean_rp, lesser(t_max - hi_up - e, band_hi)),
            greater(e - lo_down, band_lo),
        );
        sat.thrust = mean != wanted;
        let mut cmd = RotorCommand::OFF;
        for (((t, rpm), r), d) in cmd
            .thrust_n
            .iter_mut()
            .zip(cmd.rpm.iter_mut())
            .zip(rp.iter())
            .zip(dir.iter())
        {
            *t = lesser(greater(mean + r + d * e, 0.0), t_max);
            *rpm = crate::fpu::sqrt(*t / self.kf_n_per_rpm2);
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

    fn fits(af: &Airframe, cmd: &RotorCommand) -> bool {
        cmd.thrust_n
            .iter()
            .all(|t| *t >= 0.0 && *t <= af.max_rotor_thrust_n())
    }

    #[test]
    fn saturation_keeps_roll_pitch_then_yaw_and_the_collective_gives_way_in_its_band() {
        let af = Airframe::default();
        let t_max = af.max_rotor_thrust_n();
        // What a weak rotor 1 asks for: rotor 1 beyond its top, the others below. The spread
        // fits the range, so every torque is kept exactly and the collective drops 12 %.
        let want = af.wrench(&[1.1 * t_max, 0.7 * t_max, 0.9 * t_max, 0.7 * t_max]);
        let (cmd, sat) = af.mix(&want);
        assert!(fits(&af, &cmd));
        let got = af.wrench(&cmd.thrust_n);
        assert!(!sat.roll_pitch && !sat.yaw && sat.thrust, "{sat:?}");
        assert!((got.torque_nm - want.torque_nm).norm() < 1e-8, "{got:?}");
        assert!(got.thrust_n < want.thrust_n);
        assert!(got.thrust_n >= (1.0 - YAW_COLLECTIVE_BAND) * want.thrust_n);
    }

    #[test]
    fn yaw_gives_way_beyond_the_collective_band() {
        let af = Airframe::default();
        let want = Wrench {
            thrust_n: 0.26,
            torque_nm: Vector3::new(2e-3, 0.0, 6e-3),
        };
        let (cmd, sat) = af.mix(&want);
        assert!(sat.yaw, "{sat:?}");
        assert!(fits(&af, &cmd));
        let got = af.wrench(&cmd.thrust_n);
        // Roll kept exactly, yaw partly, the collective within its band.
        assert!((got.torque_nm.x - 2e-3).abs() < 1e-6);
        assert!(got.torque_nm.z > 0.0 && got.torque_nm.z < 6e-3);
        let band = YAW_COLLECTIVE_BAND * want.thrust_n;
        assert!((got.thrust_n - want.thrust_n).abs() <= band * (1.0 + 1e-4));
    }

    #[test]
    fn priorities_hold_for_any_wrench() {
        // A deterministic sweep: every wrench mixes into the rotor range; roll/pitch is kept in
        // direction and exactly whenever it fits alone; yaw keeps its sign; the collective
        // moves only within its band around the one roll/pitch leaves room for.
        let af = Airframe::default();
        let t_max = af.max_rotor_thrust_n();
        let mut seed = 0x2545_f491u32;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f32 / u32::MAX as f32 * 2.0 - 1.0
        };
        for _ in 0..20_000 {
            let want = Wrench {
                thrust_n: (rnd() + 1.0) * 2.5 * t_max,
                torque_nm: Vector3::new(rnd() * 8e-3, rnd() * 8e-3, rnd() * 8e-3),
            };
            let (cmd, sat) = af.mix(&want);
            assert!(fits(&af, &cmd), "{want:?} -> {cmd:?}");
            let got = af.wrench(&cmd.thrust_n);
            let (w, g) = (want.torque_nm, got.torque_nm);
            if !sat.roll_pitch {
                // Clipping at the limits does not touch roll/pitch when it fits.
                assert!(
                    (g.x - w.x).abs() < 2e-6 && (g.y - w.y).abs() < 2e-6,
                    "{want:?} {got:?}"
                );
            } else {
                // Scaled, not turned: the same direction in the roll/pitch plane.
                let cross = g.x * w.y - g.y * w.x;
                assert!(
                    cross.abs() < 1e-6 * (w.x.abs() + w.y.abs()).max(1e-3),
                    "{want:?} {got:?}"
                );
            }
            assert!(g.z * w.z >= -1e-9, "yaw keeps its sign: {want:?} {got:?}");
            if !sat.yaw {
                assert!((g.z - w.z).abs() < 2e-6, "{want:?} {got:?} {sat:?}");
            }
        }
    }
}
