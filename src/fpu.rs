//! The FPU instructions stable Rust cannot reach from `core`: fused multiply–add for the dense
//! layers and square root, bit-identical on every target.
//!
//! Each output of [`affine`] is one chain a ← fma(wᵢ, xᵢ, a) from the bias, in input order, each
//! step rounded once (IEEE 754 `fusedMultiplyAdd`). On the Cortex-M4F that is `vfma.f32`, in a
//! small assembly loop for the two input widths the model has (9 and 16): a row's weights come
//! in with one or two `vldmia` and the inputs stay in registers for the whole layer, about 1.4
//! instructions per multiply–add against 3 for the compiler's `vldr`/`vmul`/`vadd` (stable Rust
//! has no `mul_add` in `core`, and LLVM never fuses on its own). Elsewhere [`fma`] is
//! `f32::mul_add` (with `std`) or `libm::fmaf`. All are correctly rounded, so the firmware and a
//! host build of the same code give the same bits; the processor-in-the-loop test checks it.
//!
//! The assembly names no FPU register as an operand or clobber (stable Rust only allows the
//! `sreg` class with the double-precision `vfp2` feature, which the single-precision M4F lacks):
//! it saves the registers it uses with `vpush` and restores them with `vpop`, and takes only
//! pointers and bit patterns in core registers.
//!
//! [`sqrt`] is one `vsqrt.f32` on the M4F against ≈ 50 instructions of `libm::sqrtf`'s integer
//! algorithm; both are correctly rounded, as is `f32::sqrt`.

/// a·b + c, rounded once (`f32::mul_add` with `std`, else `libm::fmaf`; both correctly
/// rounded, as is the M4F's `vfma.f32`).
#[inline]
pub fn fma(a: f32, b: f32, c: f32) -> f32 {
    #[cfg(feature = "std")]
    {
        a.mul_add(b, c)
    }
    #[cfg(not(feature = "std"))]
    {
        libm::fmaf(a, b, c)
    }
}

/// √x, correctly rounded (NaN for x < 0).
#[inline]
pub fn sqrt(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
    {
        m4f::sqrt(x)
    }
    #[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
    {
        libm::sqrtf(x)
    }
}

/// True if every value is finite: Σ 0·xᵢ is ±0 for finite values and NaN as soon as one is NaN
/// or infinite, so the whole check is one multiply–add a value and one comparison, without a
/// branch per value (IEEE arithmetic: the compiler may not fold 0·x).
#[inline]
pub fn all_finite(values: impl IntoIterator<Item = f32>) -> bool {
    values.into_iter().fold(0.0f32, |acc, x| acc + x * 0.0) == 0.0
}

/// Targets with a single-precision FPU that has `vfma` (FPv4-SP and later, hard-float ABI).
#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
mod m4f {
    use core::arch::asm;

    /// √x in one `vsqrt.f32` (s0 saved and restored around it).
    #[inline(always)]
    pub fn sqrt(x: f32) -> f32 {
        let mut bits = x.to_bits();
        // SAFETY: s0 is restored before the block ends; only the declared core register changes.
        unsafe {
            asm!(
                "vpush {{s0}}",
                "vmov s0, {r}",
                "vsqrt.f32 s0, s0",
                "vmov {r}, s0",
                "vpop {{s0}}",
                r = inout(reg) bits,
                options(preserves_flags),
            );
        }
        f32::from_bits(bits)
    }

