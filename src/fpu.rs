//! The FPU instructions stable Rust cannot reach from `core`: fused multiply–add for the dense
//! layers and square root, bit-identical on every target.
//!
//! Each output of [`affine`] is one chain a ← fma(wᵢ, xᵢ, a) from the bias, in input order, each
//! step rounded once (IEEE 754 `fusedMultiplyAdd`); [`affine_tanh`] applies [`tanh`] (Horner
//! chains of fmas too) to each output. On the Cortex-M4F that is `vfma.f32`, in a small assembly
//! loop for the two input widths the model has (9 and 16), two rows a pass: the rows' weights
//! come in with `vldmia`, the inputs stay in registers for the whole layer, and a hidden layer's
//! activation runs in registers before the pair is stored (its constants loaded as the `vfma`
//! addends by one `vldmia`). Stable Rust has no `mul_add` in `core`, and LLVM never fuses on its
//! own. Elsewhere [`fma`] is `f32::mul_add` (with `std`, and the x86-64 FMA instructions when the
//! CPU has them) or `libm::fmaf`. All are correctly rounded, so the firmware and a host build of
//! the same code give the same bits; the processor-in-the-loop test checks it.
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
#[inline(always)]
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

    /// The activation of the value in `$v` (s30 or s31) in place: [`super::tanh`]'s sequence,
    /// with the constants of [`super::TANH_TABLE`] loaded into s16–s26 by one `vldmia` (they are
    /// the addends the `vfma`s accumulate into, so each Horner step is one instruction), x² in
    /// s27. The clamp costs one compare of |x| and a branch unless it clamps. Uses s16–s27.
    macro_rules! tanh_asm {
        ($v:literal) => {
            concat!(
                "vldmia {c}, {{s16-s26}}\n",
                // |x| ≤ c (or NaN, unordered): no clamp, one branch; else x = ±c by its sign.
                "vabs.f32 s27, ",
                $v,
                "\n",
                "vcmp.f32 s27, s16\n",
                "vmrs APSR_nzcv, fpscr\n",
                "ble 5f\n",
                "vcmp.f32 ",
                $v,
                ", #0\n",
                "vmrs APSR_nzcv, fpscr\n",
                "ite gt\n",
                "vmovgt.f32 ",
                $v,
                ", s16\n",
                "vmovle.f32 ",
                $v,
                ", s17\n",
                "5:\n",
                "vmul.f32 s27, ",
                $v,
                ", ",
                $v,
                "\n",
                "vfma.f32 s19, s18, s27\n",
                "vfma.f32 s20, s19, s27\n",
                "vfma.f32 s21, s20, s27\n",
                "vfma.f32 s22, s21, s27\n",
                "vmul.f32 s22, s22, ",
                $v,
                "\n",
                "vfma.f32 s24, s23, s27\n",
                "vfma.f32 s25, s24, s27\n",
                "vfma.f32 s26, s25, s27\n",
                "vdiv.f32 ",
                $v,
                ", s22, s26\n",
            )
        };
    }

    /// Two rows of a 16-input layer into s30 and s31 (inputs in s0–s15, weights through
    /// s16–s23).
    macro_rules! pair16_asm {
        () => {
            concat!(
                "vldmia {b}!, {{s30-s31}}\n",
                "vldmia {w}!, {{s16-s23}}\n",
                "vfma.f32 s30, s16, s0\n",
                "vfma.f32 s30, s17, s1\n",
                "vfma.f32 s30, s18, s2\n",
                "vfma.f32 s30, s19, s3\n",
                "vfma.f32 s30, s20, s4\n",
                "vfma.f32 s30, s21, s5\n",
                "vfma.f32 s30, s22, s6\n",
                "vfma.f32 s30, s23, s7\n",
                "vldmia {w}!, {{s16-s23}}\n",
                "vfma.f32 s30, s16, s8\n",
                "vfma.f32 s30, s17, s9\n",
                "vfma.f32 s30, s18, s10\n",
                "vfma.f32 s30, s19, s11\n",
                "vfma.f32 s30, s20, s12\n",
                "vfma.f32 s30, s21, s13\n",
                "vfma.f32 s30, s22, s14\n",
                "vfma.f32 s30, s23, s15\n",
                "vldmia {w}!, {{s16-s23}}\n",
                "vfma.f32 s31, s16, s0\n",
                "vfma.f32 s31, s17, s1\n",
                "vfma.f32 s31, s18, s2\n",
                "vfma.f32 s31, s19, s3\n",
                "vfma.f32 s31, s20, s4\n",
                "vfma.f32 s31, s21, s5\n",
                "vfma.f32 s31, s22, s6\n",
                "vfma.f32 s31, s23, s7\n",
                "vldmia {w}!, {{s16-s23}}\n",
                "vfma.f32 s31, s16, s8\n",
                "vfma.f32 s31, s17, s9\n",
                "vfma.f32 s31, s18, s10\n",
                "vfma.f32 s31, s19, s11\n",
                "vfma.f32 s31, s20, s12\n",
                "vfma.f32 s31, s21, s13\n",
                "vfma.f32 s31, s22, s14\n",
                "vfma.f32 s31, s23, s15\n",
            )
        };
    }

    /// Two rows of a 9-input layer into s30 and s31 (inputs in s0–s8, weights in s9–s17).
    macro_rules! pair9_asm {
        () => {
            concat!(
                "vldmia {b}!, {{s30-s31}}\n",
                "vldmia {w}!, {{s9-s17}}\n",
                "vfma.f32 s30, s9, s0\n",
                "vfma.f32 s30, s10, s1\n",
                "vfma.f32 s30, s11, s2\n",
                "vfma.f32 s30, s12, s3\n",
                "vfma.f32 s30, s13, s4\n",
                "vfma.f32 s30, s14, s5\n",
                "vfma.f32 s30, s15, s6\n",
                "vfma.f32 s30, s16, s7\n",
                "vfma.f32 s30, s17, s8\n",
                "vldmia {w}!, {{s9-s17}}\n",
                "vfma.f32 s31, s9, s0\n",
                "vfma.f32 s31, s10, s1\n",
                "vfma.f32 s31, s11, s2\n",
                "vfma.f32 s31, s12, s3\n",
                "vfma.f32 s31, s13, s4\n",
                "vfma.f32 s31, s14, s5\n",
                "vfma.f32 s31, s15, s6\n",
                "vfma.f32 s31, s16, s7\n",
                "vfma.f32 s31, s17, s8\n",
            )
        };
    }

    /// A layer kernel: the inputs loaded once (`$load`), then two rows a pass (`$pair`), with
    /// the activation applied to both in registers when the kernel takes the constants `c`.
    /// Every FPU register is saved on entry and restored on exit, so none changes across the
    /// block; the core registers used are declared.
    macro_rules! layer_kernel {
        ($(#[$doc:meta])* $name:ident, $load:literal, $pair:ident, tanh) => {
            $(#[$doc])*
            #[inline(always)]
            pub unsafe fn $name(
                w: *const f32,
                b: *const f32,
                x: *const f32,
                y: *mut f32,
                rows: usize,
                c: *const f32,
            ) {
                // SAFETY: the caller's contract (see the function's documentation).
                unsafe {
                    asm!(
                        "vpush {{s0-s31}}",
                        $load,
                        "2:",
                        $pair!(),
                        tanh_asm!("s30"),
                        tanh_asm!("s31"),
                        "vstmia {y}!, {{s30-s31}}",
                        "subs {n}, {n}, #2",
                        "bne 2b",
                        "vpop {{s0-s31}}",
                        w = inout(reg) w => _,
                        b = inout(reg) b => _,
                        x = in(reg) x,
                        y = inout(reg) y => _,
                        n = inout(reg) rows => _,
                        c = in(reg) c,
                    );
                }
            }
        };
        ($(#[$doc:meta])* $name:ident, $load:literal, $pair:ident) => {
            $(#[$doc])*
            #[inline(always)]
            pub unsafe fn $name(w: *const f32, b: *const f32, x: *const f32, y: *mut f32, rows: usize) {
                // SAFETY: the caller's contract (see the function's documentation).
                unsafe {
                    asm!(
                        "vpush {{s0-s31}}",
                        $load,
                        "2:",
                        $pair!(),
                        "vstmia {y}!, {{s30-s31}}",
                        "subs {n}, {n}, #2",
                        "bne 2b",
                        "vpop {{s0-s31}}",
                        w = inout(reg) w => _,
                        b = inout(reg) b => _,
                        x = in(reg) x,
                        y = inout(reg) y => _,
                        n = inout(reg) rows => _,
                    );
                }
            }
        };
    }

    layer_kernel!(
        /// All `rows` outputs of a 16-input layer, two rows per pass.
        ///
        /// # Safety
        /// `w` points at `rows` × 16 readable f32, `b` at `rows` readable f32, `x` at 16
        /// readable f32, `y` at `rows` writable f32, and `rows` is even and > 0.
        rows16, "vldmia {x}, {{s0-s15}}", pair16_asm
    );
    layer_kernel!(
        /// All `rows` outputs of a 16-input layer through the activation, two rows per pass.
        ///
        /// # Safety
        /// As [`rows16`]; `c` points at the 11 f32 of [`super::TANH_TABLE`].
        rows16_tanh, "vldmia {x}, {{s0-s15}}", pair16_asm, tanh
    );
    layer_kernel!(
        /// All `rows` outputs of a 9-input layer (the rows of R), two rows per pass.
        ///
        /// # Safety
        /// As [`rows16`] with 9 inputs and 9 weights per row.
        rows9, "vldmia {x}, {{s0-s8}}", pair9_asm
    );
    layer_kernel!(
        /// All `rows` outputs of a 9-input layer through the activation, two rows per pass.
        ///
        /// # Safety
        /// As [`rows9`]; `c` points at the 11 f32 of [`super::TANH_TABLE`].
        rows9_tanh, "vldmia {x}, {{s0-s8}}", pair9_asm, tanh
    );

    /// The composite law's six scalar Kalman updates ([`super::kalman_rows`]'s sequence).
    /// Registers: h (then k) s0–s5, z s6, r s7, a s8–s13, P hᵀ s14–s19, s s20, e and ν s21,
    /// 1/s s22, a column of P s24–s29.
    ///
    /// # Safety
    /// `p` points at 36 readable and writable f32 (column-major 6×6), `a` at 6, `h` at 36
    /// readable (six rows of 6), `z` at 6 readable, `r` at 6 readable and writable.
    #[inline(always)]
    pub unsafe fn kalman_rows(p: *mut f32, a: *mut f32, h: *const f32, z: *const f32, r: *mut f32) {
        // SAFETY: the caller's contract; s0–s29 are saved on entry and restored on exit.
        unsafe {
            asm!(
                "vpush {{s0-s29}}",
                "vldmia {a}, {{s8-s13}}",
                "2:",
                "vldmia {h}!, {{s0-s5}}",
                "vldmia {z}!, {{s6}}",
                "vldmia {r}!, {{s7}}",
                // ph = P hᵀ from the upper triangle, column by column (P(j, c) in s24 + j).
                "mov {t}, {p}",
                "vldmia {t}, {{s24}}",
                "vmul.f32 s14, s24, s0",
                "add {t}, {t}, #24",
                "vldmia {t}, {{s24-s25}}",
                "vfma.f32 s14, s24, s1",
                "vmul.f32 s15, s24, s0",
                "vfma.f32 s15, s25, s1",
                "add {t}, {t}, #24",
                "vldmia {t}, {{s24-s26}}",
                "vfma.f32 s14, s24, s2",
                "vmul.f32 s16, s24, s0",
                "vfma.f32 s15, s25, s2",
                "vfma.f32 s16, s25, s1",
                "vfma.f32 s16, s26, s2",
                "add {t}, {t}, #24",
                "vldmia {t}, {{s24-s27}}",
                "vfma.f32 s14, s24, s3",
                "vmul.f32 s17, s24, s0",
                "vfma.f32 s15, s25, s3",
                "vfma.f32 s17, s25, s1",
                "vfma.f32 s16, s26, s3",
                "vfma.f32 s17, s26, s2",
                "vfma.f32 s17, s27, s3",
                "add {t}, {t}, #24",
                "vldmia {t}, {{s24-s28}}",
                "vfma.f32 s14, s24, s4",
                "vmul.f32 s18, s24, s0",
                "vfma.f32 s15, s25, s4",
                "vfma.f32 s18, s25, s1",
                "vfma.f32 s16, s26, s4",
                "vfma.f32 s18, s26, s2",
                "vfma.f32 s17, s27, s4",
                "vfma.f32 s18, s27, s3",
                "vfma.f32 s18, s28, s4",
                "add {t}, {t}, #24",
                "vldmia {t}, {{s24-s29}}",
                "vfma.f32 s14, s24, s5",
                "vmul.f32 s19, s24, s0",
                "vfma.f32 s15, s25, s5",
                "vfma.f32 s19, s25, s1",
                "vfma.f32 s16, s26, s5",
                "vfma.f32 s19, s26, s2",
                "vfma.f32 s17, s27, s5",
                "vfma.f32 s19, s27, s3",
                "vfma.f32 s18, s28, s5",
                "vfma.f32 s19, s28, s4",
                "vfma.f32 s19, s29, s5",
                // s = r + h ph, stored over r; no update unless s > 0 (NaN: no update either).
                "vmov.f32 s20, s7",
                "vfma.f32 s20, s0, s14",
                "vfma.f32 s20, s1, s15",
                "vfma.f32 s20, s2, s16",
                "vfma.f32 s20, s3, s17",
                "vfma.f32 s20, s4, s18",
                "vfma.f32 s20, s5, s19",
                "vstr s20, [{r}, #-4]",
                "vcmp.f32 s20, #0",
                "vmrs APSR_nzcv, fpscr",
                "ble 3f",
                "vmov.f32 s22, #1.0",
                "vdiv.f32 s22, s22, s20",
                // e = z − h a (fused, in index order), ν = e / s, a += ph ν.
                "vmov.f32 s21, s6",
                "vfms.f32 s21, s0, s8",
                "vfms.f32 s21, s1, s9",
                "vfms.f32 s21, s2, s10",
                "vfms.f32 s21, s3, s11",
                "vfms.f32 s21, s4, s12",
                "vfms.f32 s21, s5, s13",
                "vmul.f32 s21, s21, s22",
                "vfma.f32 s8, s14, s21",
                "vfma.f32 s9, s15, s21",
                "vfma.f32 s10, s16, s21",
                "vfma.f32 s11, s17, s21",
                "vfma.f32 s12, s18, s21",
                "vfma.f32 s13, s19, s21",
                // k = ph / s over h; P(j, c) −= k_j ph_c on the upper triangle.
                "vmul.f32 s0, s14, s22",
                "vmul.f32 s1, s15, s22",
                "vmul.f32 s2, s16, s22",
                "vmul.f32 s3, s17, s22",
                "vmul.f32 s4, s18, s22",
                "vmul.f32 s5, s19, s22",
                "mov {t}, {p}",
                "vldmia {t}, {{s24}}",
                "vfms.f32 s24, s0, s14",
                "vstmia {t}, {{s24}}",
                "add {t}, {t}, #24",
                "vldmia {t}, {{s24-s25}}",
                "vfms.f32 s24, s0, s15",
                "vfms.f32 s25, s1, s15",
                "vstmia {t}, {{s24-s25}}",
                "add {t}, {t}, #24",
                "vldmia {t}, {{s24-s26}}",
                "vfms.f32 s24, s0, s16",
                "vfms.f32 s25, s1, s16",
                "vfms.f32 s26, s2, s16",
                "vstmia {t}, {{s24-s26}}",
                "add {t}, {t}, #24",
                "vldmia {t}, {{s24-s27}}",
                "vfms.f32 s24, s0, s17",
                "vfms.f32 s25, s1, s17",
                "vfms.f32 s26, s2, s17",
                "vfms.f32 s27, s3, s17",
                "vstmia {t}, {{s24-s27}}",
                "add {t}, {t}, #24",
                "vldmia {t}, {{s24-s28}}",
                "vfms.f32 s24, s0, s18",
                "vfms.f32 s25, s1, s18",
                "vfms.f32 s26, s2, s18",
                "vfms.f32 s27, s3, s18",
                "vfms.f32 s28, s4, s18",
                "vstmia {t}, {{s24-s28}}",
                "add {t}, {t}, #24",
                "vldmia {t}, {{s24-s29}}",
                "vfms.f32 s24, s0, s19",
                "vfms.f32 s25, s1, s19",
                "vfms.f32 s26, s2, s19",
                "vfms.f32 s27, s3, s19",
                "vfms.f32 s28, s4, s19",
                "vfms.f32 s29, s5, s19",
                "vstmia {t}, {{s24-s29}}",
                "3:",
                "subs {n}, {n}, #1",
                "bne 2b",
                "vstmia {a}, {{s8-s13}}",
                "vpop {{s0-s29}}",
                p = in(reg) p,
                a = in(reg) a,
                h = inout(reg) h => _,
                z = inout(reg) z => _,
                r = inout(reg) r => _,
                t = out(reg) _,
                n = inout(reg) 6usize => _,
            );
        }
    }

    /// [`super::sum_squares_split`]: the 36 features in two loads of three columns, the force
    /// rows' squares into s18 and the torque rows' into s19, column by column.
    ///
    /// # Safety
    /// `w` points at 36 readable f32 (column-major 6×6).
    #[inline(always)]
    pub unsafe fn sum_squares_split(w: *const f32) -> (f32, f32) {
        let (f, t): (u32, u32);
        // SAFETY: the caller's contract; s0–s19 are saved on entry and restored on exit.
        unsafe {
            asm!(
                "vpush {{s0-s19}}",
                "vldmia {w}!, {{s0-s17}}",
                "vmul.f32 s18, s0, s0",
                "vmul.f32 s19, s3, s3",
                "vfma.f32 s18, s1, s1",
                "vfma.f32 s19, s4, s4",
                "vfma.f32 s18, s2, s2",
                "vfma.f32 s19, s5, s5",
                "vfma.f32 s18, s6, s6",
                "vfma.f32 s19, s9, s9",
                "vfma.f32 s18, s7, s7",
                "vfma.f32 s19, s10, s10",
                "vfma.f32 s18, s8, s8",
                "vfma.f32 s19, s11, s11",
                "vfma.f32 s18, s12, s12",
                "vfma.f32 s19, s15, s15",
                "vfma.f32 s18, s13, s13",
                "vfma.f32 s19, s16, s16",
                "vfma.f32 s18, s14, s14",
                "vfma.f32 s19, s17, s17",
                "vldmia {w}, {{s0-s17}}",
                "vfma.f32 s18, s0, s0",
                "vfma.f32 s19, s3, s3",
                "vfma.f32 s18, s1, s1",
                "vfma.f32 s19, s4, s4",
                "vfma.f32 s18, s2, s2",
                "vfma.f32 s19, s5, s5",
                "vfma.f32 s18, s6, s6",
                "vfma.f32 s19, s9, s9",
                "vfma.f32 s18, s7, s7",
                "vfma.f32 s19, s10, s10",
                "vfma.f32 s18, s8, s8",
                "vfma.f32 s19, s11, s11",
                "vfma.f32 s18, s12, s12",
                "vfma.f32 s19, s15, s15",
                "vfma.f32 s18, s13, s13",
                "vfma.f32 s19, s16, s16",
                "vfma.f32 s18, s14, s14",
                "vfma.f32 s19, s17, s17",
                "vmov {f}, s18",
                "vmov {t}, s19",
                "vpop {{s0-s19}}",
                w = inout(reg) w => _,
                f = out(reg) f,
                t = out(reg) t,
                options(readonly, preserves_flags),
            );
        }
        (f32::from_bits(f), f32::from_bits(t))
    }

    /// [`super::transpose_mul`]: s in s0–s5, a column of W in s6–s11 per output (s12), two
    /// columns a pass.
    ///
    /// # Safety
    /// `w` points at 36 readable f32 (column-major 6×6), `s` at 6 readable, `y` at 6 writable.
    #[inline(always)]
    pub unsafe fn transpose_mul(w: *const f32, s: *const f32, y: *mut f32) {
        // SAFETY: the caller's contract; s0–s18 are saved on entry and restored on exit.
        unsafe {
            asm!(
                "vpush {{s0-s18}}",
                "vldmia {s}, {{s0-s5}}",
                "movs {s}, #3",
                "2:",
                "vldmia {w}!, {{s6-s11}}",
                "vmul.f32 s12, s6, s0",
                "vfma.f32 s12, s7, s1",
                "vfma.f32 s12, s8, s2",
                "vfma.f32 s12, s9, s3",
                "vfma.f32 s12, s10, s4",
                "vfma.f32 s12, s11, s5",
                "vldmia {w}!, {{s6-s11}}",
                "vmul.f32 s13, s6, s0",
                "vfma.f32 s13, s7, s1",
                "vfma.f32 s13, s8, s2",
                "vfma.f32 s13, s9, s3",
                "vfma.f32 s13, s10, s4",
                "vfma.f32 s13, s11, s5",
                "vstmia {y}!, {{s12-s13}}",
                "subs {s}, {s}, #1",
                "bne 2b",
                "vpop {{s0-s18}}",
                w = inout(reg) w => _,
                s = inout(reg) s => _,
                y = inout(reg) y => _,
            );
        }
    }

    /// One row of [`filter_rows`]: h ← fma(W, g, h β) for the row's six features (W's row read
    /// with a stride of one column, 24 bytes), z_f ← fma(d, g, z_f β), then
    /// ε = z_f − h₀a₀ − … − h₅a₅ (each − one `vfms`). Registers: a s0–s5, h s6–s11, W s12–s17,
    /// g s18, β s19, z_f s20, d s21, ε s22.
    macro_rules! filter_row_asm {
        () => {
            concat!(
                "vldmia {h}, {{s6-s11}}\n",
                "vldr s12, [{w}]\n",
                "vldr s13, [{w}, #24]\n",
                "vldr s14, [{w}, #48]\n",
                "vldr s15, [{w}, #72]\n",
                "vldr s16, [{w}, #96]\n",
                "vldr s17, [{w}, #120]\n",
                "adds {w}, {w}, #4\n",
                "vmul.f32 s6, s6, s19\n",
                "vmul.f32 s7, s7, s19\n",
                "vmul.f32 s8, s8, s19\n",
                "vmul.f32 s9, s9, s19\n",
                "vmul.f32 s10, s10, s19\n",
                "vmul.f32 s11, s11, s19\n",
                "vfma.f32 s6, s12, s18\n",
                "vfma.f32 s7, s13, s18\n",
                "vfma.f32 s8, s14, s18\n",
                "vfma.f32 s9, s15, s18\n",
                "vfma.f32 s10, s16, s18\n",
                "vfma.f32 s11, s17, s18\n",
                "vstmia {h}!, {{s6-s11}}\n",
                "vldr s20, [{z}]\n",
                "vldmia {d}!, {{s21}}\n",
                "vmul.f32 s20, s20, s19\n",
                "vfma.f32 s20, s21, s18\n",
                "vstmia {z}!, {{s20}}\n",
                "vmov.f32 s22, s20\n",
                "vfms.f32 s22, s6, s0\n",
                "vfms.f32 s22, s7, s1\n",
                "vfms.f32 s22, s8, s2\n",
                "vfms.f32 s22, s9, s3\n",
                "vfms.f32 s22, s10, s4\n",
                "vfms.f32 s22, s11, s5\n",
                "vstmia {e}!, {{s22}}\n",
            )
        };
    }

    /// The composite law's low-pass of the scaled features and of the measured force, and its
    /// prediction error ([`super::filter_rows`]'s sequence): three rows on the force block's
    /// (g, β), three on the torque block's.
    ///
    /// # Safety
    /// `w` points at 36 readable f32 (column-major 6×6), `h` at 36 readable and writable
    /// (row-major 6×6), `z` at 6 readable and writable, `d`, `a` at 6 readable, `c` at 4
    /// readable, `e` at 6 writable.
    #[inline(always)]
    pub unsafe fn filter_rows(
        w: *const f32,
        h: *mut f32,
        z: *mut f32,
        d: *const f32,
        a: *const f32,
        c: *const f32,
        e: *mut f32,
    ) {
        // SAFETY: the caller's contract; s0–s22 are saved on entry and restored on exit.
        unsafe {
            asm!(
                "vpush {{s0-s22}}",
                "vldmia {a}, {{s0-s5}}",
                "movs {a}, #2",
                "2:",
                "vldmia {c}!, {{s18-s19}}",
                filter_row_asm!(),
                filter_row_asm!(),
                filter_row_asm!(),
                "subs {a}, {a}, #1",
                "bne 2b",
                "vpop {{s0-s22}}",
                w = inout(reg) w => _,
                h = inout(reg) h => _,
                z = inout(reg) z => _,
                d = inout(reg) d => _,
                a = inout(reg) a => _,
                c = inout(reg) c => _,
                e = inout(reg) e => _,
            );
        }
    }
}

/// |x| beyond which [`tanh`]'s rational form is clamped (its own value there is within its
/// bound of 1).
const TANH_CLAMP: f32 = 6.9;

/// The numerator's coefficients A₀…A₄ of [`tanh`] (in x², times x).
const TANH_A: [f32; 5] = [
    1.0,
    0.129_138_51,
    2.908_879_7e-3,
    8.925_403e-6,
    -9.866_396e-9,
];
/// The denominator's coefficients B₀…B₃ of [`tanh`] (in x²).
const TANH_B: [f32; 4] = [1.0, 0.462_471_84, 2.373_285_6e-2, 2.251_884_4e-4];

/// The M4F kernels' constants in the order they are loaded into s16–s26: the clamp ±c, then A₄
/// (the first multiplier) and A₃…A₀ (the numerator's addends), then B₃ and B₂…B₀.
#[cfg_attr(
    not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")),
    allow(dead_code)
)]
static TANH_TABLE: [f32; 11] = [
    TANH_CLAMP,
    -TANH_CLAMP,
    TANH_A[4],
    TANH_A[3],
    TANH_A[2],
    TANH_A[1],
    TANH_A[0],
    TANH_B[3],
    TANH_B[2],
    TANH_B[1],
    TANH_B[0],
];

/// The hidden-layer activation, tanh, as a 9/6 odd/even rational function fitted for this
/// project (iteratively reweighted least squares toward minimax on [0, 6.9]): |error| < 5e-6
/// against the exact tanh for every f32 input (`tests/nn.rs` checks it on a dense grid over
/// [−10, 10]). Both polynomials are Horner chains of fused
/// multiply–adds, so on the M4F each step is one `vfma` into a constant loaded as its addend
/// ([`affine_tanh`]'s kernels), and every target rounds the same way. The host trains with the
/// exact tanh; the difference is far below the parity tolerance of the core/host model tests
/// (1e-4 relative).
#[inline(always)]
pub fn tanh(x: f32) -> f32 {
    // Constant bounds: clamp's bound check folds away at compile time. NaN stays NaN.
    let x = x.clamp(-TANH_CLAMP, TANH_CLAMP);
    let x2 = x * x;
    // Horner from the highest coefficient (constant indices: checked at compile time).
    let p = TANH_A[..4]
        .iter()
        .rev()
        .fold(TANH_A[4], |acc, c| fma(acc, x2, *c))
        * x;
    let q = TANH_B[..3]
        .iter()
        .rev()
        .fold(TANH_B[3], |acc, c| fma(acc, x2, *c));
    // q ≥ 1 for every x (all of B is positive): the division is always defined.
    p / q
}

/// The portable dense layer, through [`tanh`] when `ACT`: the outputs' chains interleaved input
/// by input (each output still one chain from its bias in input order, so the same bits as row
/// by row), which lets a host core overlap the independent chains.
#[inline(always)]
fn layer_portable<const I: usize, const O: usize, const ACT: bool>(
    w: &[[f32; I]; O],
    b: &[f32; O],
    x: &[f32; I],
) -> [f32; O] {
    let mut y = *b;
    for (i, xi) in x.iter().enumerate() {
        for (yo, row) in y.iter_mut().zip(w.iter()) {
            if let Some(wi) = row.get(i) {
                *yo = fma(*wi, *xi, *yo);
            }
        }
    }
    if ACT {
        for v in y.iter_mut() {
            *v = tanh(*v);
        }
    }
    y
}

/// Whether the M4F kernels take a layer of this shape: 9 or 16 inputs (the model's widths) and
/// an even, non-zero number of outputs (they compute two rows a pass).
#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
const fn m4f_shape(i: usize, o: usize) -> bool {
    o > 0 && o.is_multiple_of(2) && (i == 16 || i == 9)
}

/// y = W x + b with each output one fma chain from its bias, in input order (the order is part
/// of the contract: every target rounds the same way).
#[inline]
pub fn affine<const I: usize, const O: usize>(
    w: &[[f32; I]; O],
    b: &[f32; O],
    x: &[f32; I],
) -> [f32; O] {
    layer::<I, O, false>(w, b, x)
}

/// [`affine`] written into `y`: on the M4F the kernel stores straight into it, with no
/// temporary on the stack.
#[inline]
pub fn affine_into<const I: usize, const O: usize>(
    w: &[[f32; I]; O],
    b: &[f32; O],
    x: &[f32; I],
    y: &mut [f32; O],
) {
    #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
    if m4f_shape(I, O) {
        // SAFETY: `y` holds O f32 and the shape is one the kernels take.
        unsafe { m4f_layer::<I, O, false>(w, b, x, y.as_mut_ptr()) };
        return;
    }
    *y = layer::<I, O, false>(w, b, x);
}

/// tanh(W x + b), elementwise: [`affine`] then [`tanh`], the same bits; on the M4F one kernel
/// per layer with the activation applied in registers.
#[inline]
pub fn affine_tanh<const I: usize, const O: usize>(
    w: &[[f32; I]; O],
    b: &[f32; O],
    x: &[f32; I],
) -> [f32; O] {
    layer::<I, O, true>(w, b, x)
}

/// [`affine`] (`ACT` false) or [`affine_tanh`] (`ACT` true) on the fastest path the target has:
/// the M4F kernels, the host's FMA instructions, or the portable loop; the same bits on each.
#[inline(always)]
fn layer<const I: usize, const O: usize, const ACT: bool>(
    w: &[[f32; I]; O],
    b: &[f32; O],
    x: &[f32; I],
) -> [f32; O] {
    #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
    if m4f_shape(I, O) {
        let mut y = core::mem::MaybeUninit::<[f32; O]>::uninit();
        // SAFETY: `y` holds O f32 and the shape is one the kernels take; the kernel writes all
        // O outputs, so `y` is initialized after it.
        unsafe {
            m4f_layer::<I, O, ACT>(w, b, x, y.as_mut_ptr().cast::<f32>());
            return y.assume_init();
        }
    }
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    if std::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has the FMA extension (checked just above; the check is cached).
        return unsafe { layer_fma::<I, O, ACT>(w, b, x) };
    }
    layer_portable::<I, O, ACT>(w, b, x)
}

