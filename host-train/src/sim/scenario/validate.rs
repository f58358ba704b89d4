//! A scenario's checks before it flies: every key in range, every number finite, with the key
//! named in the error.

use anyhow::{bail, Result};

use super::{ScenarioSpec, Trajectory};

fn finite_all(xs: &[f64]) -> bool {
    xs.iter().all(|x| x.is_finite())
}

pub(super) fn validate(s: &ScenarioSpec) -> Result<()> {
    if let Some(sensors) = &s.sensors {
        sensors.validate()?;
    }
    if !(s.duration_s.is_finite() && s.duration_s > 0.0) {
        bail!(
            "key `duration_s`: expected a positive number of seconds, got {}",
            s.duration_s
        );
    }
    if !(s.control_hz.is_finite() && s.control_hz > 0.0) {
        bail!(
            "key `control_hz`: expected a positive rate in Hz, got {}",
            s.control_hz
        );
    }
    if !(s.physics_hz.is_finite() && s.physics_hz >= 1000.0) {
        bail!(
            "key `physics_hz`: expected a rate ≥ 1000 Hz (physics step ≤ 1 ms), got {}",
            s.physics_hz
        );
    }
    if !s.yaw_rad.is_finite() || !s.yaw_rate_rad_s.is_finite() {
        bail!("keys `yaw_rad`/`yaw_rate_rad_s`: expected finite numbers");
    }
    let pos = |name: &str, x: f64| -> Result<()> {
        if x.is_finite() && x > 0.0 {
            Ok(())
        } else {
            bail!("key `trajectory.{name}`: expected a positive number, got {x}")
        }
    };
    match &s.trajectory {
        Trajectory::Hover { position_m } => {
            if !finite_all(position_m) {
                bail!("key `trajectory.position_m`: expected three finite numbers");
            }
        }
        Trajectory::Step { from_m, to_m, at_s } => {
            if !finite_all(from_m) || !finite_all(to_m) || !at_s.is_finite() {
                bail!("keys `trajectory.from_m`, `to_m`, `at_s`: expected finite numbers");
            }
        }
        Trajectory::Circle {
            center_m,
            radius_m,
            period_s,
        } => {
            if !finite_all(center_m) {
                bail!("key `trajectory.center_m`: expected three finite numbers");
            }
            pos("radius_m", *radius_m)?;
            pos("period_s", *period_s)?;
        }
        Trajectory::Spiral {
            center_m,
            radius_m,
            period_s,
            climb_m_s,
        } => {
            if !finite_all(center_m) || !climb_m_s.is_finite() {
                bail!("keys `trajectory.center_m`/`climb_m_s`: expected finite numbers");
            }
            pos("radius_m", *radius_m)?;
            pos("period_s", *period_s)?;
        }
        Trajectory::Diamond {
            waypoints_m,
            segment_s,
            hold_s,
        } => {
            if waypoints_m.len() < 2 {
                bail!(
                    "key `trajectory.waypoints_m`: expected at least 2 waypoints, got {}",
                    waypoints_m.len()
                );
            }
            if !waypoints_m.iter().all(|w| finite_all(w)) {
                bail!("key `trajectory.waypoints_m`: expected finite numbers");
            }
            pos("segment_s", *segment_s)?;
            if !(hold_s.is_finite() && *hold_s >= 0.0) {
                bail!("key `trajectory.hold_s`: expected a number ≥ 0, got {hold_s}");
            }
        }
        Trajectory::FigureEight {
            start_m,
            half_width_m,
            duration_s,
            start_s,
        } => {
            if !finite_all(start_m) {
                bail!("key `trajectory.start_m`: expected three finite numbers");
            }
            pos("half_width_m", *half_width_m)?;
            pos("duration_s", *duration_s)?;
            if !(start_s.is_finite() && *start_s >= 0.0) {
                bail!("key `trajectory.start_s`: expected a number ≥ 0, got {start_s}");
            }
        }
    }
    let d = &s.disturbance;
    if !finite_all(&d.wind_m_s2) {
        bail!("key `disturbance.wind_m_s2`: expected three finite numbers (m/s²)");
    }
    if !d
        .rotor_efficiency
        .iter()
        .all(|x| x.is_finite() && (0.0..=2.0).contains(x))
    {
        bail!(
            "key `disturbance.rotor_efficiency`: expected four numbers in [0, 2], got {:?}",
            d.rotor_efficiency
        );
    }
    if !d.onset_s.is_finite() || !d.wind_onset_s.is_finite() {
        bail!("keys `disturbance.onset_s`/`wind_onset_s`: expected finite times (s)");
    }
    for (i, w) in d.wind_sines.iter().enumerate() {
        let ok = finite_all(&w.amplitude_m_s2)
            && w.phase_rad.is_finite()
            && w.frequency_hz.is_finite()
            && w.frequency_hz >= 0.0;
        if !ok {
            bail!(
                "key `disturbance.wind_sines[{i}]`: expected finite amplitudes (m/s²), phase \
                 (rad) and a frequency ≥ 0 Hz"
            );
        }
    }
    for (i, w) in d.wind_steps.iter().enumerate() {
        let until_ok = w.until_s.is_none_or(|u| u.is_finite() && u > w.from_s);
        if !(finite_all(&w.wind_m_s2) && w.from_s.is_finite() && until_ok) {
            bail!(
                "key `disturbance.wind_steps[{i}]`: expected finite wind (m/s²), a finite \
                 `from_s` and an `until_s` after it"
            );
        }
    }
    let e = &s.effects;
    if !(e.motor_tau_s.is_finite() && e.motor_tau_s >= 0.0) {
        bail!(
            "key `effects.motor_tau_s`: expected a time constant ≥ 0 s, got {}",
            e.motor_tau_s
        );
    }
    for (key, v) in [
        ("command_delay_s", e.command_delay_s),
        ("command_jitter_s", e.command_jitter_s),
    ] {
        if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
            bail!("key `effects.{key}`: expected a delay in [0, 1] s, got {v}");
        }
    }
    if let Some(r) = &e.residual {
        let mut numbers = [r.thrust_gain, r.torque_lag_s, r.thrust_lag_s]
            .into_iter()
            .chain(r.torque_gain)
            .chain(r.accel_per_velocity.into_iter().flatten())
            .chain(r.accel_bias)
            .chain(r.accel_per_tilt.into_iter().flatten());
        if !numbers.all(f64::is_finite) {
            bail!("key `effects.residual`: every number must be finite");
        }
        if !(r.thrust_gain > 0.0 && r.torque_gain.iter().all(|k| *k > 0.0)) {
            bail!("key `effects.residual`: thrust_gain and torque_gain must be positive");
        }
        if !(r.torque_lag_s >= 0.0 && r.thrust_lag_s >= 0.0) {
            bail!("key `effects.residual`: the lags must be ≥ 0 s");
        }
    }
    let n = &e.noise;
    if ![n.pos_m, n.vel_m_s, n.att_rad, n.rate_rad_s, n.acc_m_s2]
        .iter()
        .all(|x| x.is_finite() && *x >= 0.0)
    {
        bail!("key `effects.noise`: expected standard deviations ≥ 0");
    }
    let v = &s.vehicle;
    if v.mass_kg.is_some_and(|m| !(m.is_finite() && m > 0.0)) {
        bail!("key `vehicle.mass_kg`: expected a positive mass (kg)");
    }
    if v.inertia_kg_m2
        .is_some_and(|j| !j.iter().all(|x| x.is_finite() && *x > 0.0))
    {
        bail!("key `vehicle.inertia_kg_m2`: expected three positive moments (kg·m²)");
    }
    if v.rotor_efficiency
        .is_some_and(|e| !e.iter().all(|x| x.is_finite() && *x > 0.0 && *x <= 2.0))
    {
        bail!("key `vehicle.rotor_efficiency`: expected four numbers in (0, 2]");
    }
    for (k, x) in [
        ("gravity_m_s2", v.gravity_m_s2),
        ("arm_xy_m", v.arm_xy_m),
        ("kf_n_per_rad_s2", v.kf_n_per_rad_s2),
        ("km_nm_per_rad_s2", v.km_nm_per_rad_s2),
    ] {
        if x.is_some_and(|x| !(x.is_finite() && x > 0.0)) {
            bail!("key `vehicle.{k}`: expected a positive number");
        }
    }
    if v.thrust_to_weight
        .is_some_and(|t| !(t.is_finite() && t > 1.0))
    {
        bail!("key `vehicle.thrust_to_weight`: expected a number above 1");
    }
    if let Some(st) = &s.start {
        if !finite_all(&st.position_m)
            || !finite_all(&st.velocity_m_s)
            || !finite_all(&st.rpy_rad)
            || !finite_all(&st.rate_rad_s)
        {
            bail!("key `start`: expected finite numbers");
        }
    }
    Ok(())
}
