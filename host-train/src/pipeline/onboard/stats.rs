//! R² of the replayed commands against the logged ones, per motor and per axis.

use crate::io::MotorCommands;
use serde::Serialize;

/// Sums for one R² (1 − SSE/SST).
#[derive(Clone, Copy, Debug, Default)]
pub struct R2Acc {
    n: f64,
    sum_y: f64,
    sum_yy: f64,
    sse: f64,
}

impl R2Acc {
    /// Adds one (logged, predicted) pair.
    pub fn add(&mut self, y: f64, pred: f64) {
        self.n += 1.0;
        self.sum_y += y;
        self.sum_yy += y * y;
        self.sse += (y - pred) * (y - pred);
    }

    /// Merges another accumulator.
    pub fn merge(&mut self, o: &R2Acc) {
        self.n += o.n;
        self.sum_y += o.sum_y;
        self.sum_yy += o.sum_yy;
        self.sse += o.sse;
    }

    /// 1 − SSE/SST (`nan` without rows or variance).
    pub fn r2(&self) -> f64 {
        let sst = self.sum_yy - self.sum_y * self.sum_y / self.n.max(1.0);
        if self.n < 2.0 || sst <= 0.0 {
            f64::NAN
        } else {
            1.0 - self.sse / sst
        }
    }

    /// RMS error.
    pub fn rmse(&self) -> f64 {
        (self.sse / self.n.max(1.0)).sqrt()
    }
}

/// R² sums per motor and per axis (collective, roll, pitch, yaw).
#[derive(Clone, Copy, Debug, Default)]
pub struct FitAcc {
    /// Per motor 1..4.
    pub motor: [R2Acc; 4],
    /// Collective, roll, pitch, yaw (the power distribution's inverse).
    pub axis: [R2Acc; 4],
}

impl FitAcc {
    /// Adds one row.
    pub fn add(&mut self, log: &MotorCommands, pred: &MotorCommands) {
        for i in 0..4 {
            self.motor[i].add(log.0[i], pred.0[i]);
        }
        let (a, b) = (log.axes(), pred.axes());
        for i in 0..4 {
            self.axis[i].add(a[i], b[i]);
        }
    }

    /// Merges another.
    pub fn merge(&mut self, o: &FitAcc) {
        for i in 0..4 {
            self.motor[i].merge(&o.motor[i]);
            self.axis[i].merge(&o.axis[i]);
        }
    }

    /// The summary.
    pub fn summary(&self, rows: usize) -> R2Summary {
        R2Summary {
            rows,
            r2_motor: self.motor.map(|a| a.r2()),
            r2_collective: self.axis[0].r2(),
            r2_roll: self.axis[1].r2(),
            r2_pitch: self.axis[2].r2(),
            r2_yaw: self.axis[3].r2(),
            rmse_axis: self.axis.map(|a| a.rmse()),
        }
    }
}

/// R² per motor and axis over some rows.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct R2Summary {
    /// Rows counted.
    pub rows: usize,
    /// R² of motors 1..4.
    pub r2_motor: [f64; 4],
    /// R² of the collective (mean of the four).
    pub r2_collective: f64,
    /// R² of the roll command (−m1 − m2 + m3 + m4)/2.
    pub r2_roll: f64,
    /// R² of the pitch command (m1 − m2 − m3 + m4)/2.
    pub r2_pitch: f64,
    /// R² of the yaw command (m1 − m2 + m3 − m4)/4.
    pub r2_yaw: f64,
    /// RMS error per axis (collective, roll, pitch, yaw), normalized command units.
    pub rmse_axis: [f64; 4],
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn r2_is_one_for_a_perfect_fit_and_zero_for_the_mean() {
        let mut a = R2Acc::default();
        let mut b = R2Acc::default();
        for y in [1.0, 2.0, 4.0] {
            a.add(y, y);
            b.add(y, 7.0 / 3.0);
        }
        assert!((a.r2() - 1.0).abs() < 1e-12);
        assert!(b.r2().abs() < 1e-12);
    }
}