/// One layer on the M4F kernels (`ACT`: with tanh), written to `y`.
///
/// # Safety
/// `y` is valid for writing O f32, and `m4f_shape(I, O)` holds.
#[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
#[inline(always)]
unsafe fn m4f_layer<const I: usize, const O: usize, const ACT: bool>(
    w: &[[f32; I]; O],
    b: &[f32; O],
    x: &[f32; I],
    y: *mut f32,
) {
    let (wp, bp, xp) = (w.as_ptr().cast::<f32>(), b.as_ptr(), x.as_ptr());
    // SAFETY: `w` is O contiguous rows of I f32, `b` holds O, `x` holds I, O is even and > 0
    // (m4f_shape), the table holds the 11 constants; `y` by the caller's contract.
    unsafe {
        match (ACT, I == 16) {
            (true, true) => m4f::rows16_tanh(wp, bp, xp, y, O, TANH_TABLE.as_ptr()),
            (true, false) => m4f::rows9_tanh(wp, bp, xp, y, O, TANH_TABLE.as_ptr()),
            (false, true) => m4f::rows16(wp, bp, xp, y, O),
            (false, false) => m4f::rows9(wp, bp, xp, y, O),
        }
    }
}

/// The host's dense layers with the x86-64 FMA extension (`vfmadd`), picked at run time: the
/// portable code calls the C library's `fmaf` once per multiply–add (an x86-64 build without
/// `-C target-feature=+fma` cannot inline it), some 3 ns each, about 3,000 a step. The same
/// chains in the same order, each step one correctly rounded fma: the same bits (tests/fpu.rs
/// checks them against the scalar chain).
///
/// # Safety
/// The CPU must have the FMA extension.
#[cfg(all(feature = "std", target_arch = "x86_64"))]
#[target_feature(enable = "fma")]
unsafe fn layer_fma<const I: usize, const O: usize, const ACT: bool>(
    w: &[[f32; I]; O],
    b: &[f32; O],
    x: &[f32; I],
) -> [f32; O] {
    layer_portable::<I, O, ACT>(w, b, x)
}

