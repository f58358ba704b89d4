//! The stack's paint: cortex-m-rt's `paint-stack` fills it at reset, and the lowest word that
//! lost the paint marks the deepest the stack has been. The whole stack's peak
//! ([`stack_peak`]) and one call's high-water mark ([`measure_stack`]).

/// Paints the whole stack below the current frame again (a margin below it), so that
/// [`stack_peak`] afterwards measures from here on.
pub fn repaint_whole() {
    repaint_below(stack_end());
}

/// The stack's lowest address (cortex-m-rt's `_stack_end`).
fn stack_end() -> usize {
    extern "C" {
        static _stack_end: u32;
    }
    core::ptr::addr_of!(_stack_end) as usize
}

/// Peak stack use and stack size (bytes): cortex-m-rt's `paint-stack` fills everything between
/// `_stack_end` and `_stack_start` with `0xCCCC_CCCC` at reset; the lowest word that lost its
/// paint marks the deepest the stack has been.
pub fn stack_peak() -> (u32, u32) {
    extern "C" {
        static _stack_start: u32;
    }
    let lo = stack_end();
    let hi = core::ptr::addr_of!(_stack_start) as usize;
    let p = lowest_unpainted(lo, hi);
    ((hi - p) as u32, (hi - lo) as u32)
}

/// The lowest word in `[lo, hi)` (word-aligned addresses inside the stack) that does not hold the
/// paint, or `hi`.
fn lowest_unpainted(lo: usize, hi: usize) -> usize {
    let mut p = lo;
    while p < hi {
        // SAFETY: p is a word-aligned address inside RAM, between the linker's stack bounds.
        let v = unsafe { core::ptr::read_volatile(p as *const u32) };
        if v != cortex_m_rt::STACK_PAINT_VALUE {
            break;
        }
        p += 4;
    }
    p
}

/// The stack below a [`measure_stack`] that it paints and scans (bytes): room for a control
/// step (about 1 KB) four times over. A call that takes all of it reads as this much.
pub const PROBE_WINDOW_BYTES: u32 = 4096;

/// Runs `f` and returns, besides its result, the deepest the stack went below the caller's frame
/// meanwhile (bytes): the paint is laid in [`PROBE_WINDOW_BYTES`] below the stack pointer (below
/// the painter's own frame), `f` runs, and the lowest word that lost the paint marks the depth.
/// Inlined into the caller, whose stack pointer (MSP: thread mode's under cortex-m-rt, and every
/// handler's) is the reference: with `f` a call to a function
/// that is not inlined, the figure is that function's stack from its call (return address,
/// frames, its callees' frames), which `stack-estimate.py` bounds from above. A high-water
/// mark: a frame reserved but never written in this run does not count, and the painter's own
/// few words below the reference read as used.
///
/// Interrupts that nest in `f` count as `f`'s: run it with interrupts off. The repaint wipes out
/// what an earlier, deeper use left in the window, so read [`stack_peak`] first.
#[inline(always)]
pub fn measure_stack<R>(f: impl FnOnce() -> R) -> (R, u32) {
    let sp = cortex_m::register::msp::read() as usize;
    let bottom = sp
        .saturating_sub(PROBE_WINDOW_BYTES as usize)
        .max(stack_end())
        & !3;
    repaint_below(bottom);
    let r = f();
    let used = sp.saturating_sub(lowest_unpainted(bottom, sp));
    (r, used as u32)
}

/// Paints `[bottom, a margin below this function's stack pointer)`. Out of line, so that its
/// frame is a fixed few words under the caller's.
#[inline(never)]
fn repaint_below(bottom: usize) {
    let top = (cortex_m::register::msp::read() as usize).saturating_sub(32) & !3;
    cortex_m::interrupt::free(|_| {
        let mut p = bottom;
        while p < top {
            // SAFETY: word-aligned, inside the stack below the live frames, interrupts disabled.
            unsafe { core::ptr::write_volatile(p as *mut u32, cortex_m_rt::STACK_PAINT_VALUE) };
            p += 4;
        }
    });
}
