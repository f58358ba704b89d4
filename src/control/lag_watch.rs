//! The motor-lag watch: the attitude loop's gains and lead are designed for the motor lag the
//! blob states ([`Gains::for_vehicle`]), and a stated lag far from the motors' own leaves the
//! loop a few ms of delay margin (docs/envelope.md). The watch reads the motors' lag from the
//! flight itself and redesigns the loop for it when the stated one is plainly wrong.
//!
//! Per tick, for roll and pitch, it compares the measured torque J ω̇ + ω × Jω (high-passed,
//! so the slow disturbance drops out) with the delivered torque through first-order lags of
//! [`CANDIDATE_TAUS_S`] and of the lag in use (high-passed alike). For each it keeps the
//! low-passed correlations, and so the share of J ω̇ that the best scaled copy of the lagged
//! command leaves unexplained (1 − ρ², a scale error of J or of the torque gain costs nothing).
//! While the loop is excited (a limit cycle, or a lag that makes one grow), the watch switches
//! to the candidate that leaves at most [`SWITCH_RATIO`] of the lag in use's share, once it has
//! done so for [`SWITCH_HOLD_S`]. A calm flight never switches, whatever its lag: there the loop
//! holds the stated lag's design (the matrix's zero-delay cells all fly).

use super::*;

/// The motor lags the watch weighs against the lag in use (s): from ideal rotors to a slow
/// brushed motor behind a command delay.
pub const CANDIDATE_TAUS_S: [f32; 4] = [0.0, 0.02, 0.05, 0.1];

/// The command delays (control ticks) each lag is weighed with: a lag and a delay look alike
/// at one frequency, so a pure-lag candidate would stand in for the delay too.
pub const DELAY_TICKS: [usize; 2] = [0, 4];

/// Lags per delay row: the lag in use first, then the candidates.
const LAGS: usize = CANDIDATE_TAUS_S.len() + 1;

/// Slots: per delay row ([`DELAY_TICKS`]), the lag in use and the candidates.
pub const SLOTS: usize = LAGS * DELAY_TICKS.len();

/// Ticks of the high-passed command kept: the longest delay and the current one.
const HISTORY: usize = 5;

/// The watch weighs roll and pitch as one signal, τ_x + [`PITCH_WEIGHT`] τ_y (the lag is the
/// same linear filter on both, so it holds for the sum; unequal weights keep a diagonal
/// oscillation from cancelling): half the work of two.
pub const PITCH_WEIGHT: f32 = 0.5;

/// The watch decides every this many ticks (its filters run every tick).
pub const DECIDE_TICKS: u8 = 8;

/// The high-pass on the measured and predicted torques (s): slower than the attitude loop's
/// oscillations (> 3 Hz), faster than a disturbance's drift.
pub const HIGH_PASS_TAU_S: f32 = 0.05;

/// The window of the correlations (s).
pub const WINDOW_S: f32 = 0.25;

/// The excitation at which a limit cycle counts whatever it does: the high-passed measured
/// torque's power ((N·m)², 3e-4 N·m RMS). A limit cycle through the mixer's limits is about
/// 1e-3 N·m and more.
pub const MIN_EXCITATION_NM2: f32 = 9e-8;

/// A growing oscillation excites the loop too, long before it is large: the power above
/// [`GROWTH_FLOOR_NM2`] and at least [`GROWTH_RATIO`] times its own low-pass over
/// [`GROWTH_TAU_S`] (power growing by e every 0.13 s or faster, a loop going unstable).
pub const GROWTH_RATIO: f32 = 2.5;

/// See [`GROWTH_RATIO`] (s).
pub const GROWTH_TAU_S: f32 = 0.2;

/// The least power a growth counts from ((N·m)², 1e-6 N·m RMS: far below any flight's).
pub const GROWTH_FLOOR_NM2: f32 = 1e-12;

/// The unexplained share a candidate must leave at most, against the lag in use's.
pub const SWITCH_RATIO: f32 = 0.65;

/// How long a candidate must win before the watch switches to it (s), on growth alone: the
/// onset of any excitation grows for a while too.
pub const SWITCH_HOLD_S: f32 = 0.2;

/// [`SWITCH_HOLD_S`] when the excitation is above [`MIN_EXCITATION_NM2`] (s): a loop that is
/// already oscillating that hard has no time to lose.
pub const SWITCH_HOLD_EXCITED_S: f32 = 0.05;