/// The squared Frobenius norms of the force rows (0–2) and of the torque rows (3–5) of a
/// column-major 6×6 `w` (`w[c][r]` is W(r, c)): each one fma chain from zero, column by column,
/// rows in order. On the M4F two loads and 36 `vfma`s; the same bits everywhere.
#[inline]
pub fn sum_squares_split(w: &[[f32; 6]; 6]) -> (f32, f32) {
    #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
    {
        // SAFETY: `w` covers 36 f32.
        unsafe { m4f::sum_squares_split(w.as_ptr().cast::<f32>()) }
    }
    #[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
    {
        let (mut force, mut torque) = (0.0f32, 0.0f32);
        for &[f0, f1, f2, t0, t1, t2] in w {
            for (f, t) in [(f0, t0), (f1, t1), (f2, t2)] {
                force = fma(f, f, force);
                torque = fma(t, t, torque);
            }
        }
        (force, torque)
    }
}

/// Wᵀ s for a column-major 6×6 `w` (`w[c][r]` is W(r, c)): output c is one fma chain from zero
/// over the rows in order. On the M4F one load of a column and six `vfma`s per output; the same
/// bits everywhere.
#[inline]
pub fn transpose_mul(w: &[[f32; 6]; 6], s: &[f32; 6]) -> [f32; 6] {
    let mut y = [0.0f32; 6];
    #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
    {
        // SAFETY: `w` covers 36 f32, `s` and `y` 6 each.
        unsafe { m4f::transpose_mul(w.as_ptr().cast::<f32>(), s.as_ptr(), y.as_mut_ptr()) };
    }
    #[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
    for (yc, col) in y.iter_mut().zip(w.iter()) {
        *yc = col
            .iter()
            .zip(s.iter())
            .fold(0.0f32, |acc, (x, v)| fma(*x, *v, acc));
    }
    y
}

