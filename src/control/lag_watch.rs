//! The motor-lag watch: the attitude loop's gains and lead are designed for the motor lag the
//! blob states ([`Gains::for_vehicle`]), and a stated lag far from the motors' own leaves the
//! loop a few ms of delay margin (docs/envelope.md). The watch reads the motors' lag from the
//! flight itself and redesigns the loop for it when the stated one is plainly wrong.
//!
//! Per tick, for roll and pitch, it compares the measured torque J ω̇ + ω × Jω (high-passed,
//! so the slow disturbance drops out) with the delivered torque through first-order lags of
//! [`CANDIDATE_TAUS_S`] and of the lag in use (high-passed alike), each also [`DELAY_TICKS`]
//! later. For each it keeps the low-passed correlations, and so the share of J ω̇ that the best
//! scaled copy of the lagged command leaves unexplained (1 − ρ², a scale error of J or of the
//! torque gain costs nothing). While the loop is excited (a limit cycle, or a lag that makes one
//! grow), the watch switches to the candidate that leaves at most [`SWITCH_RATIO`] of the lag in
//! use's share, once one has done so for [`SWITCH_HOLD_S`]. A calm flight never switches,
//! whatever its lag: there the loop holds the stated lag's design (the matrix's zero-delay cells
//! all fly).
//!
//! The step budget shapes the work: the delayed row reuses the undelayed lags' outputs (a
//! ring of them) and powers, each tick scores one slot, and the decision reads the tally.

use super::*;

/// The motor lags the watch weighs against the lag in use (s): from ideal rotors to a slow
/// brushed motor behind a command delay.
pub const CANDIDATE_TAUS_S: [f32; 4] = [0.0, 0.02, 0.05, 0.1];

/// The command delays (control ticks) each lag is weighed with: a lag and a delay look alike
/// at one frequency, so a pure-lag candidate would stand in for the delay too. A delayed
/// lag's output is the undelayed one's, that much earlier (both filters are linear and time
/// invariant), so the delayed row keeps only its cross power; its power is the undelayed
/// one's but for the window's edge.
pub const DELAY_TICKS: [usize; 2] = [0, 4];

/// Lags per delay row: the lag in use first, then the candidates.
const LAGS: usize = CANDIDATE_TAUS_S.len() + 1;

/// Slots: per delay row ([`DELAY_TICKS`]), the lag in use and the candidates.
pub const SLOTS: usize = LAGS * DELAY_TICKS.len();

/// Ticks of the lagged commands kept for the delayed row.
const RING: usize = DELAY_TICKS[1];

/// The watch weighs roll and pitch as one signal, τ_x + [`PITCH_WEIGHT`] τ_y (the lag is the
/// same linear filter on both, so it holds for the sum; unequal weights keep a diagonal
/// oscillation from cancelling): half the work of two.
pub const PITCH_WEIGHT: f32 = 0.5;

/// The watch decides every this many ticks: odd tick `t` of the cycle scores slot `t / 2`
/// (the even ones carry more of the correlations), and the first tick of the next cycle
/// decides on the tally.
pub const DECIDE_TICKS: u8 = 2 * SLOTS as u8;

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

/// The shortest time from a flight's start to the first switch (s): a take-off's first
/// transient (thrust spinning up, the mixer at its limits) says little about the motors' lag,
/// but a plant far slower than the stated lag crashes within half a second.
pub const START_REST_S: f32 = 0.2;

/// The lag watch's state ([`FlightController::motor_lag_s`] reads its verdict).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagWatch {
    /// The lag in use (s): the stated one until a switch.
    pub(super) tau_s: f32,
    /// The lag the gains were built for (s): [`FlightController::reset`] returns to it.
    pub(super) stated_tau_s: Option<f32>,
    /// The previous tick's body rate (rad/s) and delivered torque signal (N·m).
    prev_w: Vector3<f32>,
    prev_u: f32,
    /// Whether `prev_w` and `prev_u` hold a tick.
    primed: bool,
    /// The high-pass states of the measured and of the delivered torque signal.
    m_low: f32,
    u_low: f32,
    /// The measured signal's power, and its slow low-pass ([`GROWTH_TAU_S`]).
    m_power: f32,
    m_power_slow: f32,
    /// The filter gains over one tick: per lag, then the high-pass, the window (over one
    /// tick and over two) and the growth low-pass; and the (tick s, lag in use s) they were computed for.
    poles: [f32; LAGS],
    k_hp: f32,
    k_win: f32,
    k_win2: f32,
    k_growth: f32,
    poles_for: (f32, f32),
    /// Per lag: the high-passed command through it now, and up to [`RING`] ticks back (the
    /// ring's `head` row is the oldest).
    y: [f32; LAGS],
    ring: [[f32; LAGS]; RING],
    head: u8,
    /// Per lag: the lagged command's power; per delay row and lag, its cross power with the
    /// measured torque.
    y_power: [f32; LAGS],
    cross: [[f32; LAGS]; DELAY_TICKS.len()],
    /// This cycle's scores so far.
    tally: Tally,
    /// The winning candidate and for how long (s); time since the last switch (s); the tick
    /// in the decision cycle.
    winner: Option<(u8, f32)>,
    rest_s: f32,
    tick: u8,
}