/// The shortest time between two switches (s): the redesigned loop settles first.
pub const SWITCH_REST_S: f32 = 0.5;

/// The lag watch's state ([`FlightController::motor_lag_s`] reads its verdict).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagWatch {
    /// The lag in use (s): the stated one until a switch.
    pub(super) tau_s: f32,
    /// The lag the gains were built for (s): [`FlightController::reset`] returns to it.
    pub(super) stated_tau_s: Option<f32>,
    /// The previous tick's body rate (rad/s) and delivered torque signal (N·m).
    prev: Option<(Vector3<f32>, f32)>,
    /// The high-pass states of the measured and of the delivered torque signal.
    m_low: f32,
    u_low: f32,
    /// The high-passed command now and up to [`HISTORY`] − 1 ticks back.
    history: [f32; HISTORY],
    /// The measured signal's power, and its slow low-pass ([`GROWTH_TAU_S`]).
    m_power: f32,
    m_power_slow: f32,
    /// Per slot: the high-passed command through the slot's lag (the two filters commute), its
    /// power and its cross power with the measured torque.
    y: [f32; SLOTS],
    y_power: [f32; SLOTS],
    cross: [f32; SLOTS],
    /// The winning candidate and for how long (s); time since the last switch (s); ticks to
    /// the next decision.
    winner: Option<(u8, f32)>,
    rest_s: f32,
    tick: u8,
}

impl Default for LagWatch {
    fn default() -> Self {
        Self {
            tau_s: 0.0,
            stated_tau_s: None,
            prev: None,
            m_low: 0.0,
            u_low: 0.0,
            history: [0.0; HISTORY],
            m_power: 0.0,
            m_power_slow: 0.0,
            y: [0.0; SLOTS],
            y_power: [0.0; SLOTS],
            cross: [0.0; SLOTS],
            winner: None,
            rest_s: SWITCH_REST_S,
            tick: 0,
        }
    }
}

/// The gain of a first-order low-pass of time constant `tau_s` over `dt_s` (1 for none).
#[inline(always)]
fn pole(tau_s: f32, dt_s: f32) -> f32 {
    if tau_s > 0.0 {
        dt_s / (tau_s + dt_s)
    } else {
        1.0
    }
}

/// The lag slot `i` stands for: in each delay row the lag in use, then [`CANDIDATE_TAUS_S`].
#[inline(always)]
fn slot_tau(i: usize, in_use: f32) -> f32 {
    match (i % LAGS).checked_sub(1) {
        None => in_use,
        Some(j) => CANDIDATE_TAUS_S.get(j).copied().unwrap_or(in_use),
    }
}

/// The command delay (ticks) of slot `i`.
#[inline(always)]
fn slot_delay(i: usize) -> usize {
    DELAY_TICKS.get(i / LAGS).copied().unwrap_or(0)
}

/// How far the watch lets the torque's scale be off (J, the torque gain, a weak rotor): a slot
/// is compared at its best scale within [1 / this, this] of the delivered torque. The scale
/// is bounded because the phase alone cannot tell a lag from a delay at one frequency (a limit
/// cycle's), while the amplitude can: a lag attenuates, a delay does not.
pub const SCALE_SPAN: f32 = 2.0;

/// The share of the measured power the slot, at its best scale within [`SCALE_SPAN`], leaves
/// unexplained: ‖m − s y‖² / ‖m‖² (1 when there is nothing to compare).
#[inline(always)]
fn unexplained(m_power: f32, y_power: f32, cross: f32) -> f32 {
    if !(m_power > 0.0 && y_power > 0.0) {
        return 1.0;
    }
    // Constant, ordered bounds: `clamp` cannot panic here.
    let s = (cross / y_power).clamp(1.0 / SCALE_SPAN, SCALE_SPAN);
    let r = (m_power - 2.0 * s * cross + s * s * y_power) / m_power;
    if r > 0.0 {
        r
    } else {
        0.0
    }
}

impl LagWatch {
    /// The high-passed measured torque's power ((N·m)², over [`WINDOW_S`]).
    pub fn excitation_nm2(&self) -> f32 {
        self.m_power
    }

