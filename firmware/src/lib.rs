//! # hamflight-firmware
//!
//! The hamflight core on the Crazyflie 2.1 (STM32F405RG, 168 MHz) and, in the `qemu` binary
//! (feature `qemu`), on QEMU's `netduinoplus2` (the same chip without a bootloader), for
//! processor-in-the-loop tests.
//!
//! Everything that does not touch the chip lives here and is unit-tested on the host
//! (`cargo test --lib --target x86_64-unknown-linux-gnu`):
//! - [`link`]: the UART frames (postcard + CRC-32 + COBS), shared with the host's PIL test;
//! - [`motor`]: rotor speed → 16-bit PWM, four `SetDutyCycle` outputs;
//! - [`control_loop`]: the tick (controller step on fresh input, watchdog, statistics).
//!
//! On the target, [`runtime`] holds the interrupt-side state and the cost/stack probes; the
//! binaries (`src/bin/crazyflie.rs`, `src/bin/qemu.rs`) only set up clocks, pins and handlers.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]

pub mod control_loop;
pub mod link;
pub mod motor;
#[cfg(target_os = "none")]
pub mod runtime;
#[cfg(target_os = "none")]
pub mod stack;

/// The weight blob embedded at build time (`HAMFLIGHT_WEIGHTS`, default
/// `weights/default.hfw`; see `build.rs`).
pub static WEIGHT_BLOB: &[u8] = include_bytes!(env!("HAMFLIGHT_BLOB_PATH"));

#[cfg(test)]
mod tests;
