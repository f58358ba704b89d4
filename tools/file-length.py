#!/usr/bin/env python3
"""Checks the file-length rule: no Rust file over 600 lines, except src/fpu.rs.

Reads every tracked `.rs` file (`git ls-files '*.rs'`; outside a git checkout, every `.rs` file
but build output) and counts its lines as `wc -l` does. Exit 1 listing each file over the limit
with its length, longest first; exit 0 with a one-line summary otherwise. A long file is split
into modules by concern (one file per concern, named by what it is); the limit is not raised.

usage: python3 tools/file-length.py [-h | --help]   (from anywhere in the repository)"""
import os
import subprocess
import sys

LIMIT = 600
# Paths from the repository root, allowed over the limit.
EXEMPT = {"src/fpu.rs"}
SKIP_DIRS = {"target", ".git", "out"}

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def rust_files():
    """The repository's .rs files, relative to its root: the tracked ones, or in an unpacked
    archive every one outside build output."""
    try:
        out = subprocess.run(["git", "ls-files", "-z", "*.rs"], cwd=ROOT, check=True,
                             capture_output=True).stdout
        return [p for p in out.decode().split("\0") if p]
    except (OSError, subprocess.CalledProcessError):
        files = []
        for d, subdirs, names in os.walk(ROOT):
            subdirs[:] = sorted(s for s in subdirs if s not in SKIP_DIRS)
            files += [os.path.relpath(os.path.join(d, n), ROOT)
                      for n in names if n.endswith(".rs")]
        return sorted(files)


def main(argv):
    if any(a in ("-h", "--help") for a in argv[1:]):
        print(__doc__)
        return 0
    if argv[1:]:
        print(f"file-length.py: unexpected argument {argv[1]!r}; try --help", file=sys.stderr)
        return 2
    files = rust_files()
    long = []
    for rel in files:
        path = os.path.join(ROOT, rel)
        if rel in EXEMPT or not os.path.isfile(path):  # tracked but deleted in the work tree
            continue
        with open(path, "rb") as fh:
            n = fh.read().count(b"\n")
        if n > LIMIT:
            long.append((n, rel))
    if long:
        print(f".rs files over {LIMIT} lines (only {', '.join(sorted(EXEMPT))} may be; split "
              "them into modules by concern):")
        for n, rel in sorted(long, key=lambda x: (-x[0], x[1])):
            print(f"{n:6} {rel}")
        return 1
    print(f"{len(files)} .rs files, none over {LIMIT} lines but {', '.join(sorted(EXEMPT))}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
