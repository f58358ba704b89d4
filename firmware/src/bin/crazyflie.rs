//! hamflight on a Crazyflie 2.1: HSE 8 MHz → PLL 168 MHz, motors on TIM2/TIM4 (brushed, 328 kHz
//! PWM as crazyflie-firmware drives them), the link on the deck UART (USART3, PC10 TX / PC11 RX,
//! 1 Mbaud, or 2 Mbaud with `loop-1khz`), the control loop on TIM5. Logs over defmt-rtt; panics
//! through panic-probe.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use defmt_rtt as _;
use hamflight_firmware::runtime::{self, Board, Counter, IsrCell, LinkReceiver};
use panic_probe as _;
use stm32f4xx_hal::pac::{self, interrupt};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::serial::{config::Config, Rx, Serial};

/// Link baud rate. At 8N1 (10 bits a byte) 1 Mbaud carries 100 bytes/ms each way. An Input
/// frame with its setpoint is 120 bytes (`link`'s module doc; 64 without it), a Telemetry frame
/// about 84 (98 at most). At 500 Hz that is 60 and 42 bytes/ms: 1 Mbaud. At 1 kHz it is 120 and
/// 84, more than 1 Mbaud carries up and too close to it down, so the `loop-1khz` build runs the
/// link at 2 Mbaud (60 % and 42 % used). USART3 is on APB1 (42 MHz here): the divider 42 MHz /
/// (16 · 2 Mbaud) = 1 + 5/16 is exact in BRR (4 fraction bits), as 2 + 10/16 is for 1 Mbaud; the
/// APB1 USARTs reach 2.625 Mbaud with 16× oversampling, 5.25 with 8× (RM0090 §30.3.4). The other
/// end must run the same rate.
const LINK_BAUD: u32 = if cfg!(feature = "loop-1khz") {
    2_000_000
} else {
    1_000_000
};

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
