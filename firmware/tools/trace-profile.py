#!/usr/bin/env python3
"""Profile of the control step from QEMU's instruction trace, with an estimate of Cortex-M4F cycles.

    firmware/tools/trace-profile.py ELF [--by func|func2|symbol|line:FILE[:FUNC,...]] [--top K] [--classes] [--summary]
    firmware/tools/trace-profile.py --self-test

ELF is a `bench` image (`cargo build --release --bin qemu --features bench[,composite]`, best
built with HAMFLIGHT_BENCH_STEPS=200: the trace of the full 2,000-step bench is ~40 M lines).
`report.sh` calls it with `--summary` to print the estimated cycles next to the instructions.

How it works:
- QEMU runs the image with `-singlestep -d exec,nochain`: one log line per executed instruction
  (its PC), streamed through a pipe and never stored.
- The step window is the one `report.sh` measures: from the first instruction of
  `CostCounter::now` to the first of `CostCounter::since` in `ControlLoop::tick` (found in the
  DWARF inline chains by `arm-none-eabi-addr2line -i`); every instruction in between counts,
  including called functions.
- Each executed instruction is looked up in `arm-none-eabi-objdump -d` and given cycles from the
  timing table below, knowing the instruction before it (load pipelining, address stalls) and the
  one after it (a branch was taken iff the next PC is not the fall-through).
- Parts: the inline chain of each PC, from the outermost frame inwards; `func` names the frame
  just below `FlightController::step_measured` (or the outermost frame of a function that was not
  inlined), `func2` two levels, `line:FILE` the innermost frame in FILE with its line
  (`line:FILE:F1,F2`: the innermost frame of the functions F1, F2 in FILE, so their helpers
  count at the call site).

Timing table (cycles, zero wait states). Sources: Arm Cortex-M4 Technical Reference Manual r0p1
(DDI 0439B), Table 3-1 "Cortex-M4 instruction set summary" and Section 3.3.2 "Load/store
timings"; Table 7-1 "FPU instruction set" (FPv4-SP), which TI's SWCU192 (CC13x2/CC26x2 TRM,
Tables 3-25 and 3-27) reproduces. P = pipeline refill after a taken branch, 1 to 3 cycles
("depending on the alignment and width of the target instruction, and whether the processor
manages to speculate the address early"); N = registers transferred.

  data processing, MOV/MOVW/MOVT, shifts, bit fields, CMP/TST, MUL/MLA/MLS, (S|U)MULL/MLAL,
    the DSP multiplies, SSAT/USAT, REV, extends                   1   (+P if it writes PC)
  SDIV/UDIV                                                       2 to 12 (early termination)
  LDR/LDRB/LDRH/LDRSB/LDRSH, STR/STRB/STRH with register offset   2
  STR/STRB/STRH with immediate offset                             1   ("always one cycle")
  LDR/STR after a single LDR whose result is not in its address   -1  (pipelined)
  LDR/STR whose address uses the result of the previous
    data-processing instruction                                   +1  (no forwarding path)
  LDRD/STRD                                                       3   (never pipelined)
  LDM/STM/PUSH/POP                                                1+N (+P if PC is loaded)
  LDR PC                                                          2+P
  B/BL/BX/BLX/CBZ/CBNZ taken                                      1+P
  conditional branch not taken, CBZ/CBNZ not taken                1
  TBB/TBH                                                         2+P
  IT                                                              0 after a 16-bit instruction
                                                                  (folded), else 1
  VADD/VSUB/VMUL/VNMUL/VABS/VNEG/VCMP(E)/VCVT/VMOV imm or S<-S    1
  VMOV between a core register and an S register, or two/D        2   (1 in `low`, see below)
  VMRS/VMSR                                                       1
  VMLA/VMLS/VNMLA/VNMLS, VFMA/VFMS/VFNMA/VFNMS                    3
  VDIV, VSQRT                                                     14
  VLDR.32, VSTR.32                                                2
  VLDR.64, VSTR.64                                                3
  VLDM/VSTM/VPUSH/VPOP of N single registers                      1+N

Three estimates bound what the table leaves open: `low` (P = 1, every load/store pipelined,
every IT folded, divides 2), `mid` (P = 2, the rules above, divides 7) and `high` (P = 3, no
pipelining, literal-pool loads +1 for fetch contention, divides 12). Not modelled: flash wait
states (STM32F405 at 168 MHz: 5, hidden by the ART accelerator's 1 KiB instruction cache and
prefetch for loops, not for long straight-line code), FPU result hazards, bus contention,
interrupts. The Crazyflie app's DWT `cycles` log is the real figure.

`--self-test` checks the model against the timing examples the TRM publishes for load/store
pairs (Section 3.3.2: "LDR R0,[R1,R2]; STR R0,[R3,#20] - normally three cycles total", ...).

Checked against a published measurement: the Cortex-M4 instruction-timing compendium
(compendium.i-0.nl, "FPU registers", measured with the DWT counter on a Cortex-M4F) finds that
"moving between a CPU register and an FPU register always takes one cycle" (`vmov s0, r0;
vmov s1, r1` two cycles), where Table 7-1 gives 2 for one float to or from a core register. The
table keeps the TRM's 2 in `mid` and `high` and takes the measured 1 in `low`; the step moves
about 50 (default build) to 70 (composite law) values between the register files, so the two
readings differ by that many cycles.
"""
import argparse
import collections
import os
import re
import subprocess
import sys