impl Default for LagWatch {
    fn default() -> Self {
        Self {
            tau_s: 0.0,
            stated_tau_s: None,
            prev_w: Vector3::new(0.0, 0.0, 0.0),
            prev_u: 0.0,
            primed: false,
            m_low: 0.0,
            u_low: 0.0,
            m_power: 0.0,
            m_power_slow: 0.0,
            poles: [1.0; LAGS],
            k_hp: 1.0,
            k_win: 1.0,
            k_win2: 1.0,
            k_growth: 1.0,
            poles_for: (-1.0, -1.0),
            y: [0.0; LAGS],
            ring: [[0.0; LAGS]; RING],
            head: 0,
            y_power: [0.0; LAGS],
            cross: [[0.0; LAGS]; DELAY_TICKS.len()],
            tally: Tally::EMPTY,
            winner: None,
            rest_s: SWITCH_REST_S - START_REST_S,
            tick: 0,
        }
    }
}

/// The scores of one decision cycle: per lag (the lag in use, then
/// [`CANDIDATE_TAUS_S`]) the least share it left unexplained at any delay, and whether every
/// score was finite.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Tally {
    cols: [f32; LAGS],
    finite: bool,
    /// Nothing scored into it yet (a flight's first cycle is still under way).
    fresh: bool,
}

impl Tally {
    const EMPTY: Self = Self {
        cols: [1.0; LAGS],
        finite: true,
        fresh: true,
    };
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

/// How far the watch lets the torque's scale be off (J, the torque gain, a weak rotor): a slot
/// is compared at its best scale within [1 / this, this] of the delivered torque. The scale
/// is bounded because the phase alone cannot tell a lag from a delay at one frequency (a limit
/// cycle's), while the amplitude can: a lag attenuates, a delay does not.
pub const SCALE_SPAN: f32 = 2.0;

/// The share of the measured power the slot, at its best scale within [`SCALE_SPAN`], leaves
/// unexplained: ‖m − s y‖² / ‖m‖² (1 when there is nothing to compare).
#[inline(never)]
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
        let powers = self.y_power.iter().cycle();
        for ((o, &p), &c) in out.iter_mut().zip(powers).zip(self.cross.iter().flatten()) {
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
        let (w_prev, applied) = (self.prev_w, self.prev_u);
        self.prev_w = *w;
        self.prev_u = ux + PITCH_WEIGHT * uy;
        if !(self.primed && dt_s > 0.0) {
            self.primed = true;
            return None;
        }
        self.rest_s += dt_s;
        self.filter(&w_prev, w, j, applied, dt_s);
        let tick = self.tick;
        self.tick = if tick + 1 >= DECIDE_TICKS {
            0
        } else {
            tick + 1
        };
        if tick % 2 == 1 {
            self.score(usize::from(tick / 2));
            return None;
        }
        // The decision on a tick that scores nothing, once the cycle's tally is complete.
        if tick != 0 || self.tally.fresh {
            return None;
        }
        let in_use = self.tau_s;
        self.decide(in_use, dt_s * f32::from(DECIDE_TICKS))
    }

    /// One tick of the filters over `dt_s` (s > 0), from the body rate `w_prev` to `w`:
    /// J ω̇ + ω × Jω about x and y (weighed as one), high-passed, against the `applied` signal
    /// through each lag, now and [`RING`] ticks back.
    #[inline(never)]
    fn filter(
        &mut self,
        w_prev: &Vector3<f32>,
        w: &Vector3<f32>,
        j: &Vector3<f32>,
        applied: f32,
        dt_s: f32,
    ) {
        let key = (dt_s, self.tau_s);
        if key != self.poles_for {
            for (k, p) in self.poles.iter_mut().enumerate() {
                *p = pole(slot_tau(k, key.1), dt_s);
            }
            self.k_hp = pole(HIGH_PASS_TAU_S, dt_s);
            self.k_win = pole(WINDOW_S, dt_s);
            self.k_win2 = pole(WINDOW_S, 2.0 * dt_s);
            self.k_growth = pole(GROWTH_TAU_S, dt_s);
            self.poles_for = key;
        }
        // (ω × Jω)_x = (J_z − J_y) ω_y ω_z, (ω × Jω)_y = (J_x − J_z) ω_z ω_x.
        let m = (j.x * (w.x - w_prev.x) + PITCH_WEIGHT * j.y * (w.y - w_prev.y)) / dt_s
            + w.z * ((j.z - j.y) * w.y + PITCH_WEIGHT * (j.x - j.z) * w.x);
        let (hp, win) = (self.k_hp, self.k_win);
        self.m_low += hp * (m - self.m_low);
        let mh = m - self.m_low;
        self.u_low += hp * (applied - self.u_low);
        let u = applied - self.u_low;
        self.m_power += win * (mh * mh - self.m_power);
        self.m_power_slow += self.k_growth * (self.m_power - self.m_power_slow);
        let head = usize::from(self.head);
        self.head = if head + 1 >= RING {
            0
        } else {
            (head + 1) as u8
        };
        // The correlations of half the lags each tick, alternately, at twice the window's
        // gain: they are slow, the lags are not.
        let (win2, turn) = (self.k_win2, usize::from(self.tick) % 2);
        let [now, late] = &mut self.cross;
        if let Some(old) = self.ring.get_mut(head) {
            for (i, (((((y, o), p), c), cl), k)) in self
                .y
                .iter_mut()
                .zip(old.iter_mut())
                .zip(self.y_power.iter_mut())
                .zip(now.iter_mut())
                .zip(late.iter_mut())
                .zip(self.poles.iter())
                .enumerate()
            {
                *y += k * (u - *y);
                if i % 2 == turn {
                    *p += win2 * (*y * *y - *p);
                    *c += win2 * (*y * mh - *c);
                    *cl += win2 * (*o * mh - *cl);
                }
                *o = *y;
            }
        }
    }

