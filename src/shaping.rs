//! Setpoint shaping: a reference model that turns a jump of the setpoint into a motion the
//! vehicle can follow, so that the adaptation sees disturbances and not transients.
//!
//! **Why (windup).** The adaptation law (paper eq. `geometric_adaptive_law`) integrates
//! the tracking errors whatever their cause. A setpoint that jumps 0.5 m makes e_p ≈ 0.5 m for a
//! second; the law reads that as a disturbance and winds a up, and unwinding takes seconds
//! (the `step` scenario's figures with and without shaping: docs/adaptation.md). Clipping and
//! freezing the law's drive only halved it (see [`crate::adapt`]), because the tail of every
//! transient still looks like a disturbance. Model-reference adaptive control answers this at the source: the closed
//! loop is asked to follow a reference model, a motion it can actually fly, and the tracking
//! errors that remain are evidence about the model.
//!
//! **What.** The shaped setpoint is the raw one plus an offset δ (position, velocity,
//! acceleration and jerk) that obeys δ̈ = −ω² δ − 2ζω δ̇ (critically damped, ζ = 1). A jump of
//! the raw setpoint beyond what its own velocity and acceleration predict over the tick — more
//! than [`JUMP_POSITION_M`] or [`JUMP_VELOCITY_M_S`] — is absorbed into δ (a setpoint repeated
//! for several ticks, as a 100 Hz commander under a 500 Hz loop sends it, is predicted over
//! the whole hold), so the shaped
//! setpoint stays continuous and then converges to the raw one with time constant 1/ω. A smooth
//! trajectory never jumps: δ stays exactly zero and the controller sees the raw setpoint bit for
//! bit (paper-spiral is unchanged). Once δ has decayed below [`SETTLED_M`] it snaps to zero.

use crate::reference::Setpoint;
use nalgebra::Vector3;

/// A position jump (m) beyond the setpoint's own prediction that is shaped; smaller ones pass.
pub const JUMP_POSITION_M: f32 = 0.01;
/// A velocity jump (m/s) beyond the setpoint's own prediction that is shaped.
pub const JUMP_VELOCITY_M_S: f32 = 0.05;
/// Below this offset (m, and m/s for its rate) the shaped setpoint snaps back to the raw one.
pub const SETTLED_M: f32 = 1e-6;

/// While the shaped setpoint is further than this (m) from the raw one, the gradient law's
/// tracking term is frozen: the errors then belong to a commanded transient.
pub const SHAPING_FREEZE_M: f32 = 0.02;

/// The reference model's state: the raw setpoint's own prediction of the next tick, the offset
/// δ of the shaped setpoint, and the shaped setpoint while δ ≠ 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SetpointShaper {
    /// Whether `last_*` hold a setpoint (false before the first tick and after a reset).
    primed: bool,
    /// δ ≠ 0 (kept as a flag: the common, inactive tick tests one bool).
    active: bool,
    /// The last raw setpoint that differed from its predecessor: position, velocity and
    /// acceleration (m, m/s, m/s²).
    last_p_m: Vector3<f32>,
    last_v_m_s: Vector3<f32>,
    last_a_m_s2: Vector3<f32>,
    /// How long (s) the raw setpoint has been held unchanged since `last_*`: a commander that
    /// updates at 100 Hz repeats each setpoint for several ticks, and its next one follows
    /// from this one over the whole hold, not over one tick.
    held_s: f32,
    /// δ (m).
    offset_m: Vector3<f32>,
    /// δ̇ (m/s).
    offset_m_s: Vector3<f32>,
    /// The shaped setpoint of the last tick on which δ ≠ 0.
    shaped: Setpoint,
}

impl SetpointShaper {
    /// Forgets the past: the next setpoint passes unshaped.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// True while ‖δ‖ > [`SHAPING_FREEZE_M`]: the gradient law's tracking term is frozen.
    pub fn freezes_adaptation(&self) -> bool {
        self.active && self.offset_m.norm_squared() > SHAPING_FREEZE_M * SHAPING_FREEZE_M
    }

    /// True while the shaped setpoint differs from the raw one.
    pub fn is_active(&self) -> bool {
        self.active
    }

    /// The shaped setpoint for this tick of `dt_s` (s), with the reference model's natural
    /// frequency `omega_rad_s` (rad/s; 0 or less, or non-finite, turns shaping off).
    pub fn shape(&mut self, sp: &Setpoint, dt_s: f32, omega_rad_s: f32) -> Setpoint {
        if self.update(sp, dt_s, omega_rad_s) {
            self.shaped
        } else {
            *sp
        }
    }

