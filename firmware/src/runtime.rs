//! The interrupt side on the STM32F405 (board and QEMU): who owns what, and the handlers' bodies.
//!
//! - USART RX interrupt (highest priority, short): bytes → [`FrameDecoder`] → the latest
//!   [`Input`] (or a request flag); bad frames counted.
//! - TIM5 update interrupt at [`LOOP_HZ`]: takes the latest input, runs
//!   [`ControlLoop::tick`] (controller, PWM) with the cost counter, queues the telemetry frame.
//!   The step runs outside any critical section, so reception is never blocked by it.
//! - Thread mode ([`pump`]): writes queued frames to the UART and sleeps.
//!
//! Nothing here depends on the board or on a cargo feature: each binary says which USART carries
//! the link (a [`LinkReceiver`] in its own `static`, [`Board::link_irq`]), at what clock TIM5
//! counts and which cost counter works ([`Board`]), then calls [`init`] and binds the interrupts
//! to [`on_rx`] and [`on_tick`]. So every binary builds with every feature set.

use crate::control_loop::{
    load_model, ControlLoop, CostCounter, Model, TickOutcome, LOOP_HZ, WATCHDOG_TICKS,
};
use crate::link::{
    self, CostUnit, Downlink, FrameDecoder, Hello, Input, Report, Uplink, MAX_FRAME,
};
use crate::motor::Motors;
use core::cell::{Cell, RefCell, UnsafeCell};
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use critical_section::Mutex;
use embedded_hal_nb::serial::{Read, Write};
use hamflight::model::{LearnedModel, ModelWeights};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::serial::RxListen;
use stm32f4xx_hal::timer::ErasedChannel;

/// The Crazyflie 2.1 motor outputs: M1 TIM2_CH2, M2 TIM2_CH4, M3 TIM2_CH1, M4 TIM4_CH4.
pub type BoardMotors = Motors<
    ErasedChannel<pac::TIM2>,
    ErasedChannel<pac::TIM2>,
    ErasedChannel<pac::TIM2>,
    ErasedChannel<pac::TIM4>,
>;

/// The four motor outputs at 328 kHz, duty 0, enabled (crazyflie-firmware `motors_def.c`,
/// CF2.x brushed). PA15 resets as JTDI (AF0); SWD needs only PA13/PA14, so it goes to TIM2 (AF1).
/// Under QEMU the same timers are modelled and the pins are inert.
pub fn board_motors(
    tim2: pac::TIM2,
    tim4: pac::TIM4,
    pins: (
        stm32f4xx_hal::gpio::PA1,
        stm32f4xx_hal::gpio::PB11,
        stm32f4xx_hal::gpio::PA15<stm32f4xx_hal::gpio::Alternate<0>>,
        stm32f4xx_hal::gpio::PB9,
    ),
    clocks: &stm32f4xx_hal::rcc::Clocks,
) -> BoardMotors {
    use stm32f4xx_hal::prelude::*;
    let (pa1, pb11, pa15, pb9) = pins;
    let (_pwm2, (t2c1, t2c2, _t2c3, t2c4)) = tim2.pwm_hz(328.kHz(), clocks);
    let (_pwm4, (_t4c1, _t4c2, _t4c3, t4c4)) = tim4.pwm_hz(328.kHz(), clocks);
    let mut m1 = t2c2.with(pa1).erase();
    let mut m2 = t2c4.with(pb11).erase();
    let mut m3 = t2c1.with(pa15.into_alternate::<1>()).erase();
    let mut m4 = t4c4.with(pb9).erase();
    for m in [&mut m1, &mut m2, &mut m3] {
        m.set_duty(0);
        m.enable();
    }
    m4.set_duty(0);
    m4.enable();
    Motors { m1, m2, m3, m4 }
}

/// The free-running counter that measures the step cost on a board.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Counter {
    /// DWT cycle counter: CPU cycles (real hardware; reads 0 under QEMU).
    Dwt,
    /// SysTick as a free-running 24-bit down-counter on the core clock. Under QEMU with
    /// `-icount shift=0` it advances 168 ticks per 1000 instructions.
    SysTick,
}

impl Counter {
    /// The unit the telemetry reports this counter's ticks in.
    pub const fn unit(self) -> CostUnit {
        match self {
            Self::Dwt => CostUnit::Cycles,
            Self::SysTick => CostUnit::QemuSysTick168MHz,
        }
    }
}

