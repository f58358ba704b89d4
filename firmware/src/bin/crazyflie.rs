//! hamflight on a Crazyflie 2.1: HSE 8 MHz → PLL 168 MHz, motors on TIM2/TIM4 (brushed, 328 kHz
//! PWM as crazyflie-firmware drives them), the link on the deck UART (USART3, PC10 TX / PC11 RX,
//! 1 Mbaud), the control loop on TIM5. Logs over defmt-rtt; panics through panic-probe.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use defmt_rtt as _;
use hamflight_firmware::runtime::{self, Board, Counter, IsrCell, LinkReceiver};
use panic_probe as _;
use stm32f4xx_hal::pac::{self, interrupt};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::serial::{config::Config, Rx, Serial};

/// Link baud rate: an Input frame is ~145 bytes, 500 of them a second need ~730 kbit/s.
const LINK_BAUD: u32 = 1_000_000;

/// The link's receiver: deck connector UART1 = USART3 (PC10 TX / PC11 RX; USART6 is the nRF51
/// syslink).
static LINK: IsrCell<LinkReceiver<Rx<pac::USART3>>> = IsrCell::new();

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

    let motors = runtime::board_motors(
        dp.TIM2,
        dp.TIM4,
        (gpioa.pa1, gpiob.pb11, gpioa.pa15, gpiob.pb9),
        &clocks,
    );

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
    LINK.init_with(|| LinkReceiver::new(rx));

    let board = Board {
        link_irq: pac::Interrupt::USART3,
        timer_clock_hz: clocks.timclk1().raw(),
        counter: Counter::Dwt,
    };
    let boot = runtime::init(motors, dp.TIM5, board, &mut cp);
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
    runtime::on_rx(&LINK);
}

#[interrupt]
fn TIM5() {
    runtime::on_tick();
}
