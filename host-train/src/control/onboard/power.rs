//! Bitcraze's legacy quadrotor power distribution and its capping (firmware 2025.09,
//! `power_distribution_quadrotor.c`: `powerDistributionLegacy`, `powerDistributionCap`).

/// The largest PWM count (`UINT16_MAX`).
pub const PWM_MAX: f64 = 65535.0;

/// The controller's legacy-mode output (`control_t`): thrust in PWM counts, roll, pitch, yaw in
/// counts (the firmware holds them as int16).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct LegacyControl {
    /// Collective, PWM counts.
    pub thrust: f64,
    /// Roll command, counts (positive: left motors up, roll right).
    pub roll: f64,
    /// Pitch command, counts (positive: front motors up, nose up).
    pub pitch: f64,
    /// Yaw command, counts (positive: motors 1 and 3 up).
    pub yaw: f64,
}

/// Distributes `control` to the four motors and caps them, returning PWM counts.
///
/// m1 = T − r + p + y, m2 = T − r − p − y, m3 = T + r − p + y, m4 = T + r + p − y, with
/// r = roll / 2, p = pitch / 2 (1 front-right, 2 back-right, 3 back-left, 4 front-left). The cap
/// subtracts the largest motor's excess over 65535 from all four, then floors each at `idle`.
/// With `integer` the firmware's truncations are emulated (r, p to int16, motors to int32).
pub fn legacy_power_distribution(control: &LegacyControl, idle: f64, integer: bool) -> [f64; 4] {
    let trunc = |x: f64| if integer { x.trunc() } else { x };
    let r = trunc(control.roll / 2.0);
    let p = trunc(control.pitch / 2.0);
    let t = control.thrust;
    let y = control.yaw;
    let uncapped = [
        trunc(t - r + p + y),
        trunc(t - r - p - y),
        trunc(t + r - p + y),
        trunc(t + r + p - y),
    ];
    let highest = uncapped.iter().copied().fold(0.0_f64, f64::max);
    let reduction = if highest > PWM_MAX {
        highest - PWM_MAX
    } else {
        0.0
    };
    uncapped.map(|m| (m - reduction).max(idle))
}