    /// Scores slot `slot` into the tally (a new one from the first).
    #[inline(always)]
    fn score(&mut self, slot: usize) {
        if slot == 0 {
            self.tally = Tally::EMPTY;
        }
        let c = self.cross.get(slot / LAGS).and_then(|r| r.get(slot % LAGS));
        let (Some(&p), Some(&c)) = (self.y_power.get(slot % LAGS), c) else {
            return;
        };
        let s = unexplained(self.m_power, p, c);
        self.tally.finite &= s.is_finite();
        self.tally.fresh = false;
        if let Some(col) = self.tally.cols.get_mut(slot % LAGS) {
            if s < *col {
                *col = s;
            }
        }
    }

    /// The decision over the last `span_s` (s): the cycle's best candidate against the lag in
    /// use, each lag at its best delay.
    #[inline(never)]
    fn decide(&mut self, in_use: f32, span_s: f32) -> Option<f32> {
        let Tally { cols, finite, .. } = self.tally;
        if !(finite && self.m_power.is_finite()) {
            self.restart();
            return None;
        }
        // The best candidate that differs from the lag in use. The hold counts while any
        // candidate wins (two alike would otherwise reset each other's); the best one at the
        // end of it is taken.
        let in_use_score = cols.first().copied().unwrap_or(1.0);
        let bar = SWITCH_RATIO * in_use_score;
        let mut best = (0usize, 1.0f32);
        for (col, &s) in cols.iter().enumerate().skip(1) {
            if s < best.1 && (slot_tau(col, in_use) - in_use).abs() > 1e-4 {
                best = (col, s);
            }
        }
        let strong = self.m_power >= MIN_EXCITATION_NM2;
        let excited = strong
            || (self.m_power >= GROWTH_FLOOR_NM2
                && self.m_power >= GROWTH_RATIO * self.m_power_slow);
        if !(excited && best.0 != 0 && best.1 <= bar) {
            self.winner = None;
            return None;
        }
        let col = best.0;
        let held = match self.winner {
            Some((_, t)) => t + span_s,
            None => 0.0,
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
        // Switch: the winner's column (its lagged command, its past, powers and cross powers)
        // becomes the lag in use's.
        let tau = slot_tau(col, in_use);
        let rows = self.ring.iter_mut().chain(self.cross.iter_mut());
        for a in [&mut self.y, &mut self.y_power].into_iter().chain(rows) {
            if let (Some(v), Some(t)) = (a.get(col).copied(), a.first_mut()) {
                *t = v;
            }
        }
        self.tau_s = tau;
        self.winner = None;
        self.rest_s = 0.0;
        Some(tau)
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
    /// second of the start's rest ([`START_REST_S`]), in either direction, each switch moving towards it and never past it; the
    /// right one is never replaced. (At the test's single frequency a lag and a shorter lag
    /// behind the delay row's delay differ little, so the watch may stop at the nearer one
    /// on the way.)
    #[test]
    fn an_excited_wrong_lag_is_replaced() {
        for (stated, truth, want) in [(0.05, 0.0, 0.0), (0.0, 0.05, 0.05), (0.02, 0.1, 0.1)] {
            let mut w = watching(stated);
            let s = fly(&mut w, truth, 2e-3, 2.0);
            let by = START_REST_S + 1.0;
            let settled = s.iter().take_while(|(t, _)| *t < by).last();
            assert!(
                matches!(settled, Some((_, tau)) if (tau - want).abs() < 1e-6),
                "stated {stated}, motors {truth}: {s:?}"
            );
            let mut from = stated;
            for &(_, tau) in &s {
                let (gap, was) = ((tau - truth).abs(), (from - truth).abs());
                assert!(gap < was, "stated {stated}, motors {truth}: {s:?}");
                from = tau;
            }
            assert!(s.len() <= 2, "stated {stated}, motors {truth}: {s:?}");
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
