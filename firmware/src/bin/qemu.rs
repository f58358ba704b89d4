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
use hamflight_firmware::runtime::{self, Board, Counter, IsrCell, LinkReceiver};
use stm32f4xx_hal::pac::{self, interrupt};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::serial::{config::Config, Rx, Serial};

/// QEMU's STM32F405 timers count at this fixed clock, whatever the RCC says.
const QEMU_TIMER_CLOCK_HZ: u32 = 48_000_000;

/// The link's receiver: USART1, which QEMU connects to the first `-serial`.
static LINK: IsrCell<LinkReceiver<Rx<pac::USART1>>> = IsrCell::new();

#[entry]
fn main() -> ! {
    let (Some(dp), Some(mut cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
        fail("peripherals already taken")
    };
    // HSI, no PLL: nothing to wait for.
    let clocks = dp.RCC.constrain().cfgr.freeze();
    let gpioa = dp.GPIOA.split();
    let gpiob = dp.GPIOB.split();

    let motors = runtime::board_motors(
        dp.TIM2,
        dp.TIM4,
        (gpioa.pa1, gpiob.pb11, gpioa.pa15, gpiob.pb9),
        &clocks,
    );

    let Ok(serial) = Serial::<pac::USART1>::new(
        dp.USART1,
        (gpioa.pa9, gpioa.pa10),
        Config::default().baudrate(115_200.bps()),
        &clocks,
    ) else {
        fail("USART1 set-up failed")
    };
    let (mut tx, rx) = serial.split();
    LINK.init_with(|| LinkReceiver::new(rx));

    let board = Board {
        link_irq: pac::Interrupt::USART1,
        timer_clock_hz: QEMU_TIMER_CLOCK_HZ,
        // DWT's cycle counter reads 0 under QEMU.
        counter: Counter::SysTick,
    };
    let boot = runtime::init(motors, dp.TIM5, board, &mut cp);
    runtime::repaint_stack();
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
    #[cfg(feature = "bench")]
    if boot.blob.is_err() {
        // No step would ever run.
        fail("BENCH impossible: the weight blob was rejected");
    } else {
        bench::run(&mut tx);
    }
    #[cfg(not(feature = "bench"))]
    loop {
        if runtime::pump(&mut tx) {
            hprintln!("hamflight-qemu: finished");
            debug::exit(debug::EXIT_SUCCESS);
        }
    }
}

/// Self-driven cost benchmark (feature `bench`): one input per tick along paper-spiral, with the
/// state off the reference by a few centimetres and degrees so that every term of the law works.
#[cfg(feature = "bench")]
mod bench {
    use super::*;
    use hamflight::{FlightController, Measurement, Output, Setpoint, State};
    use hamflight_firmware::control_loop::{Model, DT_S};
    use hamflight_firmware::link::{Input, WireState};
    use libm::{cosf, sinf};
    use nalgebra::{Rotation3, Vector3};

    /// Steps measured: 2000, or `HAMFLIGHT_BENCH_STEPS` at build time (the instruction trace of
    /// `tools/trace-profile.py` runs a shorter bench).
    const STEPS: u32 = match option_env!("HAMFLIGHT_BENCH_STEPS") {
        Some(s) => parse_u32(s),
        None => 2000,
    };

    /// A decimal number at compile time (a malformed one fails the build).
    const fn parse_u32(s: &str) -> u32 {
        let b = s.as_bytes();
        let mut n: u32 = 0;
        let mut i = 0;
        while i < b.len() {
            assert!(b[i].is_ascii_digit(), "HAMFLIGHT_BENCH_STEPS: not a number");
            n = n * 10 + (b[i] - b'0') as u32;
            i += 1;
        }
        assert!(n > 0, "HAMFLIGHT_BENCH_STEPS: at least 1");
        n
    }

    // Inlined (into the probes too): the benchmark's frame stays as it was.
    #[inline(always)]
    fn input(k: u32) -> Input {
        let t = k as f32 * DT_S;
        let w = core::f32::consts::TAU / 10.0;
        let (s, c) = (sinf(w * t), cosf(w * t));
        let p_ref = Vector3::new(0.5 * c, 0.5 * s, 0.5 + 0.03 * t);
        let v_ref = Vector3::new(-0.5 * w * s, 0.5 * w * c, 0.03);
        let a_ref = Vector3::new(-0.5 * w * w * c, -0.5 * w * w * s, 0.0);
        let j_ref = Vector3::new(0.5 * w * w * w * s, -0.5 * w * w * w * c, 0.0);
        let state = hamflight::State {
            p_m: p_ref + Vector3::new(0.02 * s, -0.01 * c, 0.005),
            rot: Rotation3::from_euler_angles(0.05 * s, -0.04 * c, 0.1 * s).into_inner(),
            v_body_m_s: v_ref + Vector3::new(0.01, -0.02, 0.0),
            w_body_rad_s: Vector3::new(0.2 * c, -0.1 * s, 0.05),
        };
        let sp = hamflight::Setpoint {
            p_m: p_ref,
            v_m_s: v_ref,
            a_m_s2: a_ref,
            j_m_s3: j_ref,
            yaw_rad: 0.0,
            yaw_rate_rad_s: 0.0,
        };
        Input {
            seq: k,
            state: WireState::from(&state),
            setpoint: Some(sp),
        }
    }

    pub fn run<W: embedded_hal_nb::serial::Write<u8>>(tx: &mut W) -> ! {
        for k in 0..STEPS {
            runtime::inject(input(k));
            while runtime::steps() <= k {
                runtime::pump(tx);
            }
        }
        runtime::finish();
        while !runtime::pump(tx) {}
        match runtime::report() {
            Some(r) => hprintln!(
                "BENCH steps={} total={} max={} min={} stack_peak={} stack_boot_peak={} stack_size={} blob_len={} unit=systick168",
                r.steps,
                r.total_step_cost,
                r.max_step_cost,
                r.min_step_cost,
                r.stack_peak_bytes,
                r.stack_boot_peak_bytes,
                r.stack_size_bytes,
                hamflight_firmware::WEIGHT_BLOB.len()
            ),
            None => hprintln!("BENCH no report"),
        }
        stack_report();
        debug::exit(debug::EXIT_SUCCESS);
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// The stack probes, after the counted run (and after the stack peaks of its report), on the
    /// controller it flew: they change nothing the BENCH line counts. Prints the STACK line.
    /// Out of line, so that the benchmark's frame, under every tick, is what it was without them.
    #[inline(never)]
    fn stack_report() {
        match runtime::with_finished_controller(probe_stacks) {
            Some(s) => hprintln!(
                "STACK step={} step_stress={} window={}",
                s.step,
                s.step_stress,
                runtime::PROBE_WINDOW_BYTES
            ),
            None => hprintln!("STACK no controller"),
        }
    }

    /// Measured stack high-water marks (bytes, from the call: [`runtime::measure_stack`]).
    struct Stacks {
        /// [`step`] over the benchmark's inputs.
        step: u32,
        /// [`step`] over the cases the benchmark does not fly ([`stress_inputs`]).
        step_stress: u32,
    }

    /// The controller's step as the Crazyflie app's `hf_step` runs it (`step_into`, the output
    /// written in place): one call that [`runtime::measure_stack`] measures and
    /// `stack-estimate.py` bounds. The tick handler inlines its own copy of the step, so this is
    /// the step's own stack, without the handler's frame around it.
    #[inline(never)]
    fn step(
        ctl: &mut FlightController<Model>,
        state: &State,
        sp: &Setpoint,
        meas: &Measurement,
        dt_s: f32,
        out: &mut Output,
    ) {
        ctl.step_into(state, sp, meas, dt_s, out);
    }

    /// [`step`]'s stack on one input (interrupts off: nothing else lands in the window).
    fn step_stack(
        ctl: &mut FlightController<Model>,
        state: &State,
        sp: &Setpoint,
        meas: &Measurement,
        dt_s: f32,
    ) -> u32 {
        let mut out = Output::default();
        cortex_m::interrupt::free(|_| {
            runtime::measure_stack(|| step(ctl, state, sp, meas, dt_s, &mut out)).1
        })
    }

    /// The benchmark's inputs again, then [`stress_inputs`].
    fn probe_stacks(ctl: &mut FlightController<Model>) -> Stacks {
        let none = Measurement::default();
        let mut step = 0;
        for k in 0..STEPS {
            let i = input(k);
            let sp = i.setpoint.unwrap_or_default();
            step = step.max(step_stack(ctl, &State::from(&i.state), &sp, &none, DT_S));
        }
        let mut step_stress = 0;
        for k in 0..STRESS_STEPS {
            let (state, sp, meas, dt_s) = stress_inputs(k);
            step_stress = step_stress.max(step_stack(ctl, &state, &sp, &meas, dt_s));
        }
        Stacks { step, step_stress }
    }

    /// Steps of [`stress_inputs`].
    const STRESS_STEPS: u32 = 400;

    /// What the benchmark's flight near the reference never does, a block of steps each: the
    /// accelerometer present (the composite law's measured branch; the link carries none),
    /// rotor saturation and the tilt limit (metres and radians off, fast), yaw across ±π with a
    /// fast yaw reference, the fault paths (a non-finite state, a bad dt), then the benchmark's
    /// flight again with the accelerometer.
    fn stress_inputs(k: u32) -> (State, Setpoint, Measurement, f32) {
        let i = input(k);
        let mut state = State::from(&i.state);
        let mut sp = i.setpoint.unwrap_or_default();
        let mut meas = Measurement {
            acc_body_m_s2: Some(Vector3::new(0.3, -0.2, 9.6)),
        };
        let mut dt_s = DT_S;
        let t = k as f32 * DT_S;
        match k / 50 {
            0 | 7 => {}
            1 => {
                // Far and fast: every rotor at a limit, the tilt limited.
                state.p_m += Vector3::new(2.0, -1.5, -1.0);
                state.v_body_m_s = Vector3::new(-3.0, 2.0, 1.5);
                state.rot = Rotation3::from_euler_angles(0.9, -0.7, 0.3).into_inner();
                state.w_body_rad_s = Vector3::new(6.0, -5.0, 3.0);
                meas.acc_body_m_s2 = None;
            }
            2 => {
                state.p_m += Vector3::new(-2.0, 1.5, 1.0);
                state.rot = Rotation3::from_euler_angles(-1.2, 1.0, -2.5).into_inner();
                state.w_body_rad_s = Vector3::new(-8.0, 7.0, -4.0);
            }
            3 => {
                // Yaw across ±π, the reference turning fast.
                state.rot = Rotation3::from_euler_angles(0.0, 0.0, -3.1 + 0.01 * t).into_inner();
                sp.yaw_rad = 3.1;
                sp.yaw_rate_rad_s = 4.0;
            }
            4 => {
                // A huge yaw reference: the whole-turn wrap before the reduction.
                sp.yaw_rad = 1.0e5 + t;
            }
            5 => {
                state.p_m.x = f32::NAN;
            }
            _ => {
                dt_s = 0.0;
            }
        }
        (state, sp, meas, dt_s)
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
    runtime::on_rx(&LINK);
}

#[interrupt]
fn TIM5() {
    runtime::on_tick();
}
