//! Rotor speed → motor PWM, written through `embedded_hal::pwm::SetDutyCycle` so the control
//! code does not know the chip.
//!
//! The map is gym-pybullet-drones' CF2X motor model (the one the SITL plant and the core's
//! airframe use): rpm = 0.2685 · PWM + 4070.3 with PWM on a 16-bit scale (0..=65535), as the
//! Crazyflie's `motorsSetRatio` takes it. Inverted: PWM = (rpm − 4070.3) / 0.2685, clamped to
//! 0..=65535; a commanded speed of zero (the safe state) gives duty 0, motors stopped.
//! It is a linear fit for a brushed 7×16 mm motor at nominal battery voltage; a real Crazyflie
//! loses thrust as the battery sags, which the adaptation law absorbs as a disturbance.
//!
//! Crazyflie 2.1 motor outputs (Bitcraze crazyflie-firmware, `motors_def.c`, brushed):
//! M1 PA1 TIM2_CH2, M2 PB11 TIM2_CH4, M3 PA15 TIM2_CH1, M4 PB9 TIM4_CH4.

use embedded_hal::pwm::SetDutyCycle;

/// rpm per PWM count (gym-pybullet-drones `PWM2RPM_SCALE`).
pub const PWM2RPM_SCALE: f32 = 0.2685;
/// rpm at PWM 0 (gym-pybullet-drones `PWM2RPM_CONST`).
pub const PWM2RPM_CONST: f32 = 4070.3;
/// Full scale of the 16-bit PWM command.
pub const PWM_MAX: u16 = u16::MAX;

/// The 16-bit PWM command for a rotor speed (rpm). Non-finite or non-positive speeds give 0.
pub fn rpm_to_pwm(rpm: f32) -> u16 {
    // NaN fails this test too.
    if rpm.is_nan() || rpm <= 0.0 {
        return 0;
    }
    let pwm = (rpm - PWM2RPM_CONST) / PWM2RPM_SCALE;
    if pwm >= PWM_MAX as f32 {
        PWM_MAX
    } else if pwm > 0.0 {
        pwm as u16
    } else {
        0
    }
}

/// The rotor speed (rpm) a 16-bit PWM command gives; 0 for PWM 0 (motor off).
pub fn pwm_to_rpm(pwm: u16) -> f32 {
    if pwm == 0 {
        0.0
    } else {
        PWM2RPM_SCALE * pwm as f32 + PWM2RPM_CONST
    }
}

/// The four motor outputs M1..M4 (rotor numbering of the core's mixer).
pub struct Motors<A, B, C, D> {
    /// M1 (front-right).
    pub m1: A,
    /// M2 (back-right).
    pub m2: B,
    /// M3 (back-left).
    pub m3: C,
    /// M4 (front-left).
    pub m4: D,
}

/// A PWM output failed to take its duty (the motors are then commanded off).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MotorError;

impl<A, B, C, D> Motors<A, B, C, D>
where
    A: SetDutyCycle,
    B: SetDutyCycle,
    C: SetDutyCycle,
    D: SetDutyCycle,
{
    /// Writes the 16-bit PWM commands; on any error tries to stop all four.
    ///
    /// # Errors
    /// [`MotorError`] if a channel rejected its duty.
    pub fn set(&mut self, pwm: [u16; 4]) -> Result<(), MotorError> {
        let [p1, p2, p3, p4] = pwm;
        let ok = self.m1.set_duty_cycle_fraction(p1, PWM_MAX).is_ok()
            & self.m2.set_duty_cycle_fraction(p2, PWM_MAX).is_ok()
            & self.m3.set_duty_cycle_fraction(p3, PWM_MAX).is_ok()
            & self.m4.set_duty_cycle_fraction(p4, PWM_MAX).is_ok();
        if ok {
            Ok(())
        } else {
            self.off();
            Err(MotorError)
        }
    }

    /// All four motors stopped (best effort: errors are ignored, there is nothing safer to do).
    pub fn off(&mut self) {
        let _ = self.m1.set_duty_cycle_fully_off();
        let _ = self.m2.set_duty_cycle_fully_off();
        let _ = self.m3.set_duty_cycle_fully_off();
        let _ = self.m4.set_duty_cycle_fully_off();
    }
}