CONDS = {"eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt",
         "gt", "le", "al"}

# Base mnemonics (without condition codes, .w/.n, or the S flag) by class.
LOADS = {"ldr", "ldrb", "ldrh", "ldrsb", "ldrsh", "ldrt", "ldrbt", "ldrht", "ldrex", "ldrexb",
         "ldrexh"}
STORES = {"str", "strb", "strh", "strt", "strbt", "strht", "strex", "strexb", "strexh"}
MULTI = {"ldm", "ldmia", "ldmfd", "ldmdb", "ldmea", "stm", "stmia", "stmea", "stmdb", "stmfd",
         "push", "pop"}
BRANCH = {"b", "bl", "bx", "blx", "cbz", "cbnz"}
TABLE = {"tbb", "tbh"}
DIV = {"sdiv", "udiv"}
FP1 = {"vadd", "vsub", "vmul", "vnmul", "vabs", "vneg", "vcmp", "vcmpe", "vcvt", "vcvtr",
       "vmrs", "vmsr", "vsel", "vmaxnm", "vminnm"}
FP3 = {"vmla", "vmls", "vnmla", "vnmls", "vfma", "vfms", "vfnma", "vfnms"}
FP14 = {"vdiv", "vsqrt"}
FPLS = {"vldr", "vstr"}
FPMULTI = {"vldm", "vldmia", "vldmdb", "vstm", "vstmia", "vstmdb", "vpush", "vpop"}
# Everything else that is 1 cycle; `s` = may take the S suffix.
DP_S = {"add", "adc", "sub", "sbc", "rsb", "and", "orr", "orn", "eor", "bic", "mov", "mvn",
        "lsl", "lsr", "asr", "ror", "rrx", "mul", "mla", "smull", "umull", "smlal", "umlal",
        "neg"}
DP = {"movw", "movt", "cmp", "cmn", "tst", "teq", "mls", "bfi", "bfc", "ubfx", "sbfx", "uxtb",
      "uxth", "sxtb", "sxth", "uxtab", "uxtah", "sxtab", "sxtah", "rev", "rev16", "revsh",
      "rbit", "clz", "ssat", "usat", "adr", "addw", "subw", "pkhbt", "pkhtb", "smulbb",
      "smulbt", "smultb", "smultt", "smlabb", "smlabt", "smlatb", "smlatt", "smulwb", "smulwt",
      "smlawb", "smlawt", "smmul", "smmla", "smmls", "smlad", "smlsd", "smuad", "smusd",
      "umaal", "qadd", "qsub", "uadd8", "usub8", "sel", "nop", "cpsid", "cpsie", "mrs", "msr",
      "dmb", "dsb", "isb", "sev", "wfi", "wfe", "bkpt", "svc", "udf", "it", "itt", "ite",
      "ittt", "itte", "itet", "itee", "itttt", "ittte", "ittet", "ittee", "itett", "itete",
      "iteet", "iteee", "ldrd", "strd", "vmov", "yield"}
KNOWN = (LOADS | STORES | MULTI | BRANCH | TABLE | DIV | FP1 | FP3 | FP14 | FPLS | FPMULTI | DP_S
         | DP)