    /// The share of the measured torque each slot leaves unexplained: per delay row
    /// ([`DELAY_TICKS`]) the lag in use, then [`CANDIDATE_TAUS_S`].
    pub fn unexplained(&self) -> [f32; SLOTS] {
        let mut out = [1.0; SLOTS];
        for ((o, &p), &c) in out
            .iter_mut()
            .zip(self.y_power.iter())
            .zip(self.cross.iter())
        {
            *o = unexplained(self.m_power, p, c);
        }
        out
    }

    /// Forgets the flight (the lag in use stays).
    pub(super) fn restart(&mut self) {
        *self = Self {
            tau_s: self.tau_s,
            stated_tau_s: self.stated_tau_s,
            ..Self::default()
        };
    }

    /// One tick: `w` the body rate now (rad/s), `j` diag(J) (kg·m²), `delivered` the roll and
    /// pitch torque the rotors were just commanded to deliver (N·m). Returns a new lag (s) when
    /// the watch switches.
    pub(super) fn observe(
        &mut self,
        w: &Vector3<f32>,
        j: &Vector3<f32>,
        delivered: [f32; 2],
        dt_s: f32,
    ) -> Option<f32> {
        let [ux, uy] = delivered;
        let (w_prev, applied) = self.prev.replace((*w, ux + PITCH_WEIGHT * uy))?;
        self.rest_s += dt_s;
        // J ω̇ + ω × Jω about x and y (weighed as one): the torque that acted over the tick.
        let jw = j.component_mul(w);
        let gyro = w.cross(&jw);
        let dw = (w - w_prev) / dt_s;
        let m = j.x * dw.x + gyro.x + PITCH_WEIGHT * (j.y * dw.y + gyro.y);
        let (hp, win) = (pole(HIGH_PASS_TAU_S, dt_s), pole(WINDOW_S, dt_s));
        self.m_low += hp * (m - self.m_low);
        let mh = m - self.m_low;
        self.u_low += hp * (applied - self.u_low);
        self.history.rotate_right(1);
        if let Some(now) = self.history.first_mut() {
            *now = applied - self.u_low;
        }
        self.m_power += win * (mh * mh - self.m_power);
        self.m_power_slow += pole(GROWTH_TAU_S, dt_s) * (self.m_power - self.m_power_slow);
        let in_use = self.tau_s;
        for (i, ((y, yp), cr)) in self
            .y
            .iter_mut()
            .zip(self.y_power.iter_mut())
            .zip(self.cross.iter_mut())
            .enumerate()
        {
            let u = self.history.get(slot_delay(i)).copied().unwrap_or(0.0);
            *y += pole(slot_tau(i, in_use), dt_s) * (u - *y);
            *yp += win * (*y * *y - *yp);
            *cr += win * (*y * mh - *cr);
        }
        self.tick = self.tick.wrapping_add(1);
        if self.tick < DECIDE_TICKS {
            return None;
        }
        self.tick = 0;
        self.decide(in_use, dt_s * f32::from(DECIDE_TICKS))
    }

    /// The decision over the last `span_s` (s): the best candidate against the lag in use.
    #[inline(never)]
    fn decide(&mut self, in_use: f32, span_s: f32) -> Option<f32> {
        let scores = self.unexplained();
        if !(self.m_power.is_finite() && scores.iter().all(|s| s.is_finite())) {
            self.restart();
            return None;
        }
        // Each lag at its best delay.
        let mut in_use_score = 1.0f32;
        let mut best = (0usize, 1.0f32);
        for (i, &s) in scores.iter().enumerate() {
            if i % LAGS == 0 {
                if s < in_use_score {
                    in_use_score = s;
                }
            } else if s < best.1 {
                best = (i, s);
            }
        }
        let strong = self.m_power >= MIN_EXCITATION_NM2;
        let excited = strong
            || (self.m_power >= GROWTH_FLOOR_NM2
                && self.m_power >= GROWTH_RATIO * self.m_power_slow);
        let wins = !best.0.is_multiple_of(LAGS)
            && excited
            && best.1 <= SWITCH_RATIO * in_use_score
            && (slot_tau(best.0, in_use) - in_use).abs() > 1e-4;
        if !wins {
            self.winner = None;
            return None;
        }
        let col = best.0 % LAGS;
        let held = match self.winner {
            Some((c, t)) if usize::from(c) == col => t + span_s,
            _ => 0.0,
        };
        self.winner = Some((col as u8, held));
        let hold = if strong {
            SWITCH_HOLD_EXCITED_S
        } else {
            SWITCH_HOLD_S
        };
        if held < hold || self.rest_s < SWITCH_REST_S {
            return None;
        }
        // Switch: the winner's column (every delay row) becomes the lag in use's.
        let tau = slot_tau(best.0, in_use);
        for row in 0..DELAY_TICKS.len() {
            let (from, to) = (row * LAGS + col, row * LAGS);
            if let (Some(y), Some(p), Some(c)) = (
                self.y.get(from).copied(),
                self.y_power.get(from).copied(),
                self.cross.get(from).copied(),
            ) {
                if let (Some(yt), Some(pt), Some(ct)) = (
                    self.y.get_mut(to),
                    self.y_power.get_mut(to),
                    self.cross.get_mut(to),
                ) {
                    *yt = y;
                    *pt = p;
                    *ct = c;
                }
            }
        }
        self.tau_s = tau;
        self.winner = None;
        self.rest_s = 0.0;
        Some(tau)
    }
}