impl CostCounter for Counter {
    fn now(&mut self) -> u32 {
        match self {
            Self::Dwt => cortex_m::peripheral::DWT::cycle_count(),
            Self::SysTick => cortex_m::peripheral::SYST::get_current(),
        }
    }
    fn since(&mut self, start: u32) -> u32 {
        match self {
            Self::Dwt => cortex_m::peripheral::DWT::cycle_count().wrapping_sub(start),
            Self::SysTick => {
                start.wrapping_sub(cortex_m::peripheral::SYST::get_current()) & 0x00FF_FFFF
            }
        }
    }
}

/// What differs between the boards that [`init`] needs to know.
#[derive(Clone, Copy, Debug)]
pub struct Board {
    /// The interrupt of the link's USART (whose receiver the binary keeps in a
    /// [`LinkReceiver`] cell and hands to [`on_rx`]).
    pub link_irq: pac::Interrupt,
    /// The input clock of TIM5 (Hz).
    pub timer_clock_hz: u32,
    /// The step-cost counter that works where this binary runs.
    pub counter: Counter,
}

/// The link's receive side: a USART receiver (any [`Read<u8>`]) and the frame decoder. A binary
/// keeps one in a `static` [`IsrCell`] and calls [`on_rx`] on it from the USART's interrupt.
pub struct LinkReceiver<R> {
    rx: R,
    dec: FrameDecoder,
}

impl<R: Read<u8> + RxListen> LinkReceiver<R> {
    /// Enables `rx`'s receive interrupt (the NVIC line stays masked until [`init`]).
    pub fn new(mut rx: R) -> Self {
        rx.listen();
        Self {
            rx,
            dec: FrameDecoder::new(),
        }
    }
}

type Frame = heapless::Vec<u8, MAX_FRAME>;

struct Tick {
    control: ControlLoop<Model>,
    motors: BoardMotors,
    counter: Counter,
    timer: pac::TIM5,
}

/// State owned by one interrupt handler, reached by reference (never moved: the loop holds the
/// model, kilobytes that must not be copied every tick). An atomic flag makes a second,
/// overlapping borrow fail instead of aliasing. Empty, it is all zeros, so it lives in `.bss`
/// (an `Option<T>` static would put a 10 KiB initial image of `None` into flash).
pub struct IsrCell<T> {
    value: UnsafeCell<MaybeUninit<T>>,
    full: AtomicBool,
    busy: AtomicBool,
}

// SAFETY: access to `value` is exclusive through the `busy` flag (`with`, `set`); T moves
// between contexts, hence `T: Send`.
unsafe impl<T: Send> Sync for IsrCell<T> {}

impl<T> IsrCell<T> {
    /// An empty cell.
    pub const fn new() -> Self {
        Self {
            value: UnsafeCell::new(MaybeUninit::uninit()),
            full: AtomicBool::new(false),
            busy: AtomicBool::new(false),
        }
    }

    /// Runs `f` on the content; `None` if empty or already borrowed.
    pub fn with<R>(&self, f: impl FnOnce(&mut T) -> R) -> Option<R> {
        if self.busy.swap(true, Ordering::Acquire) {
            return None;
        }
        let r = if self.full.load(Ordering::Acquire) {
            // SAFETY: `busy` gives exclusive access, and `full` says the value is initialised.
            Some(f(unsafe { (*self.value.get()).assume_init_mut() }))
        } else {
            None
        };
        self.busy.store(false, Ordering::Release);
        r
    }

    /// Fills an empty cell with `make()`, built in place where the compiler can; false (and
    /// `make` not called) if the cell is full or borrowed.
    pub fn init_with(&self, make: impl FnOnce() -> T) -> bool {
        if self.busy.swap(true, Ordering::Acquire) {
            return false;
        }
        let ok = !self.full.load(Ordering::Acquire);
        if ok {
            // SAFETY: exclusive through `busy`; the slot is empty, so nothing is overwritten.
            unsafe { (*self.value.get()).write(make()) };
            self.full.store(true, Ordering::Release);
        }
        self.busy.store(false, Ordering::Release);
        ok
    }
}

impl<T> Default for IsrCell<T> {
    fn default() -> Self {
        Self::new()
    }
}