def base_mnemonic(mn):
    """(base, cond) of an objdump mnemonic such as `movwne`, `subs.w`, `bls.n`, `vmul.f32`."""
    m = mn.split(".")[0].lower()
    if m in KNOWN:
        return m, ""
    for cut in range(len(m) - 1, 0, -1):
        head, tail = m[:cut], m[cut:]
        if head not in KNOWN:
            continue
        if tail in CONDS:
            return head, tail
        if head in DP_S and (tail == "s" or (tail[:1] == "s" and tail[1:] in CONDS)):
            return head, tail[1:]
    return m, ""


REG = re.compile(r"\b(r\d+|sb|sl|fp|ip|sp|lr|pc)\b")


def regs(text):
    return REG.findall(text)


class Insn:
    __slots__ = ("addr", "size", "mn", "base", "cond", "ops", "dest", "addr_regs", "nregs",
                 "writes_pc", "literal", "reg_offset", "fp64")

    def __init__(self, addr, size, mn, ops):
        self.addr, self.size, self.mn, self.ops = addr, size, mn, ops
        self.base, self.cond = base_mnemonic(mn)
        ops_l = ops.lower()
        first = ops_l.split(",")[0].strip()
        self.dest = first if REG.fullmatch(first) else None
        inside = re.search(r"\[([^\]]*)\]", ops_l)
        self.addr_regs = regs(inside.group(1)) if inside else []
        self.literal = bool(inside) and inside.group(1).startswith("pc")
        self.reg_offset = len(self.addr_regs) >= 2
        brace = re.search(r"\{([^}]*)\}", ops_l)
        n = 0
        if brace:
            for part in brace.group(1).split(","):
                part = part.strip()
                rng = re.fullmatch(r"([rsd])(\d+)\s*-\s*[rsd](\d+)", part)
                if rng:
                    n += int(rng.group(3)) - int(rng.group(2)) + 1
                elif part:
                    n += 1
        self.nregs = n
        self.fp64 = bool(re.search(r"\bd\d+\b", ops_l))
        self.writes_pc = (
            (self.base in MULTI and self.base.startswith(("ldm", "pop")) and brace is not None
             and "pc" in regs(brace.group(1)))
            or (self.base in LOADS and self.dest == "pc")
            or (self.base in DP_S | DP and self.dest == "pc" and self.base not in
                {"cmp", "cmn", "tst", "teq"})
        )


def disassemble(elf):
    out = subprocess.run(["arm-none-eabi-objdump", "-d", elf], check=True, capture_output=True,
                         text=True).stdout
    insns = {}
    line_re = re.compile(r"^\s*([0-9a-f]+):\t((?:[0-9a-f]{4} ?)+)\s*\t(\S+)\s*(.*)$")
    for line in out.splitlines():
        m = line_re.match(line)
        if not m:
            continue
        mn = m.group(3)
        if mn.startswith("."):
            continue
        addr = int(m.group(1), 16)
        size = 2 * len(m.group(2).split())
        ops = m.group(4).split("@")[0].split(";")[0].strip()
        insns[addr] = Insn(addr, size, mn, ops)
    return insns


def inline_chains(elf, addrs):
    """addr -> [(function, file, line)] from the innermost frame outwards."""
    addrs = sorted(addrs)
    chains = {}
    for i in range(0, len(addrs), 4000):
        chunk = addrs[i:i + 4000]
        out = subprocess.run(
            ["arm-none-eabi-addr2line", "-e", elf, "-f", "-i", "-C", "-a"]
            + [hex(a) for a in chunk], check=True, capture_output=True, text=True).stdout
        cur = None
        lines = out.splitlines()
        j = 0
        while j < len(lines):
            ln = lines[j]
            if ln.startswith("0x") and re.fullmatch(r"0x[0-9a-f]+", ln):
                cur = int(ln, 16)
                chains[cur] = []
                j += 1
                continue
            func = ln
            loc = lines[j + 1] if j + 1 < len(lines) else "??:0"
            f, _, l = loc.rpartition(":")
            l = l.split(" ")[0]
            chains[cur].append((simplify(func), f, l))
            j += 2
    return chains


