#!/usr/bin/env python3
"""stack-estimate.py ELF FUNCTION[=BUDGET] [...]: worst-case stack of each FUNCTION in a linked
Cortex-M ELF, from its disassembly (arm-none-eabi-objdump): the largest sum of frame sizes (push,
vpush, sub sp) along any call path (bl, blx, and b to another function, counted as a call: an
over-estimate for tail calls). Recursion is cut at the first repeat. Prints the deepest path.
With =BUDGET (bytes), exits 1 when FUNCTION needs more.

build-in-tree.sh runs it on cf2.elf for the two tasks that run hamflight code; ci-check.sh on
the Rust object alone, for hf_step.
"""
import re
import subprocess
import sys


def parse(elf):
    out = subprocess.run(
        ["arm-none-eabi-objdump", "-d", "--no-show-raw-insn", elf],
        capture_output=True, text=True, check=True).stdout
    frames, calls, fn = {}, {}, None
    for line in out.splitlines():
        m = re.match(r"^[0-9a-f]+ <(.*)>:$", line)
        if m:
            fn = m.group(1)
            frames.setdefault(fn, 0)
            calls.setdefault(fn, set())
            continue
        parts = line.split("\t")
        if fn is None or len(parts) < 2:
            continue
        op = parts[1].strip()
        args = parts[2].strip() if len(parts) > 2 else ""
        if op.startswith("push"):
            frames[fn] += 4 * len(re.findall(r"r\d+|lr|fp|ip", args))
        elif op.startswith("vpush"):
            r = re.search(r"d(\d+)-d(\d+)", args)
            frames[fn] += 8 * (int(r.group(2)) - int(r.group(1)) + 1) if r else 8 * len(re.findall(r"d\d+", args))
        elif op.startswith("sub") and re.match(r"sp, (sp, )?#\d+", args):
            frames[fn] += int(re.search(r"#(\d+)", args).group(1))
        elif op.split(".")[0] in ("bl", "blx", "b") and "<" in args:
            target = re.search(r"<([^>+]+)", args).group(1)
            if target != fn:
                calls[fn].add(target)
    return frames, calls


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
