//! hamflight on a Crazyflie 2.1: HSE 8 MHz → PLL 168 MHz, motors on TIM2/TIM4 (brushed, 328 kHz
//! PWM as crazyflie-firmware drives them), the link on the deck UART (USART3, PC10 TX / PC11 RX,
//! 1 Mbaud), the control loop on TIM5. Logs over defmt-rtt; panics through panic-probe.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use defmt_rtt as _;
use hamflight_firmware::motor::Motors;
use hamflight_firmware::runtime;
use panic_probe as _;
use stm32f4xx_hal::pac::{self, interrupt};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::serial::{config::Config, Serial};

/// Link baud rate: an Input frame is ~145 bytes, 500 of them a second need ~730 kbit/s.
const LINK_BAUD: u32 = 1_000_000;

#[entry]
fn main() -> ! {
    let (Some(dp), Some(mut cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
        defmt::panic!("peripherals already taken");
    };
    // Crazyflie 2.1: 8 MHz crystal (crazyflie-firmware builds with HSE_VALUE=8000000).
    let clocks = dp
        .RCC
        .constrain()
        .cfgr
        .use_hse(8.MHz())
        .sysclk(168.MHz())
        .pclk1(42.MHz())
        .pclk2(84.MHz())
        .freeze();
    let gpioa = dp.GPIOA.split();
    let gpiob = dp.GPIOB.split();
    let gpioc = dp.GPIOC.split();

    // Motors (crazyflie-firmware motors_def.c, CF2.x brushed): M1 PA1 TIM2_CH2,
    // M2 PB11 TIM2_CH4, M3 PA15 TIM2_CH1, M4 PB9 TIM4_CH4.
    let (_pwm2, (t2c1, t2c2, _t2c3, t2c4)) = dp.TIM2.pwm_hz(328.kHz(), &clocks);
    let (_pwm4, (_t4c1, _t4c2, _t4c3, t4c4)) = dp.TIM4.pwm_hz(328.kHz(), &clocks);
    let mut m1 = t2c2.with(gpioa.pa1).erase();
    let mut m2 = t2c4.with(gpiob.pb11).erase();
    // PA15 resets as JTDI (AF0); SWD needs only PA13/PA14, so it can go to TIM2 (AF1).
    let mut m3 = t2c1.with(gpioa.pa15.into_alternate::<1>()).erase();
    let mut m4 = t4c4.with(gpiob.pb9).erase();
    for m in [&mut m1, &mut m2, &mut m3] {
        m.set_duty(0);
        m.enable();
    }
    m4.set_duty(0);
    m4.enable();
    let motors = Motors { m1, m2, m3, m4 };

    let serial: Serial<pac::USART3> = match Serial::new(
        dp.USART3,
        (gpioc.pc10, gpioc.pc11),
        Config::default().baudrate(LINK_BAUD.bps()),
        &clocks,
    ) {
        Ok(s) => s,
        Err(_) => defmt::panic!("USART3 cannot run at {} baud", LINK_BAUD),
    };
    let (mut tx, rx) = serial.split();

    let boot = runtime::init(motors, rx, dp.TIM5, clocks.timclk1().raw(), &mut cp);
    runtime::repaint_stack();
    match boot.blob {
        Ok(()) => defmt::info!(
            "hamflight: blob ok ({} bytes), loop {} Hz",
            hamflight_firmware::WEIGHT_BLOB.len(),
            hamflight_firmware::control_loop::LOOP_HZ
        ),
        Err(e) => defmt::error!("hamflight: weight blob rejected ({}): motors stay off", e),
    }
    loop {
        runtime::pump(&mut tx);
    }
}

#[interrupt]
fn USART3() {
    runtime::on_rx();
}

#[interrupt]
fn TIM5() {
    runtime::on_tick();
}