def simplify(func):
    # Drop generic arguments and closure noise: `<a::B<T> as c::D>::f` -> `a::B::f`.
    s = func
    m = re.match(r"^<(.+?)(?:<.*>)? as .+>::(\w+)$", s)
    if m:
        s = m.group(1) + "::" + m.group(2)
    prev = None
    while prev != s:
        prev = s
        s = re.sub(r"<[^<>]*>", "", s)
    return s


STEP_FN = "hamflight::control::FlightController::step_measured"


def part_of(chain, by):
    """The name of the part an instruction with this inline chain (innermost first) belongs to."""
    if not chain:
        return "?"
    outer = list(reversed(chain))
    names = [c[0] for c in outer]
    if by.startswith("line:"):
        want = by[5:]
        for func, f, l in chain:
            if f.endswith(want):
                return f"{want}:{l} ({func.split('::')[-1]})"
        return "(elsewhere) " + part_of(chain, "func")
    depth = 2 if by == "func2" else 1
    if STEP_FN in names:
        k = names.index(STEP_FN)
        below = names[k + 1:k + 1 + depth]
        if not below:
            return "step_measured (own code)"
        return " > ".join(short(n) for n in below)
    # A function that was not inlined: its outermost frames.
    return " > ".join(short(n) for n in names[:depth])


def attribute(chains, sites, addr, by):
    """The part of an instruction at `addr` executed inside calls made at `sites` (outermost
    first). The logical call path is the call sites' inline chains and the instruction's, outer
    to inner; by function, the part is what lies below `step_measured` on that path; by line,
    the innermost frame in FILE."""
    if by == "symbol":
        # The function whose code this is (not inlined anywhere): where memcpy, the soft-float
        # helpers and other out-of-line callees go.
        own = chains.get(addr, [])
        return short(own[-1][0]) if own else "?"
    path = []  # (function, file, line), outermost first
    for a in tuple(int(s, 16) for s in sites) + (addr,):
        path.extend(reversed(chains.get(a, [])))
    if by.startswith("line:"):
        # line:FILE, or line:FILE:F1,F2 (only frames of functions named F1 or F2: the call
        # sites of their helpers count as theirs).
        want, _, funcs = by[5:].partition(":")
        names = tuple(funcs.split(",")) if funcs else None
        for func, f, l in reversed(path):
            if f.endswith(want) and (names is None or func.split("::")[-1] in names):
                return f"{want}:{l} ({func.split('::')[-1]})"
        return "(elsewhere) " + attribute(chains, sites, addr, "func")
    return part_of(list(reversed(path)), by)


def short(name):
    parts = name.split("::")
    return "::".join(parts[-2:]) if len(parts) >= 2 else name


def cycles(prev, cur, nxt, mode):
    """Cycles of `cur`, given the instruction executed before and after it."""
    P = {"low": 1, "mid": 2, "high": 3}[mode]
    b = cur.base
    taken = nxt is not None and nxt.addr != cur.addr + cur.size
    if b in BRANCH:
        return 1 + P if taken else 1
    if b in TABLE:
        return 2 + P
    if b in MULTI:
        return 1 + cur.nregs + (P if cur.writes_pc else 0)
    if b in ("ldrd", "strd"):
        return 3
    if b in LOADS or b in STORES:
        if cur.writes_pc:
            return 2 + P
        c = 2
        if b in STORES and not cur.reg_offset:
            c = 1
        elif prev is not None and prev.base in LOADS and not prev.writes_pc and mode != "high":
            if mode == "low" or prev.dest not in cur.addr_regs:
                c -= 1
        if (mode != "low" and prev is not None and prev.base in DP_S | DP and prev.dest
                and prev.dest in cur.addr_regs):
            c += 1
        if mode == "high" and cur.literal:
            c += 1
        return c
    if b in DIV:
        return {"low": 2, "mid": 7, "high": 12}[mode]
    if b in FP3:
        return 3
    if b in FP14:
        return 14
    if b in FPLS:
        c = 3 if cur.fp64 else 2
        if mode == "low" and prev is not None and prev.base in LOADS | FPLS:
            c -= 1
        return c
    if b in FPMULTI:
        return 1 + cur.nregs * (2 if cur.fp64 else 1)
    if b == "vmov":
        core = regs(cur.ops.lower())
        return (1 if mode == "low" else 2) if core else 1
    if b in FP1:
        return 1
    if b.startswith("it"):
        if mode == "low":
            return 0
        if mode == "high":
            return 1
        return 0 if prev is not None and prev.size == 2 else 1
    if cur.writes_pc:
        return 1 + P
    return 1


