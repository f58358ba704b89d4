#!/usr/bin/env python3
"""Fails if the top-level modules of host-train/src import each other in a circle.
Looks at `crate::NAME` in code (not comments) of every file under a module."""
import os
import re
import sys

root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "host-train", "src")
graph, where = {}, {}
for base, _, files in os.walk(root):
    for f in files:
        if not f.endswith(".rs"):
            continue
        path = os.path.join(base, f)
        top = os.path.relpath(path, root).split(os.sep)[0].removesuffix(".rs")
        with open(path, encoding="utf-8") as fh:
            for n, line in enumerate(fh, 1):
                code = line.split("//")[0]
                for dep in re.findall(r"crate::(\w+)", code):
                    if dep != top:
                        graph.setdefault(top, set()).add(dep)
                        where.setdefault((top, dep), f"{os.path.relpath(path, root)}:{n}")
def cycle_from(start):
    """A path start -> ... -> start through the import graph, or None."""
    stack, seen = [(start, [start])], set()
    while stack:
        node, path = stack.pop()
        for dep in sorted(graph.get(node, ())):
            if dep == start:
                return path + [start]
            if dep not in seen:
                seen.add(dep)
                stack.append((dep, path + [dep]))
    return None


found = {tuple(sorted(set(c))): c for m in graph if (c := cycle_from(m))}
for c in found.values():
    steps = " -> ".join(f"{a} ({where[(a, b)]})" for a, b in zip(c, c[1:]))
    print(f"import circle: {steps} -> {c[0]}")
if found:
    sys.exit(1)
print(f"no import circles between {len(graph)} modules of host-train/src")
