//! Host unit tests of the chip-independent parts, by topic; the helpers they share are here.

mod blob;
mod control_loop;
mod dt;
mod framing;
mod pwm;
mod wire;

use crate::link::{FrameDecoder, FrameError, Input, Uplink, WireState};
use crate::motor::Motors;
use core::convert::Infallible;
use embedded_hal::pwm::{ErrorType, SetDutyCycle};
use hamflight::{Setpoint, State};
use nalgebra::Vector3;

#[derive(Default)]
struct FakePwm(u16);
impl ErrorType for FakePwm {
    type Error = Infallible;
}
impl SetDutyCycle for FakePwm {
    fn max_duty_cycle(&self) -> u16 {
        255
    }
    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
        self.0 = duty;
        Ok(())
    }
}

fn motors() -> Motors<FakePwm, FakePwm, FakePwm, FakePwm> {
    Motors {
        m1: FakePwm(7),
        m2: FakePwm(7),
        m3: FakePwm(7),
        m4: FakePwm(7),
    }
}

fn hover_input(seq: u32) -> Input {
    let p = Vector3::new(0.0, 0.0, 0.5);
    Input {
        seq,
        state: WireState::from(&State {
            p_m: p,
            ..State::default()
        }),
        setpoint: Some(Setpoint::hover(p, 0.0)),
    }
}

/// An input off the hover point (position, velocity and attitude errors), so that the
/// adaptation law moves the estimate every step.
fn off_input(seq: u32) -> Input {
    let k = seq as f32;
    let p = Vector3::new(0.0, 0.0, 0.5);
    Input {
        seq,
        state: WireState::from(&State {
            p_m: p + Vector3::new(0.05 + 0.001 * k, -0.03, 0.02),
            rot: nalgebra::Rotation3::from_euler_angles(0.05, -0.03, 0.1).into_inner(),
            v_body_m_s: Vector3::new(0.1, 0.0, -0.05),
            w_body_rad_s: Vector3::new(0.2, -0.1, 0.05),
        }),
        setpoint: Some(Setpoint::hover(p, 0.0)),
    }
}

fn decode_all<T: for<'de> serde::Deserialize<'de>>(bytes: &[u8]) -> Vec<Result<T, FrameError>> {
    let mut d = FrameDecoder::new();
    bytes.iter().filter_map(|&b| d.push::<T>(b)).collect()
}

struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
    /// A finite f32 of any bit pattern (±0, subnormal, huge), often with zero bytes in it.
    fn f32(&mut self) -> f32 {
        loop {
            let bits = match self.below(4) {
                0 => 0,
                1 => (self.next_u64() as u32) & 0xFF00_FF00,
                _ => self.next_u64() as u32,
            };
            let x = f32::from_bits(bits);
            if x.is_finite() {
                return x;
            }
        }
    }
    fn f32s<const N: usize>(&mut self) -> [f32; N] {
        core::array::from_fn(|_| self.f32())
    }
    /// A wire quaternion: a unit one (as a sender makes it), one off unit norm by up to ±1e-3,
    /// any finite bits, or one with a NaN or infinite component.
    fn quat(&mut self) -> [f32; 4] {
        let unit = hamflight::lie::quat_from_rot(&hamflight::lie::exp(&Vector3::new(
            self.below(2001) as f32 * 3e-3 - 3.0,
            self.below(2001) as f32 * 3e-3 - 3.0,
            self.below(2001) as f32 * 3e-3 - 3.0,
        )));
        match self.below(5) {
            0 | 1 => unit,
            2 => {
                let k = 1.0 + (self.below(2001) as f32 - 1000.0) * 1e-6;
                unit.map(|c| c * k)
            }
            3 => self.f32s(),
            _ => {
                let mut q = unit;
                if let Some(c) = q.get_mut(self.below(4)) {
                    *c = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][self.below(3)];
                }
                q
            }
        }
    }
}

fn random_uplink(rng: &mut SplitMix64) -> Uplink {
    match rng.below(6) {
        0 => Uplink::Hello,
        1 => Uplink::Finish,
        _ => Uplink::Input(Input {
            seq: rng.next_u64() as u32,
            state: WireState {
                p: rng.f32s(),
                q: rng.quat(),
                v: rng.f32s(),
                w: rng.f32s(),
                acc: if rng.below(2) == 0 {
                    None
                } else {
                    Some(rng.f32s())
                },
            },
            setpoint: if rng.below(3) == 0 {
                None
            } else {
                Some(Setpoint {
                    p_m: rng.f32s().into(),
                    v_m_s: rng.f32s().into(),
                    a_m_s2: rng.f32s().into(),
                    j_m_s3: rng.f32s().into(),
                    yaw_rad: rng.f32(),
                    yaw_rate_rad_s: rng.f32(),
                })
            },
        }),
    }
}