static TICK: IsrCell<Tick> = IsrCell::new();
/// The learned model's weights, decoded in place at boot (all zeros until then: `.bss`).
static MODEL: ModelSlot = ModelSlot::new();
static SYSTICK_COST: AtomicBool = AtomicBool::new(false);
static BOOT_STACK_PEAK: AtomicU32 = AtomicU32::new(0);
static LATEST: Mutex<Cell<Option<Input>>> = Mutex::new(Cell::new(None));
static TXQ: Mutex<RefCell<heapless::Deque<Frame, 8>>> =
    Mutex::new(RefCell::new(heapless::Deque::new()));
static BAD_FRAMES: AtomicU32 = AtomicU32::new(0);
static HELLO_REQ: AtomicBool = AtomicBool::new(false);
static FINISH_REQ: AtomicBool = AtomicBool::new(false);
static FINISHED: AtomicBool = AtomicBool::new(false);
static BLOB_OK: AtomicBool = AtomicBool::new(false);
static BLOB_CRC: AtomicU32 = AtomicU32::new(0);
static STEPS: AtomicU32 = AtomicU32::new(0);
static REPORT: Mutex<Cell<Option<Report>>> = Mutex::new(Cell::new(None));

fn queue(msg: &Downlink) {
    let mut buf = [0u8; MAX_FRAME];
    if let Ok(n) = link::encode(msg, &mut buf) {
        if let Ok(frame) = Frame::from_slice(buf.get(..n).unwrap_or(&[])) {
            critical_section::with(|cs| {
                // A full queue drops the newest frame: the link is slower than the loop. Inside
                // the critical section nothing else holds the queue; try_borrow_mut keeps the
                // panic path (and its formatting code, 2 KB of flash) out of the image.
                if let Ok(mut q) = TXQ.borrow(cs).try_borrow_mut() {
                    let _ = q.push_back(frame);
                }
            });
        }
    }
}

fn hello() -> Downlink {
    Downlink::Hello(Hello {
        loop_hz: LOOP_HZ,
        blob_ok: BLOB_OK.load(Ordering::Relaxed),
        blob_len: crate::WEIGHT_BLOB.len() as u32,
        blob_crc: BLOB_CRC.load(Ordering::Relaxed),
        model: crate::control_loop::MODEL_KIND,
        cost_unit: if SYSTICK_COST.load(Ordering::Relaxed) {
            Counter::SysTick.unit()
        } else {
            Counter::Dwt.unit()
        },
        watchdog_ticks: WATCHDOG_TICKS,
    })
}

/// What [`init`] reports.
pub struct Boot {
    /// The blob check: `Err` keeps the motors off for good.
    pub blob: Result<(), hamflight::blob::BlobError>,
}

/// A `static` home for the learned model, filled once at boot by decoding the blob in place.
struct ModelSlot {
    model: UnsafeCell<LearnedModel>,
    taken: AtomicBool,
}

// SAFETY: `take` hands out the only reference, once.
unsafe impl Sync for ModelSlot {}

impl ModelSlot {
    const fn new() -> Self {
        Self {
            model: UnsafeCell::new(LearnedModel::new(ModelWeights::ZERO)),
            taken: AtomicBool::new(false),
        }
    }

