//! The motors' rpm ↔ PWM map.

use crate::motor::{pwm_to_rpm, rpm_to_pwm};

#[test]
fn pwm_map_matches_gym_pybullet_drones() {
    assert_eq!(rpm_to_pwm(0.0), 0);
    assert_eq!(rpm_to_pwm(f32::NAN), 0);
    assert_eq!(rpm_to_pwm(-5.0), 0);
    assert_eq!(rpm_to_pwm(1e9), u16::MAX);
    // Hover of the CF2X: 14 468 rpm ↔ PWM ≈ 38 725.
    let pwm = rpm_to_pwm(14_468.0);
    assert!((pwm as i32 - 38_725).abs() <= 1, "{pwm}");
    assert!((pwm_to_rpm(pwm) - 14_468.0).abs() < 0.5);
}