def run_trace(elf, timeout):
    """Counts of (previous PC, PC) pairs inside the step window, and the number of windows."""
    insns = disassemble(elf)
    chains = inline_chains(elf, insns.keys())
    starts = {a for a, c in chains.items() if any(f.endswith("Counter::now") for f, _, _ in c)}
    ends = {a for a, c in chains.items() if any(f.endswith("Counter::since") for f, _, _ in c)}
    if not starts or not ends:
        sys.exit("trace-profile: no CostCounter::now/since in the ELF's inline chains "
                 "(a bench image built with debug info?)")
    starts_s = {f"{a:08x}" for a in starts}
    ends_s = {f"{a:08x}" for a in ends}
    # Calls: PC of a BL/BLX -> the return address, to attribute a called function's instructions
    # to the call site (a shadow call stack).
    calls = {f"{a:08x}": f"{a + i.size:08x}" for a, i in insns.items() if i.base in ("bl", "blx")}
    rfd, wfd = os.pipe()
    cmd = ["qemu-system-arm", "-M", "netduinoplus2", "-nographic", "-monitor", "none",
           "-serial", "null", "-semihosting-config", "enable=on,target=native", "-icount",
           "shift=0", "-singlestep", "-d", "exec,nochain", "-D", f"/dev/fd/{wfd}", "-kernel", elf]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            pass_fds=(wfd,), text=True)
    os.close(wfd)
    pairs = collections.Counter()
    windows = 0
    inside = False
    prev = None
    stack = []  # (return address, call site PC)
    sites = ()
    with os.fdopen(rfd, "r", buffering=1 << 20) as log:
        for line in log:
            if not line.startswith("Trace"):
                continue
            i = line.find("/")
            pc = line[i + 1:i + 9]
            if inside:
                if pc in ends_s and not stack:
                    inside = False
                    prev = None
                    continue
                if stack and pc == stack[-1][0]:
                    stack.pop()
                    sites = tuple(s for _, s in stack)
                elif prev in calls:
                    stack.append((calls[prev], prev))
                    sites = tuple(s for _, s in stack)
                pairs[(sites, prev, pc)] += 1
                prev = pc
            elif pc in starts_s:
                inside = True
                windows += 1
                stack = []
                sites = ()
                pairs[((), None, pc)] += 1
                prev = pc
    out, _ = proc.communicate(timeout=timeout)
    bench = next((ln.strip() for ln in out.splitlines() if ln.startswith("BENCH")), None)
    return insns, chains, pairs, windows, bench


def analyse(insns, chains, pairs, windows, by):
    # Successor counts per PC (for taken branches) and per-pair costs.
    succ = collections.defaultdict(collections.Counter)
    for (_, a, b), n in pairs.items():
        if a is not None:
            succ[a][b] += n
    parts = collections.defaultdict(lambda: {"ins": 0, "low": 0, "mid": 0, "high": 0})
    total = {"ins": 0, "low": 0, "mid": 0, "high": 0}
    unknown = collections.Counter()
    for (sites, a, b), n in pairs.items():
        cur = insns.get(int(b, 16))
        if cur is None:
            unknown[b] += n
            continue
        prev = insns.get(int(a, 16)) if a is not None else None
        nx = succ.get(b)
        # Split this pair's count over cur's successors in proportion (exact for branches: the
        # successor does not depend on the predecessor for straight-line code).
        tot_s = sum(nx.values()) if nx else 0
        if by == "class":
            name = cur.base + (" (core<->S)" if cur.base == "vmov" and regs(cur.ops.lower())
                               else "")
        else:
            name = attribute(chains, sites, cur.addr, by)
        p = parts[name]
        p["ins"] += n
        total["ins"] += n
        for mode in ("low", "mid", "high"):
            if tot_s:
                c = sum(cycles(prev, cur, insns.get(int(s, 16)), mode) * k
                        for s, k in nx.items()) / tot_s
            else:
                c = cycles(prev, cur, None, mode)
            p[mode] += c * n
            total[mode] += c * n
        if cur.base not in KNOWN:
            unknown[cur.mn] += n
    return parts, total, unknown