    /// The slot, the first time; `None` after.
    // A singleton: the flag hands the one `&mut` out once, like `cortex_m::singleton!` (which
    // would build the 10 KiB value on the stack first).
    #[allow(clippy::mut_from_ref)]
    fn take(&'static self) -> Option<&'static mut LearnedModel> {
        if self.taken.swap(true, Ordering::AcqRel) {
            return None;
        }
        // SAFETY: the flag makes this the one and only reference, for the rest of the program.
        Some(unsafe { &mut *self.model.get() })
    }
}

/// Decodes the blob in place into a `static`, builds the loop, starts TIM5 at [`LOOP_HZ`], starts
/// the cost counter, enables the interrupts (link RX above the control tick) and queues the boot
/// [`Hello`]. The binary has put its [`LinkReceiver`] in place before. Nothing large passes
/// through the stack (the boot peak is reported as `stack_boot_peak_bytes`); call
/// [`repaint_stack`] afterwards. Never inlined, so that its set-up temporaries do not stay in the
/// caller's frame, under every interrupt for the rest of the flight.
#[inline(never)]
pub fn init(
    mut motors: BoardMotors,
    timer: pac::TIM5,
    board: Board,
    core: &mut cortex_m::Peripherals,
) -> Boot {
    motors.off();
    SYSTICK_COST.store(board.counter == Counter::SysTick, Ordering::Relaxed);
    let Some(slot) = MODEL.take() else {
        // Only a second call gets here; the first one's loop keeps running.
        return Boot { blob: Ok(()) };
    };
    let model = load_model(crate::WEIGHT_BLOB, slot);
    let blob = model.as_ref().map(|_| ()).map_err(|e| *e);
    BLOB_OK.store(blob.is_ok(), Ordering::Relaxed);
    BLOB_CRC.store(
        hamflight::blob::crc32(crate::WEIGHT_BLOB),
        Ordering::Relaxed,
    );

    // Cost counters: both are started; the board says which one works where it runs.
    core.DCB.enable_trace();
    core.DWT.enable_cycle_counter();
    core.SYST
        .set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
    core.SYST.set_reload(0x00FF_FFFF);
    core.SYST.clear_current();
    core.SYST.enable_counter();

    // TIM5: 1 MHz count, update at LOOP_HZ.
    // SAFETY: RCC APB1ENR is only modified here, before interrupts are enabled.
    unsafe {
        (*pac::RCC::ptr())
            .apb1enr()
            .modify(|_, w| w.tim5en().set_bit())
    };
    let psc = (board.timer_clock_hz / 1_000_000).saturating_sub(1);
    timer.cr1().write(|w| w.cen().clear_bit());
    timer.psc().write(|w| w.psc().set(psc as u16));
    timer.arr().write(|w| w.arr().set(1_000_000 / LOOP_HZ - 1));
    timer.egr().write(|w| w.ug().set_bit());
    timer.sr().write(|w| w.uif().clear_bit());
    timer.dier().write(|w| w.uie().set_bit());

    TICK.init_with(|| Tick {
        control: ControlLoop::new(model),
        motors,
        counter: board.counter,
        timer,
    });
    queue(&hello());
    // SAFETY: the handlers' state is in place; priorities are set before unmasking.
    unsafe {
        core.NVIC.set_priority(board.link_irq, 0x40);
        core.NVIC.set_priority(pac::Interrupt::TIM5, 0x80);
        cortex_m::peripheral::NVIC::unmask(board.link_irq);
        cortex_m::peripheral::NVIC::unmask(pac::Interrupt::TIM5);
    }
    // Start the loop last.
    TICK.with(|t| t.timer.cr1().write(|w| w.cen().set_bit()));
    Boot { blob }
}

/// Body of the link's RX interrupt: drains the USART of `link` into its decoder.
pub fn on_rx<R: Read<u8>>(link: &IsrCell<LinkReceiver<R>>) {
    link.with(|l| rx_drain(&mut l.rx, &mut l.dec));
}

fn rx_drain<R: Read<u8>>(rx: &mut R, dec: &mut FrameDecoder) {
    loop {
        match rx.read() {
            Ok(byte) => match dec.push::<Uplink>(byte) {
                Some(Ok(Uplink::Input(input))) => {
                    critical_section::with(|cs| LATEST.borrow(cs).set(Some(input)));
                }
                Some(Ok(Uplink::Hello)) => HELLO_REQ.store(true, Ordering::Release),
                Some(Ok(Uplink::Finish)) => FINISH_REQ.store(true, Ordering::Release),
                Some(Err(_)) => {
                    BAD_FRAMES.fetch_add(1, Ordering::Relaxed);
                }
                None => {}
            },
            Err(nb::Error::WouldBlock) => break,
            Err(nb::Error::Other(_)) => {
                // Overrun, framing or noise: the frame in progress is lost.
                BAD_FRAMES.fetch_add(1, Ordering::Relaxed);
                *dec = FrameDecoder::new();
            }
        }
    }
}

/// Body of the TIM5 update interrupt: one control tick.
pub fn on_tick() {
    // SAFETY: only clears TIM5's update flag (whether or not the loop is set up).
    unsafe { (*pac::TIM5::ptr()).sr().write(|w| w.uif().clear_bit()) };
    if FINISHED.load(Ordering::Acquire) {
        return;
    }
    TICK.with(tick);
}

fn tick(t: &mut Tick) {
    if FINISH_REQ.swap(false, Ordering::AcqRel) {
        t.motors.off();
        let (peak, size) = stack_peak();
        let mut report = t.control.report();
        report.stack_peak_bytes = peak;
        report.stack_size_bytes = size;
        report.stack_boot_peak_bytes = BOOT_STACK_PEAK.load(Ordering::Relaxed);
        report.bad_frames = BAD_FRAMES.load(Ordering::Relaxed);
        queue(&Downlink::Report(report));
        critical_section::with(|cs| REPORT.borrow(cs).set(Some(report)));
        FINISHED.store(true, Ordering::Release);
        t.timer.cr1().write(|w| w.cen().clear_bit());
        return; // FINISHED: motors off for good.
    }

    if let Some(input) = critical_section::with(|cs| LATEST.borrow(cs).take()) {
        t.control.on_input(input);
    }
    match t.control.tick(&mut t.motors, &mut t.counter) {
        TickOutcome::Stepped(mut tel) => {
            STEPS.fetch_add(1, Ordering::Release);
            tel.bad_frames = BAD_FRAMES.load(Ordering::Relaxed);
            queue(&Downlink::Telemetry(tel));
        }
        TickOutcome::Stopped(status) => queue(&Downlink::Status(status)),
        TickOutcome::Idle => {}
    }
}

/// After the final report (a [`finish`] request handled: the loop has stopped for good), runs
/// `f` in thread mode on the controller the loop flew; `None` before that, or without a
/// controller (the blob was rejected). For self-driven benchmarks that probe the step further
/// (its stack) without touching the counted ticks.
pub fn with_finished_controller<R>(
    f: impl FnOnce(&mut hamflight::FlightController<Model>) -> R,
) -> Option<R> {
    if !FINISHED.load(Ordering::Acquire) {
        return None;
    }
    // The tick handler returns before touching TICK once FINISHED is set.
    TICK.with(|t| t.control.controller_mut().map(f)).flatten()
}

/// Hands an input to the next tick as if it had come over the link (self-driven benchmarks).
pub fn inject(input: Input) {
    critical_section::with(|cs| LATEST.borrow(cs).set(Some(input)));
}

/// Asks the next tick to stop the motors and produce the final [`Report`], as
/// [`Uplink::Finish`] does.
pub fn finish() {
    FINISH_REQ.store(true, Ordering::Release);
}

/// Control steps run so far.
pub fn steps() -> u32 {
    STEPS.load(Ordering::Acquire)
}

/// The final report, once a finish request was handled.
pub fn report() -> Option<Report> {
    critical_section::with(|cs| REPORT.borrow(cs).get())
}

/// Thread mode: writes queued frames to the link, answers Hello requests, sleeps until the next
/// interrupt. Returns true once a Finish was handled and its report sent.
pub fn pump<W: Write<u8>>(tx: &mut W) -> bool {
    if HELLO_REQ.swap(false, Ordering::AcqRel) {
        queue(&hello());
    }
    loop {
        let frame = critical_section::with(|cs| {
            TXQ.borrow(cs)
                .try_borrow_mut()
                .ok()
                .and_then(|mut q| q.pop_front())
        });
        match frame {
            Some(f) => {
                for &b in f.iter() {
                    // A write error leaves the frame cut: the host's CRC drops it.
                    if nb::block!(tx.write(b)).is_err() {
                        break;
                    }
                }
            }
            None => break,
        }
    }
    let _ = nb::block!(tx.flush());
    if FINISHED.load(Ordering::Acquire) {
        return true;
    }
    // Sleep unless something arrived between the check above and here (WFI wakes on a pending
    // interrupt even with PRIMASK set).
    cortex_m::interrupt::disable();
    let idle = critical_section::with(|cs| TXQ.borrow(cs).try_borrow().is_ok_and(|q| q.is_empty()))
        && !HELLO_REQ.load(Ordering::Acquire);
    if idle {
        cortex_m::asm::wfi();
    }
    // SAFETY: re-enables the interrupts disabled just above; no critical section is open here.
    unsafe { cortex_m::interrupt::enable() };
    false
}

/// Records the boot-time stack peak (clock, pin and loop set-up, blob check) and
/// paints the stack below the current frame again, so that [`stack_peak`] afterwards measures
/// the steady state: the control loop, the interrupts and thread mode.
pub fn repaint_stack() {
    BOOT_STACK_PEAK.store(stack_peak().0, Ordering::Relaxed);
    crate::stack::repaint_whole();
}

pub use crate::stack::{measure_stack, stack_peak, PROBE_WINDOW_BYTES};