/// The attitude design's effective lag for a motor lag τ_m ([`Gains::for_vehicle`]):
/// min(τ_m, [`LAG_TARGET_S`]) + [`SENSOR_DELAY_S`].
fn design_lag_s(tau_m: f32) -> f32 {
    let t = if tau_m > 0.0 { tau_m } else { 0.0 };
    (if t < LAG_TARGET_S { t } else { LAG_TARGET_S }) + SENSOR_DELAY_S
}

impl Gains {
    /// These gains redesigned from motor lag `from_s` to `to_s` (s), as [`Gains::for_vehicle`]
    /// designs them: k_ω ∝ 1 / τ_e and k_R ∝ 1 / τ_e², the lead to [`LAG_TARGET_S`] and the
    /// composite law's prediction on `to_s`.
    pub fn with_motor_lag(mut self, from_s: f32, to_s: f32) -> Self {
        let s = design_lag_s(from_s) / design_lag_s(to_s);
        if s.is_finite() && s > 0.0 {
            self.k_w *= s;
            self.k_r *= s * s;
        }
        self.lag = if to_s > LAG_TARGET_S {
            LagCompensation {
                motor_tau_s: to_s,
                target_tau_s: LAG_TARGET_S,
            }
        } else {
            LagCompensation::OFF
        };
        self.composite.motor_tau_s = to_s;
        self
    }
}

impl<M: HamiltonianModel> FlightController<M> {
    /// The motor lag the attitude loop is designed for now (s): the gains' own unless the lag
    /// watch ([`Gains::lag_watch`]) has switched.
    pub fn motor_lag_s(&self) -> f32 {
        if self.watch.stated_tau_s.is_some() {
            self.watch.tau_s
        } else {
            self.gains.composite.motor_tau_s
        }
    }

    /// The motor-lag watch's state.
    pub fn lag_watch(&self) -> &LagWatch {
        &self.watch
    }

    /// The watch's tick after the actuation ([`LagWatch::observe`]); a switch redesigns the
    /// gains ([`Gains::with_motor_lag`]).
    #[inline(never)]
    pub(super) fn watch_lag(
        &mut self,
        state: &State,
        inertia: &Matrix3<f32>,
        act: &Actuation,
        dt_s: f32,
    ) {
        if !self.gains.lag_watch {
            return;
        }
        if self.watch.stated_tau_s.is_none() {
            self.watch.stated_tau_s = Some(self.gains.composite.motor_tau_s);
            self.watch.tau_s = self.gains.composite.motor_tau_s;
        }
        let t = act.delivered.torque_nm;
        let j = inertia.diagonal();
        let from = self.watch.tau_s;
        if let Some(to) = self
            .watch
            .observe(&state.w_body_rad_s, &j, [t.x, t.y], dt_s)
        {
            self.gains = self.gains.with_motor_lag(from, to);
            if self.gains.lag.ratio().is_none() {
                self.u_model = None;
            }
        }
    }

