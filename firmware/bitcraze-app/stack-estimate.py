#!/usr/bin/env python3
"""stack-estimate.py ELF FUNCTION[=BUDGET] [...]: worst-case stack of each FUNCTION in a linked
Cortex-M ELF, from its disassembly (arm-none-eabi-objdump): the largest sum of frame sizes along
any call path. A function's frame is the deepest its own pushes (push and stmdb sp!, vpush and
vstmdb sp!, str to [sp, #-N]!, sub sp) take the stack, net of the pops in its body (the vpush/vpop
pair of an assembly kernel), with the epilogues' pops not subtracted. Calls are bl, blx, and b to
another function (an over-estimate for tail calls). Recursion is cut at the first repeat. Prints the deepest path.
With =BUDGET (bytes), exits 1 when FUNCTION needs more.

build-in-tree.sh runs it on cf2.elf for the two tasks that run hamflight code; ci-check.sh on
the Rust object alone, for hf_step, and on the shim linked with it, for controllerOutOfTree.
qemu-stack.sh and firmware/report.sh set its bounds beside high-water marks measured under QEMU
(a bound below a measurement means a path is missing here).
"""
import re
import subprocess
import sys


# Core registers by number, for ranges in register lists (objdump names r9-r12 sb/sl/fp/ip).
REG_NUM = {**{f"r{i}": i for i in range(16)}, "sb": 9, "sl": 10, "fp": 11, "ip": 12, "sp": 13,
           "lr": 14, "pc": 15}


def count_regs(args):
    """Registers in a push/stmdb list such as `{r4, r5, r6, r7, lr}` or `sp!, {r4-r11, lr}`."""
    inner = re.search(r"\{([^}]*)\}", args)
    n = 0
    for item in (inner.group(1).split(",") if inner else []):
        lo, _, hi = item.strip().partition("-")
        n += REG_NUM[hi] - REG_NUM[lo] + 1 if hi else 1
    return n


def bytes_of_vregs(args):
    """Bytes of a vpush/vstmdb list: `{d8-d15}` (8 B each) or `{s16-s31}` (4 B each)."""
    inner = re.search(r"\{([^}]*)\}", args)
    total = 0
    for item in (inner.group(1).split(",") if inner else []):
        m = re.match(r"\s*([ds])(\d+)(?:-[ds](\d+))?", item)
        if m:
            k = int(m.group(3) or m.group(2)) - int(m.group(2)) + 1
            total += k * (8 if m.group(1) == "d" else 4)
    return total


def classify(op, args):
    """(kind, bytes) of one instruction for the stack: "push" (the stack grows), "restore" (it
    shrinks), "ret" (a return, or a pop that loads pc), or "other"."""
    base = op.split(".")[0]
    if base == "push" or (base in ("stmdb", "stmfd") and args.startswith("sp!")):
        return "push", 4 * count_regs(args)
    if base == "vpush" or (base in ("vstmdb", "fstmdbd") and args.startswith("sp!")):
        return "push", bytes_of_vregs(args)
    m = re.search(r"\[sp, #-(\d+)\]!", args)
    if base == "str" and m:
        return "push", int(m.group(1))
    if base in ("sub", "subw") and re.match(r"sp, (sp, )?#\d+", args):
        return "push", int(re.search(r"#(\d+)", args).group(1))
    if base == "pop" or (base in ("ldmia", "ldmfd", "ldm") and args.startswith("sp!")):
        return ("ret", 0) if "pc" in args else ("restore", 4 * count_regs(args))
    if base == "vpop" or (base in ("vldmia", "fldmiad") and args.startswith("sp!")):
        return "restore", bytes_of_vregs(args)
    m = re.match(r"\w+, \[sp\], #(\d+)", args)
    if base == "ldr" and m:
        return ("ret", 0) if args.startswith("pc") else ("restore", int(m.group(1)))
    if base in ("add", "addw") and re.match(r"sp, (sp, )?#\d+", args):
        return "restore", int(re.search(r"#(\d+)", args).group(1))
    if base == "bx" and args.startswith("lr"):
        return "ret", 0
    return "other", 0


def frame_size(insns):
    """The deepest the function's own stack gets: pushes add, restores in the body subtract
    (an assembly kernel's vpush/vpop pair), restores in an epilogue (only restores up to a
    return or a tail call) do not, because the code after them in address order runs with the
    whole frame."""
    cur = peak = 0
    kinds = [classify(op, args) for op, args in insns]
    for i, (kind, n) in enumerate(kinds):
        if kind == "push":
            cur += n
            peak = max(peak, cur)
        elif kind == "restore":
            j = i
            while j < len(kinds) and kinds[j][0] == "restore":
                j += 1
            tail_call = j < len(insns) and insns[j][0].split(".")[0] == "b" and "<" in insns[j][1]
            if not (j < len(kinds) and (kinds[j][0] == "ret" or tail_call)):
                cur -= n
    return peak


def parse(elf):
    out = subprocess.run(
        ["arm-none-eabi-objdump", "-d", "--no-show-raw-insn", elf],
        capture_output=True, text=True, check=True).stdout
    insns, calls, fn = {}, {}, None
    for line in out.splitlines():
        m = re.match(r"^[0-9a-f]+ <(.*)>:$", line)
        if m:
            fn = m.group(1)
            insns.setdefault(fn, [])
            calls.setdefault(fn, set())
            continue
        parts = line.split("\t")
        if fn is None or len(parts) < 2:
            continue
        op = parts[1].strip()
        args = parts[2].strip() if len(parts) > 2 else ""
        insns[fn].append((op, args))
        if op.split(".")[0] in ("bl", "blx", "b") and "<" in args:
            target = re.search(r"<([^>+]+)", args).group(1)
            if target != fn:
                calls[fn].add(target)
    return {f: frame_size(i) for f, i in insns.items()}, calls


def worst(frames, calls, fn, seen=()):
    """(bytes, path) of the deepest call path from fn."""
    if fn in seen:
        return 0, []
    best = (0, [])
    for c in calls.get(fn, ()):
        d = worst(frames, calls, c, seen + (fn,))
        if d[0] > best[0]:
            best = d
    return frames.get(fn, 0) + best[0], [(fn, frames.get(fn, 0))] + best[1]


def main():
    if len(sys.argv) < 3:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    frames, calls = parse(sys.argv[1])
    over = False
    for arg in sys.argv[2:]:
        fn, _, budget = arg.partition("=")
        if fn not in frames:
            print(f"{fn}: not in {sys.argv[1]}", file=sys.stderr)
            sys.exit(1)
        total, path = worst(frames, calls, fn)
        print(f"{fn}: worst-case stack {total} B")
        for name, size in path:
            print(f"    {size:5d}  {name[:90]}")
        if budget:
            if total > int(budget):
                print(f"{fn} needs {total} B of stack, more than its budget of {budget} B",
                      file=sys.stderr)
                over = True
            else:
                print(f"{fn}: {total} B of stack, within {budget} B")
    sys.exit(1 if over else 0)

if __name__ == "__main__":
    main()
