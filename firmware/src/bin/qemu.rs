//! hamflight on QEMU's `netduinoplus2` (STM32F405): the Crazyflie firmware's control loop with
//! QEMU's differences only — HSI clock (QEMU has no RCC model: a PLL set-up would wait forever),
//! the link on USART1 (QEMU wires the first `-serial` to USART1), timers clocked at QEMU's fixed
//! 48 MHz, messages and exit over semihosting.
//!
//! Run: `qemu-system-arm -M netduinoplus2 -nographic -semihosting-config enable=on,target=native
//! -serial tcp:127.0.0.1:PORT -kernel target/thumbv7em-none-eabihf/release/qemu`
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use hamflight_firmware::motor::Motors;
use hamflight_firmware::runtime;
use stm32f4xx_hal::pac::{self, interrupt};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::serial::{config::Config, Serial};

/// QEMU's STM32F405 timers count at this fixed clock, whatever the RCC says.
const QEMU_TIMER_CLOCK_HZ: u32 = 48_000_000;

#[entry]
fn main() -> ! {
    let (Some(dp), Some(mut cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
        fail("peripherals already taken")
    };
    // HSI, no PLL: nothing to wait for.
    let clocks = dp.RCC.constrain().cfgr.freeze();
    let gpioa = dp.GPIOA.split();
    let gpiob = dp.GPIOB.split();

    // The same motor outputs as the Crazyflie (QEMU models TIM2..TIM5; the pins are inert).
    let (_pwm2, (t2c1, t2c2, _t2c3, t2c4)) = dp.TIM2.pwm_hz(328.kHz(), &clocks);
    let (_pwm4, (_t4c1, _t4c2, _t4c3, t4c4)) = dp.TIM4.pwm_hz(328.kHz(), &clocks);
    let mut m1 = t2c2.with(gpioa.pa1).erase();
    let mut m2 = t2c4.with(gpiob.pb11).erase();
    let mut m3 = t2c1.with(gpioa.pa15.into_alternate::<1>()).erase();
    let mut m4 = t4c4.with(gpiob.pb9).erase();
    for m in [&mut m1, &mut m2, &mut m3] {
        m.set_duty(0);
        m.enable();
    }
    m4.set_duty(0);
    m4.enable();
    let motors = Motors { m1, m2, m3, m4 };

    let Ok(serial) = Serial::<pac::USART1>::new(
        dp.USART1,
        (gpioa.pa9, gpioa.pa10),
        Config::default().baudrate(115_200.bps()),
        &clocks,
    ) else {
        fail("USART1 set-up failed")
    };
    let (mut tx, rx) = serial.split();

    let boot = runtime::init(motors, rx, dp.TIM5, QEMU_TIMER_CLOCK_HZ, &mut cp);
    match boot.blob {
        Ok(()) => hprintln!(
            "hamflight-qemu: blob ok ({} bytes), loop {} Hz",
            hamflight_firmware::WEIGHT_BLOB.len(),
            hamflight_firmware::control_loop::LOOP_HZ
        ),
        Err(e) => hprintln!(
            "hamflight-qemu: weight blob rejected ({}): motors stay off",
            e
        ),
    }
    loop {
        if runtime::pump(&mut tx) {
            hprintln!("hamflight-qemu: finished");
            debug::exit(debug::EXIT_SUCCESS);
        }
    }
}

fn fail(msg: &str) -> ! {
    hprintln!("hamflight-qemu: {}", msg);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("hamflight-qemu: panic: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

#[interrupt]
fn USART1() {
    runtime::on_rx();
}

#[interrupt]
fn TIM5() {
    runtime::on_tick();
}
