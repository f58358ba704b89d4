#!/usr/bin/env python3
"""Checks that controller names become controllers in one place only: host-train's
`control/spec.rs` (`ControllerSpec::ALL`). Anywhere else in the Rust sources (host-train, the
core, python/src, tools/, xtask, examples and tests), a `match` arm on a controller name
(`"adaptive" =>`, `"learned" |`), a prefix or suffix test on one (`starts_with("adaptive")`,
`ends_with("-composite")`) or a comparison (`name == "ida-pbc"`) is a second mapping and fails
the check with file:line. Lists of names to fly (demo, studies) and the names in strings,
comments and docs are fine: they go through the registry, which parses them with the spec.
Bitcraze's own controllers of tools/bitcraze-loop (`bc-*`) are not ours and not checked, nor
are host-train/tests, which choose a bar by the name they flew (the flight itself is built by the
registry)."""
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SPEC = os.path.join("host-train", "src", "control", "spec.rs")
DIRS = ["src", "host-train", "python/src", "tools", "xtask", "examples", "firmware/bitcraze-app/src"]
NAMES = (
    r"(?:adaptive|learned|ida-pbc|geometric|pid)"
    r"(?:-adaptive)?(?:-gradient|-composite)?"
)
PATTERNS = [
    re.compile(r'"' + NAMES + r'"\s*(?:=>|\|)'),  # match arm
    re.compile(r'\|\s*"' + NAMES + r'"\s*=>'),  # last alternative of an arm
    re.compile(r'(?:starts_with|ends_with|strip_prefix|strip_suffix)\(\s*"-?' + NAMES + r'-?"'),
    re.compile(r'(?:starts_with|ends_with|strip_suffix)\(\s*"-(?:gradient|composite)"'),
    re.compile(r'(?:==|!=)\s*"' + NAMES + r'"'),
]
SKIP_DIRS = {"target", ".git", "node_modules", "build"}


def code_of(line: str) -> str:
    """The line without a // comment (a crude cut: controller names never contain //)."""
    i = line.find("//")
    return line if i < 0 else line[:i]


def main() -> int:
    bad = []
    for d in DIRS:
        for base, dirs, files in os.walk(os.path.join(ROOT, d)):
            dirs[:] = [x for x in dirs if x not in SKIP_DIRS]
            for f in files:
                if not f.endswith(".rs"):
                    continue
                path = os.path.join(base, f)
                rel = os.path.relpath(path, ROOT)
                if rel == SPEC or rel.startswith(os.path.join("host-train", "tests") + os.sep):
                    continue
                with open(path, encoding="utf-8") as fh:
                    for n, line in enumerate(fh, 1):
                        code = code_of(line)
                        if any(p.search(code) for p in PATTERNS):
                            bad.append(f"{rel}:{n}: {line.strip()}")
    if bad:
        print("controller names mapped outside host-train/src/control/spec.rs:")
        print("\n".join(bad))
        print("parse the name with ControllerSpec (host_train::ControllerSpec::parse) instead")
        return 1
    print("one name map: controller names become controllers only in " + SPEC)
    return 0


if __name__ == "__main__":
    sys.exit(main())