def self_test():
    """The TRM's published load/store pairing examples (Section 3.3.2), through the model."""
    def seq(lines):
        out = []
        addr = 0x1000
        for text in lines:
            mn, _, ops = text.partition(" ")
            out.append(Insn(addr, 4, mn, ops))
            addr += 4
        return out

    cases = [
        (["ldr r0, [r1, r2]", "str r0, [r3, #20]"], 3),
        (["ldr r0, [r1, r2]", "str r1, [r3, r2]"], 3),
        (["ldr r0, [r1, r5]", "ldr r1, [r2]", "ldr r2, [r3, #4]"], 4),
        (["ldr r0, [r1]", "ldr r1, [r2]"], 3),
    ]
    ok = True
    for lines, want in cases:
        s = seq(lines)
        got = sum(cycles(s[i - 1] if i else None, s[i], s[i + 1] if i + 1 < len(s) else None,
                         "mid") for i in range(len(s)))
        flag = "ok" if got == want else "MISMATCH"
        ok &= got == want
        print(f"{'; '.join(lines):55s} TRM {want}  model {got}  {flag}")
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("elf", nargs="?")
    ap.add_argument("--by", default="func",
                    help="func | func2 | line:FILE[:FUNC,...] (e.g. line:src/adapt/composite.rs:kalman)")
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--timeout", type=int, default=900)
    ap.add_argument("--summary", action="store_true",
                    help="one line: instructions and low/mid/high cycles per step")
    ap.add_argument("--self-test", action="store_true")
    ap.add_argument("--classes", action="store_true",
                    help="also a table by instruction (mnemonic without condition and size)")
    args = ap.parse_args()
    if args.self_test:
        sys.exit(0 if self_test() else 1)
    if not args.elf or not os.path.exists(args.elf):
        ap.error("need the ELF of a bench image")
    insns, chains, pairs, windows, bench = run_trace(args.elf, args.timeout)
    if windows == 0:
        sys.exit("trace-profile: no step window in the trace")
    parts, total, unknown = analyse(insns, chains, pairs, windows, args.by)
    if args.classes:
        classes, _, _ = analyse(insns, chains, pairs, windows, "class")
    w = windows
    if args.summary:
        print(f"TRACE steps={w} instructions={total['ins'] / w:.0f} cycles_low={total['low'] / w:.0f} "
              f"cycles_mid={total['mid'] / w:.0f} cycles_high={total['high'] / w:.0f}")
        return
    print(f"{w} steps traced; {bench or 'no BENCH line'}")
    print()
    print("| part | instructions / step | cycles / step (mid; low-high) | share of cycles |")
    print("| --- | ---: | ---: | ---: |")
    rows = sorted(parts.items(), key=lambda kv: -kv[1]["mid"])
    shown = rows[:args.top]
    rest = rows[args.top:]
    for name, p in shown:
        print(f"| {name} | {p['ins'] / w:,.0f} | {p['mid'] / w:,.0f} ({p['low'] / w:,.0f}-"
              f"{p['high'] / w:,.0f}) | {100 * p['mid'] / total['mid']:.1f} % |")
    if rest:
        r = {k: sum(p[k] for _, p in rest) for k in ("ins", "low", "mid", "high")}
        print(f"| {len(rest)} more | {r['ins'] / w:,.0f} | {r['mid'] / w:,.0f} ({r['low'] / w:,.0f}-"
              f"{r['high'] / w:,.0f}) | {100 * r['mid'] / total['mid']:.1f} % |")
    print(f"| **step** | **{total['ins'] / w:,.0f}** | **{total['mid'] / w:,.0f}** "
          f"({total['low'] / w:,.0f}-{total['high'] / w:,.0f}) | CPI {total['mid'] / total['ins']:.2f} |")
    if args.classes:
        print()
        print("| instruction | count / step | cycles / step (mid; low-high) |")
        print("| --- | ---: | ---: |")
        for name, p in sorted(classes.items(), key=lambda kv: -kv[1]["mid"])[:args.top]:
            print(f"| {name} | {p['ins'] / w:,.0f} | {p['mid'] / w:,.0f} ({p['low'] / w:,.0f}-"
                  f"{p['high'] / w:,.0f}) |")
    if unknown:
        print()
        print("instructions without a timing rule (counted as 1 cycle):",
              ", ".join(f"{k} x{v / w:.0f}" for k, v in unknown.most_common(8)))


if __name__ == "__main__":
    main()