/// The composite law's filters and prediction error (`adapt.rs`), in one pass over the rows:
/// for row r of the features `w` (column-major: `w[c][r]` is W(r, c)), with (g, β) =
/// (`c[0]`, `c[1]`) for the force rows 0–2 and (`c[2]`, `c[3]`) for the torque rows 3–5:
/// - `h[r][c] ← fma(W(r, c), g, h[r][c] β)` (the low-pass h + (g/α W − h) α with g = sα,
///   β = 1 − α, written so that each entry costs a product and one fma);
/// - `z[r] ← fma(d[r], g, z[r] β)`;
/// - `e[r] = z[r] − h[r][0] a₀ − … − h[r][5] a₅`, each − one fma, in index order (the same
///   sequence as [`kalman_rows`]' innovation, so its row 0's is `e[0]`).
///
/// On the M4F one assembly loop; the same sequence, and so the same bits, everywhere.
#[inline]
pub fn filter_rows(
    w: &[[f32; 6]; 6],
    h: &mut [[f32; 6]; 6],
    z: &mut [f32; 6],
    d: &[f32; 6],
    a: &[f32; 6],
    c: &[f32; 4],
    e: &mut [f32; 6],
) {
    #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
    {
        // SAFETY: every pointer covers the array it comes from, with the sizes the kernel needs.
        unsafe {
            m4f::filter_rows(
                w.as_ptr().cast::<f32>(),
                h.as_mut_ptr().cast::<f32>(),
                z.as_mut_ptr(),
                d.as_ptr(),
                a.as_ptr(),
                c.as_ptr(),
                e.as_mut_ptr(),
            );
        }
    }
    #[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
    {
        let [gf, bf, gt, bt] = *c;
        let rows = h
            .iter_mut()
            .zip(z.iter_mut())
            .zip(d.iter().zip(e.iter_mut()));
        for (r, ((hr, zr), (dr, er))) in rows.enumerate() {
            let (g, b) = if r < 3 { (gf, bf) } else { (gt, bt) };
            for (hv, col) in hr.iter_mut().zip(w.iter()) {
                let wv = col.get(r).copied().unwrap_or(0.0);
                *hv = fma(wv, g, *hv * b);
            }
            *zr = fma(*dr, g, *zr * b);
            *er = hr
                .iter()
                .zip(a.iter())
                .fold(*zr, |acc, (x, y)| fma(-x, *y, acc));
        }
    }
}

