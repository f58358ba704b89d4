//! The two faults a flight can be given during the hold: the radio link lost (`--link-loss-s`:
//! no setpoint and no pose from then on) and the estimator reset (`--estimator-reset-s`), and
//! what each did to the flight.

use host_train::io::param_write_u8;
use host_train::{PlantState, TrajectoryPoint};
use nalgebra::Vector3;

use crate::launch::Link;
use crate::Args;

#[derive(Default)]
pub struct Faults {
    /// When the link was lost, and when the motors stopped after it (plant time).
    pub link_lost_at: Option<f64>,
    pub motors_off_at: Option<f64>,
    /// After a lost link, until the motors stop: the largest distance from where the link was
    /// lost.
    pub drift_m: f64,
    lost_p: Option<Vector3<f64>>,
    /// The estimator reset's first write and its echo (plant time).
    pub reset_sent_at: Option<f64>,
    pub reset_echoed_at: Option<f64>,
    /// After an estimator reset: the largest distance from the setpoint, and when it last was
    /// above 1 cm.
    pub reset_peak_m: f64,
    pub reset_last_over_1cm: Option<f64>,
}

impl Faults {
    /// The radio link at plant time `t`: lost from `--link-loss-s` into the hold (setpoints and
    /// pose alike: with cflib, motion capture reaches the vehicle over the same radio).
    pub fn link_up(args: &Args, hold_started_at: Option<f64>, t: f64) -> bool {
        match (args.link_loss_s, hold_started_at) {
            (Some(l), Some(h0)) => t < h0 + l,
            _ => true,
        }
    }

    /// The estimator reset: `kalman.resetEstimation = 1` (id `reset_id`), written every 20 ms
    /// until the firmware echoes it.
    pub fn reset_estimator(
        &mut self,
        link: &Link,
        args: &Args,
        k: u64,
        t: f64,
        hold_started_at: Option<f64>,
        reset_id: Option<u16>,
    ) {
        if let (Some(r), Some(h0), Some(id)) = (args.estimator_reset_s, hold_started_at, reset_id) {
            if t >= h0 + r && self.reset_echoed_at.is_none() {
                if link
                    .shared
                    .lock()
                    .unwrap()
                    .param_written
                    .iter()
                    .any(|w| w.0 == id)
                {
                    self.reset_echoed_at = Some(t);
                } else if k.is_multiple_of(20) {
                    link.send(&param_write_u8(id, 1));
                    self.reset_sent_at.get_or_insert(t);
                }
            }
        }
    }

    /// When the link was lost, and when the motor command (`pwm`) was all zero after it.
    pub fn watch_link(&mut self, link_up: bool, t: f64, pwm: [u16; 4]) {
        if !link_up && self.link_lost_at.is_none() {
            self.link_lost_at = Some(t);
        }
        if self.link_lost_at.is_some() && self.motors_off_at.is_none() && pwm == [0; 4] {
            self.motors_off_at = Some(t);
        }
    }

    /// After the plant step to `s`: the error after an estimator reset (in the hold), the drift
    /// after a lost link.
    pub fn after_step(
        &mut self,
        s: &PlantState,
        t: f64,
        phase: &str,
        setpoint: &Option<TrajectoryPoint>,
    ) {
        if let (Some(_), Some(sp), "hold") = (self.reset_sent_at, setpoint, phase) {
            let e = (s.p_m - sp.p_m).norm();
            self.reset_peak_m = self.reset_peak_m.max(e);
            if e > 0.01 {
                self.reset_last_over_1cm = Some(t);
            }
        }
        if self.link_lost_at.is_some() && self.motors_off_at.is_none() {
            let p0 = *self.lost_p.get_or_insert(s.p_m);
            self.drift_m = self.drift_m.max((s.p_m - p0).norm());
        }
    }
}