    /// One tick of the reference model. Returns true if the setpoint is shaped this tick: it is
    /// then [`SetpointShaper::shaped`]; false means `sp` passes unchanged (the common case, with
    /// no copy on the control path).
    pub fn update(&mut self, sp: &Setpoint, dt_s: f32, omega_rad_s: f32) -> bool {
        if !(omega_rad_s > 0.0 && omega_rad_s.is_finite()) {
            if self.primed {
                self.reset();
            }
            return false;
        }
        let repeated = self.primed
            && sp.p_m == self.last_p_m
            && sp.v_m_s == self.last_v_m_s
            && sp.a_m_s2 == self.last_a_m_s2;
        if repeated {
            self.held_s += dt_s;
        } else {
            if self.primed {
                // Where the last distinct setpoint's own velocity and acceleration put it now.
                let t = self.held_s + dt_s;
                let a_t = self.last_a_m_s2 * t;
                let jump_p = sp.p_m - (self.last_p_m + (self.last_v_m_s + a_t * 0.5) * t);
                if jump_p.norm_squared() > JUMP_POSITION_M * JUMP_POSITION_M {
                    self.offset_m -= jump_p;
                    self.active = true;
                }
                let jump_v = sp.v_m_s - (self.last_v_m_s + a_t);
                if jump_v.norm_squared() > JUMP_VELOCITY_M_S * JUMP_VELOCITY_M_S {
                    self.offset_m_s -= jump_v;
                    self.active = true;
                }
            }
            self.last_p_m = sp.p_m;
            self.last_v_m_s = sp.v_m_s;
            self.last_a_m_s2 = sp.a_m_s2;
            self.held_s = 0.0;
            self.primed = true;
        }
        if !self.active {
            return false;
        }
        let (w2, two_w) = (omega_rad_s * omega_rad_s, 2.0 * omega_rad_s);
        let acc = -(self.offset_m * w2) - self.offset_m_s * two_w;
        // Semi-implicit Euler: stable for ω dt < 2 (ω = 3 rad/s at 500 Hz: 0.006).
        let next_v = self.offset_m_s + acc * dt_s;
        let next_p = self.offset_m + next_v * dt_s;
        if !(next_p.iter().chain(next_v.iter()).all(|x| x.is_finite())) {
            self.reset();
            return false;
        }
        self.offset_m_s = next_v;
        self.offset_m = next_p;
        let jerk = -(self.offset_m_s * w2) - acc * two_w;
        self.shaped = Setpoint {
            p_m: sp.p_m + self.offset_m,
            v_m_s: sp.v_m_s + self.offset_m_s,
            a_m_s2: sp.a_m_s2 + acc,
            j_m_s3: sp.j_m_s3 + jerk,
            ..*sp
        };
        if self.offset_m.norm_squared() < SETTLED_M * SETTLED_M
            && self.offset_m_s.norm_squared() < SETTLED_M * SETTLED_M
        {
            self.offset_m = Vector3::zeros();
            self.offset_m_s = Vector3::zeros();
            self.active = false;
        }
        true
    }

    /// The shaped setpoint of the last [`SetpointShaper::update`] that returned true.
    pub fn shaped(&self) -> &Setpoint {
        &self.shaped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f32 = 0.002;

    #[test]
    fn smooth_trajectory_passes_bit_for_bit() {
        let mut s = SetpointShaper::default();
        for k in 0..5000 {
            let t = k as f32 * DT;
            let sp = Setpoint {
                p_m: Vector3::new(libm::cosf(t), libm::sinf(t), 1.0 + 0.1 * t),
                v_m_s: Vector3::new(-libm::sinf(t), libm::cosf(t), 0.1),
                a_m_s2: Vector3::new(-libm::cosf(t), -libm::sinf(t), 0.0),
                ..Setpoint::default()
            };
            assert_eq!(s.shape(&sp, DT, 3.0), sp, "tick {k}");
        }
        assert!(!s.is_active());
    }

    #[test]
    fn a_step_becomes_continuous_and_converges() {
        let mut s = SetpointShaper::default();
        let from = Setpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0);
        let to = Setpoint::hover(Vector3::new(0.5, 0.0, 1.2), 0.0);
        assert_eq!(s.shape(&from, DT, 3.0), from);
        let first = s.shape(&to, DT, 3.0);
        assert!(
            (first.p_m - from.p_m).norm() < 1e-4,
            "no jump: {:?}",
            first.p_m
        );
        let mut last = first;
        let mut max_a = 0.0f32;
        for k in 1..3000 {
            let sh = s.shape(&to, DT, 3.0);
            // Continuous: never more than a few mm per tick, and monotone toward the target.
            assert!((sh.p_m - last.p_m).norm() < 0.01, "tick {k}");
            assert!(sh.p_m.x >= last.p_m.x - 1e-6, "tick {k}: overshoot back");
            max_a = max_a.max(sh.a_m_s2.norm());
            last = sh;
        }
        // ω² · 0.54 m ≈ 4.9 m/s² at the start, within a 0.6 rad tilt (6.7 m/s²).
        assert!(max_a < 5.5, "peak acceleration {max_a}");
        // After 6 s (ω t = 18) it is the raw setpoint again, exactly.
        assert_eq!(last, to);
        assert!(!s.is_active());
    }

    /// A commander at 100 Hz under the 500 Hz loop: each setpoint of a 2 m/s line is repeated
    /// for five ticks. The steps between them are what its velocity predicts: nothing shaped.
    #[test]
    fn a_setpoint_held_for_several_ticks_is_not_a_jump() {
        let mut s = SetpointShaper::default();
        for k in 0..2000 {
            let t_update = (k / 5) as f32 * 5.0 * DT;
            let sp = Setpoint {
                p_m: Vector3::new(2.0 * t_update, 0.0, 1.0),
                v_m_s: Vector3::new(2.0, 0.0, 0.0),
                ..Setpoint::default()
            };
            assert_eq!(s.shape(&sp, DT, 3.0), sp, "tick {k}");
            assert!(!s.is_active(), "tick {k}");
        }
    }

    #[test]
    fn off_and_small_jumps_pass_unchanged() {
        let mut s = SetpointShaper::default();
        let a = Setpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0);
        let b = Setpoint::hover(Vector3::new(0.005, 0.0, 1.0), 0.0);
        let far = Setpoint::hover(Vector3::new(3.0, 0.0, 1.0), 0.0);
        s.shape(&a, DT, 3.0);
        assert_eq!(s.shape(&b, DT, 3.0), b, "5 mm is below the jump threshold");
        for omega in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(s.shape(&far, DT, omega), far, "ω = {omega}");
            assert!(!s.is_active());
        }
    }
}