/// The composite law's measurement update (`adapt.rs`): the six rows of a diagonal-R
/// measurement as six scalar Kalman updates in turn, on the upper triangle of a symmetric,
/// column-major P (`p[c][j]` is P(j, c), j ≤ c; the lower triangle is neither read nor
/// written). For each row hᵢ with zᵢ and rᵢ:
/// - P hᵀ column by column: for column c, ph₀ += P(0,c) h_c and ph_c = P(0,c) h₀ (a product),
///   then for 0 < j < c: ph_j += P(j,c) h_c and ph_c += P(j,c) h_j, then ph_c += P(c,c) h_c
///   (every += one fma);
/// - s = rᵢ + Σ h_j ph_j (fmas in j order), written over rᵢ; no update unless s > 0;
/// - e = zᵢ − h₀a₀ − h₁a₁ − … (each − one fma, in order), ν = e · (1/s),
///   a_j ← fma(ph_j, ν, a_j);
/// - k_j = ph_j · (1/s), P(j,c) ← fma(−k_j, ph_c, P(j,c)) for j ≤ c.
///
/// On the M4F one assembly loop, about half the instructions of the compiler's code for the same
/// sequence (docs/performance.md, "The composite law's step: three implementations"); the same
/// sequence, and so the same bits, everywhere.
#[inline]
pub fn kalman_rows(
    p: &mut [[f32; 6]; 6],
    a: &mut [f32; 6],
    h: &[[f32; 6]; 6],
    z: &[f32; 6],
    r: &mut [f32; 6],
) {
    #[cfg(all(target_arch = "arm", target_os = "none", target_abi = "eabihf"))]
    {
        // SAFETY: every pointer covers the array it comes from, with the sizes the kernel needs.
        unsafe {
            m4f::kalman_rows(
                p.as_mut_ptr().cast::<f32>(),
                a.as_mut_ptr(),
                h.as_ptr().cast::<f32>(),
                z.as_ptr(),
                r.as_mut_ptr(),
            );
        }
    }
    #[cfg(not(all(target_arch = "arm", target_os = "none", target_abi = "eabihf")))]
    for ((hi, zi), ri) in h.iter().zip(z.iter()).zip(r.iter_mut()) {
        let mut ph = [0.0f32; 6];
        for (c, (col, hc)) in p.iter().zip(hi.iter()).enumerate() {
            for (j, (pjc, hj)) in col.iter().zip(hi.iter()).enumerate().take(c + 1) {
                if j == c {
                    if let Some(v) = ph.get_mut(c) {
                        *v = if c == 0 { pjc * hc } else { fma(*pjc, *hc, *v) };
                    }
                } else {
                    if let Some(v) = ph.get_mut(j) {
                        *v = fma(*pjc, *hc, *v);
                    }
                    if let Some(v) = ph.get_mut(c) {
                        *v = if j == 0 { pjc * hj } else { fma(*pjc, *hj, *v) };
                    }
                }
            }
        }
        let s = hi
            .iter()
            .zip(ph.iter())
            .fold(*ri, |acc, (x, y)| fma(*x, *y, acc));
        *ri = s;
        // Not s > 0 (NaN included): no update, as the kernel's `ble`.
        if s.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
            continue;
        }
        let inv = 1.0 / s;
        let e = hi
            .iter()
            .zip(a.iter())
            .fold(*zi, |acc, (x, y)| fma(-x, *y, acc));
        let nu = e * inv;
        for (aj, phj) in a.iter_mut().zip(ph.iter()) {
            *aj = fma(*phj, nu, *aj);
        }
        let k = ph.map(|v| v * inv);
        for (c, (col, phc)) in p.iter_mut().zip(ph.iter()).enumerate() {
            for (v, kj) in col.iter_mut().zip(k.iter()).take(c + 1) {
                *v = fma(-kj, *phc, *v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> [[f32; 6]; 6] {
        core::array::from_fn(|c| core::array::from_fn(|r| 0.1 * (c as f32 + 1.0) - 0.07 * r as f32))
    }

    /// The kernels' sequences agree with the plain (unfused) formulas to rounding.
    #[test]
    fn feature_kernels_match_the_plain_formulas() {
        let w = sample();
        let (f, t) = sum_squares_split(&w);
        let f_ref: f32 = w.iter().flat_map(|c| c[..3].iter()).map(|x| x * x).sum();
        let t_ref: f32 = w.iter().flat_map(|c| c[3..].iter()).map(|x| x * x).sum();
        assert!((f - f_ref).abs() <= 1e-5 * f_ref && (t - t_ref).abs() <= 1e-5 * t_ref);

        let s = [0.3, -1.2, 0.5, 2.0, -0.7, 0.1];
        let y = transpose_mul(&w, &s);
        for (yc, col) in y.iter().zip(w.iter()) {
            let want: f32 = col.iter().zip(s.iter()).map(|(a, b)| a * b).sum();
            assert!((yc - want).abs() <= 1e-5, "{yc} vs {want}");
        }

        // One filter step against h + (s W − h) α, z_f + (s d − z_f) α and z_f − h a.
        let (alpha_f, alpha_t, sf, st) = (0.2f32, 0.3f32, 37.0f32, 1000.0f32);
        let c = [sf * alpha_f, 1.0 - alpha_f, st * alpha_t, 1.0 - alpha_t];
        let h0: [[f32; 6]; 6] =
            core::array::from_fn(|r| core::array::from_fn(|k| 0.5 - 0.1 * (r + k) as f32));
        let z0 = [1.0, -2.0, 0.5, 3.0, -1.0, 0.25];
        let d = [0.01, 0.02, -0.03, 1e-3, -2e-3, 4e-4];
        let a = [0.5, -0.25, 1.0, 2.0, -1.5, 0.75];
        let (mut h, mut z, mut e) = (h0, z0, [0.0f32; 6]);
        filter_rows(&w, &mut h, &mut z, &d, &a, &c, &mut e);
        for r in 0..6 {
            let (al, sc) = if r < 3 { (alpha_f, sf) } else { (alpha_t, st) };
            let zr = z0[r] + (sc * d[r] - z0[r]) * al;
            assert!((z[r] - zr).abs() <= 1e-5 * (1.0 + zr.abs()), "z[{r}]");
            let mut er = z[r];
            for k in 0..6 {
                let hr = h0[r][k] + (sc * w[k][r] - h0[r][k]) * al;
                assert!(
                    (h[r][k] - hr).abs() <= 1e-5 * (1.0 + hr.abs()),
                    "h[{r}][{k}]"
                );
                er -= h[r][k] * a[k];
            }
            assert!((e[r] - er).abs() <= 1e-4 * (1.0 + er.abs()), "e[{r}]");
        }
    }
}