    /// All `rows` outputs of a 16-input layer.
    ///
    /// # Safety
    /// `w` points at `rows` × 16 readable f32, `b` at `rows` readable f32, `x` at 16 readable
    /// f32, `y` at `rows` writable f32, and `rows > 0`.
    #[inline(always)]
    pub unsafe fn rows16(w: *const f32, b: *const f32, x: *const f32, y: *mut f32, rows: usize) {
        // SAFETY: the caller's contract. s0–s24 are saved on entry and restored on exit, so no
        // FPU register changes across the block; the core registers used are declared.
        unsafe {
            asm!(
                "vpush {{s0-s24}}",
                "vldmia {x}, {{s0-s15}}",
                "2:",
                "vldmia {b}!, {{s24}}",
                "vldmia {w}!, {{s16-s23}}",
                "vfma.f32 s24, s16, s0",
                "vfma.f32 s24, s17, s1",
                "vfma.f32 s24, s18, s2",
                "vfma.f32 s24, s19, s3",
                "vfma.f32 s24, s20, s4",
                "vfma.f32 s24, s21, s5",
                "vfma.f32 s24, s22, s6",
                "vfma.f32 s24, s23, s7",
                "vldmia {w}!, {{s16-s23}}",
                "vfma.f32 s24, s16, s8",
                "vfma.f32 s24, s17, s9",
                "vfma.f32 s24, s18, s10",
                "vfma.f32 s24, s19, s11",
                "vfma.f32 s24, s20, s12",
                "vfma.f32 s24, s21, s13",
                "vfma.f32 s24, s22, s14",
                "vfma.f32 s24, s23, s15",
                "vstmia {y}!, {{s24}}",
                "subs {n}, {n}, #1",
                "bne 2b",
                "vpop {{s0-s24}}",
                w = inout(reg) w => _,
                b = inout(reg) b => _,
                x = in(reg) x,
                y = inout(reg) y => _,
                n = inout(reg) rows => _,
            );
        }
    }

    /// All `rows` outputs of a 9-input layer (the rows of R): as [`rows16`] with 9 weights a
    /// row.
    ///
    /// # Safety
    /// As [`rows16`] with 9 inputs and 9 weights per row.
    #[inline(always)]
    pub unsafe fn rows9(w: *const f32, b: *const f32, x: *const f32, y: *mut f32, rows: usize) {
        // SAFETY: as in `rows16`; s0–s18 are saved and restored.
        unsafe {
            asm!(
                "vpush {{s0-s18}}",
                "vldmia {x}, {{s0-s8}}",
                "2:",
                "vldmia {b}!, {{s18}}",
                "vldmia {w}!, {{s9-s17}}",
                "vfma.f32 s18, s9, s0",
                "vfma.f32 s18, s10, s1",
                "vfma.f32 s18, s11, s2",
                "vfma.f32 s18, s12, s3",
                "vfma.f32 s18, s13, s4",
                "vfma.f32 s18, s14, s5",
                "vfma.f32 s18, s15, s6",
                "vfma.f32 s18, s16, s7",
                "vfma.f32 s18, s17, s8",
                "vstmia {y}!, {{s18}}",
                "subs {n}, {n}, #1",
                "bne 2b",
                "vpop {{s0-s18}}",
                w = inout(reg) w => _,
                b = inout(reg) b => _,
                x = in(reg) x,
                y = inout(reg) y => _,
                n = inout(reg) rows => _,
            );
        }
    }
}

/// y = W x + b with each output one fma chain from its bias, in input order (the order is part
/// of the contract: every target rounds the same way).
#[inline]
pub fn affine<const I: usize, const O: usize>(
    w: &[[f32; I]; O],
    b: &[f32; O],
    x: &[f32; I],
) -> [f32; O] {
    let mut y = [0.0; O];
    #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
    if O > 0 && (I == 16 || I == 9) {
        let (wp, bp, xp, yp) = (
            w.as_ptr().cast::<f32>(),
            b.as_ptr(),
            x.as_ptr(),
            y.as_mut_ptr(),
        );
        // SAFETY: `w` is O contiguous rows of I f32, `b` and `y` hold O, `x` holds I, O > 0.
        unsafe {
            if I == 16 {
                m4f::rows16(wp, bp, xp, yp, O);
            } else {
                m4f::rows9(wp, bp, xp, yp, O);
            }
        }
        return y;
    }
    for ((yo, row), bo) in y.iter_mut().zip(w.iter()).zip(b.iter()) {
        *yo = row
            .iter()
            .zip(x.iter())
            .fold(*bo, |acc, (wi, xi)| fma(*wi, *xi, acc));
    }
    y
}