    /// Back to the stated lag's design (a new flight).
    pub(super) fn unwatch_lag(&mut self) {
        if let Some(stated) = self.watch.stated_tau_s {
            if self.watch.tau_s != stated {
                self.gains = self.gains.with_motor_lag(self.watch.tau_s, stated);
                self.watch.tau_s = stated;
            }
        }
        self.watch.restart();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Flies `watch` for `secs` s on a rigid axis pair J = 1.4e-5 whose motors lag the command
    /// by `true_tau_s`, the command a 6 Hz sine of `amp_nm` (roll) and its cosine (pitch) with
    /// a steady 2e-4 N·m disturbance; returns the switches (time s, new lag s).
    fn fly(
        watch: &mut LagWatch,
        true_tau_s: f32,
        amp_nm: f32,
        secs: f32,
    ) -> std::vec::Vec<(f32, f32)> {
        let dt = 0.002;
        let j = Vector3::new(1.4e-5, 1.4e-5, 2.17e-5);
        let mut w = Vector3::zeros();
        let mut lagged = [0.0f32; 2];
        let mut switches = std::vec::Vec::new();
        let n = (secs / dt) as usize;
        for k in 0..n {
            let t = k as f32 * dt;
            let ph = 2.0 * core::f32::consts::PI * 6.0 * t;
            let cmd = [amp_nm * libm::sinf(ph), amp_nm * libm::cosf(ph)];
            if let Some(tau) = watch.observe(&w, &j, cmd, dt) {
                switches.push((t, tau));
            }
            // The plant over the next tick: the lagged torque plus the disturbance.
            let b = pole(true_tau_s, dt);
            for (l, c) in lagged.iter_mut().zip(cmd.iter()) {
                *l += b * (c - *l);
            }
            w.x += (lagged[0] + 2e-4) / j.x * dt;
            w.y += (lagged[1] - 2e-4) / j.y * dt;
        }
        switches
    }

    fn watching(tau_s: f32) -> LagWatch {
        LagWatch {
            tau_s,
            stated_tau_s: Some(tau_s),
            ..LagWatch::default()
        }
    }

    /// Excited, a wrong stated lag is replaced by the candidate nearest the motors' within a
    /// second, in either direction; the right one is never replaced.
    #[test]
    fn an_excited_wrong_lag_is_replaced() {
        for (stated, truth, want) in [(0.05, 0.0, 0.0), (0.0, 0.05, 0.05), (0.02, 0.1, 0.1)] {
            let mut w = watching(stated);
            let s = fly(&mut w, truth, 2e-3, 2.0);
            let first = s.first().copied();
            assert!(
                matches!(first, Some((t, tau)) if t < 1.0 && (tau - want).abs() < 1e-6),
                "stated {stated}, motors {truth}: {s:?}"
            );
            assert!((w.tau_s - want).abs() < 1e-6, "{s:?}");
        }
        for tau in [0.0, 0.05] {
            let mut w = watching(tau);
            let s = fly(&mut w, tau, 2e-3, 3.0);
            assert!(s.is_empty(), "matched {tau}: {s:?}");
        }
    }

    /// A calm flight (command 1e-4 N·m) never switches, however wrong the stated lag.
    #[test]
    fn a_calm_flight_keeps_the_stated_lag() {
        let mut w = watching(0.08);
        let s = fly(&mut w, 0.0, 1e-4, 3.0);
        assert!(s.is_empty(), "{s:?}");
        assert_eq!(w.tau_s, 0.08);
    }

    /// The redesign is the one `Gains::for_vehicle` makes for the new lag.
    #[test]
    fn the_redesign_is_the_vehicle_design() {
        use crate::gains::VehicleFacts;
        for (from, to) in [(0.05, 0.0), (0.0, 0.05), (0.02, 0.08), (0.003, 0.03)] {
            let facts = |tau| VehicleFacts {
                motor_tau_s: tau,
                ..VehicleFacts::default()
            };
            let got = Gains::for_vehicle(&facts(from)).with_motor_lag(from, to);
            let want = Gains::for_vehicle(&facts(to));
            assert!((got.k_r / want.k_r - 1.0).abs() < 1e-5, "{from} -> {to}");
            assert!((got.k_w / want.k_w - 1.0).abs() < 1e-5, "{from} -> {to}");
            assert_eq!(got.lag, want.lag);
            assert_eq!(got.composite.motor_tau_s, want.composite.motor_tau_s);
        }
    }
}
