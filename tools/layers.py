#!/usr/bin/env python3
"""Checks host-train/src's layers: every `crate::` path in code (not comments) of a top-level
folder names its own folder, a lower layer, or a same-layer folder this table allows; no import
circle between top-level folders; and every top-level module is in the table.

Reads `use crate::...;` statements whole (grouped imports like `use crate::{a::b, c}` spanning
lines included) and `crate::x::y` paths anywhere in code. Exit 1 with file:line and the import
on any violation."""
import os
import re
import sys

# The layers, lowest first: a folder may import from lower layers, and from its own layer only
# where SAME_LAYER allows it.
LAYERS = {
    "sim": 1,  # plant, scenario, trajectory, sensors, ekf: the simulation
    "io": 1,  # files, flight log, uSD log, dataset
    "control": 2,  # the Controller trait, baselines, the core adapter, the name registry
    "report": 2,  # plots
    "data": 3,  # collect, import
    "train": 3,  # training, flight-free
    "fly": 3,  # the SITL loop, scores, events, track, margins, uSD recording
    "pipeline": 4,  # train + flight check, bench, demo, vehicle study
    "bridge": 4,  # the JSON-lines bridge
    "main": 5,  # the binary: parses and dispatches (its own crate; `host_train::` paths)
}
# Same-layer imports allowed, (from, to).
SAME_LAYER = {("io", "sim")}
# Files at the crate root that are no layer.
ROOT_FILES = {"lib.rs"}

root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "host-train", "src")


def strip_comments(text):
    """The text with // and /* */ comments blanked (newlines kept), strings left alone."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == '"' or text.startswith('r"', i) or text.startswith('r#"', i):
            # A string literal: copied as is (it may hold `//`).
            if c == '"':
                j = i + 1
                while j < n and text[j] != '"':
                    j += 2 if text[j] == "\\" else 1
                j += 1
            else:
                hashes = text[i + 1 : text.index('"', i)]
                end = '"' + hashes
                j = text.find(end, i + 1 + len(hashes) + 1)
                j = n if j < 0 else j + len(end)
            out.append(text[i:j])
            i = j
        elif c == "'" and re.match(r"'(\\.|[^\\'])'", text[i : i + 4]):
            # A char literal such as '"'.
            m = re.match(r"'(\\.|[^\\'])'", text[i : i + 4])
            out.append(m.group(0))
            i += len(m.group(0))
        else:
            out.append(c)
            i += 1
    return "".join(out)


def use_paths(tree):
    """The full paths of a use tree (`a::{b, c::{d}}` → `a::b`, `a::c::d`)."""
    tree = tree.strip()
    if "{" not in tree:
        return [tree.split(" as ")[0].strip()]
    j = tree.index("{")
    head = tree[:j].rstrip(":").strip()
    inner = tree[j + 1 : tree.rindex("}")]
    parts, depth, cur = [], 0, ""
    for ch in inner:
        depth += (ch == "{") - (ch == "}")
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    parts.append(cur)
    return [f"{head}::{p}" if head else p for part in parts if part.strip() for p in use_paths(part)]


def imports(path):
    """(line, top-level module, the import as written) for every crate path in the file."""
    with open(path, encoding="utf-8") as fh:
        code = strip_comments(fh.read())
    line_of = lambda pos: code.count("\n", 0, pos) + 1
    found, covered = [], []
    # The binary names the library as `host_train::`, the library itself as `crate::`.
    prefixes = "crate|host_train" if os.path.basename(path) == "main.rs" else "crate"
    for m in re.finditer(r"\buse\s+(?:" + prefixes + r")::([^;]*);", code):
        covered.append(m.span())
        for p in use_paths(m.group(1)):
            top = p.split("::")[0].strip()
            if top and top != "self":
                found.append((line_of(m.start()), top, "crate::" + " ".join(p.split())))
    for m in re.finditer(r"\b(?:" + prefixes + r")::((?:r#)?\w+)((?:::\w+)*)", code):
        if any(a <= m.start() < b for a, b in covered):
            continue
        found.append((line_of(m.start()), m.group(1), m.group(0)))
    return found


def main():
    errors = []
    graph, where = {}, {}
    files = 0
    for base, _, names in os.walk(root):
        for f in sorted(names):
            if not f.endswith(".rs"):
                continue
            path = os.path.join(base, f)
            rel = os.path.relpath(path, root)
            files += 1
            if rel in ROOT_FILES:
                continue
            folder = rel.split(os.sep)[0].removesuffix(".rs")
            if folder not in LAYERS:
                errors.append(f"{rel}: top-level module `{folder}` is in no layer (add it to "
                              "LAYERS in tools/layers.py, or move it into a layer's folder)")
                continue
            for line, dep, text in imports(path):
                if dep == folder:
                    continue
                if dep not in LAYERS:
                    errors.append(f"{rel}:{line}: `{text}`: `{dep}` is in no layer (name the "
                                  "module by its layer's path)")
                    continue
                graph.setdefault(folder, set()).add(dep)
                where.setdefault((folder, dep), f"{rel}:{line}")
                lf, ld = LAYERS[folder], LAYERS[dep]
                if ld > lf:
                    errors.append(f"{rel}:{line}: `{text}`: {folder} (layer {lf}) imports "
                                  f"{dep} (layer {ld}), a higher layer")
                elif ld == lf and (folder, dep) not in SAME_LAYER:
                    errors.append(f"{rel}:{line}: `{text}`: {folder} imports {dep} of its own "
                                  f"layer {lf} (not in SAME_LAYER)")

    def cycle_from(start):
        stack, seen = [(start, [start])], set()
        while stack:
            node, p = stack.pop()
            for dep in sorted(graph.get(node, ())):
                if dep == start:
                    return p + [start]
                if dep not in seen:
                    seen.add(dep)
                    stack.append((dep, p + [dep]))
        return None

    cycles = {tuple(sorted(set(c))): c for m in sorted(graph) if (c := cycle_from(m))}
    for c in cycles.values():
        steps = " -> ".join(f"{a} ({where[(a, b)]})" for a, b in zip(c, c[1:]))
        errors.append(f"import circle: {steps} -> {c[0]}")
    for e in errors:
        print(e)
    if errors:
        sys.exit(1)
    edges = sum(len(v) for v in graph.values())
    print(f"host-train/src: {files} files in {len(LAYERS)} layered folders, {edges} imports "
          "between folders, all downward (or allowed same-layer), no circles")


if __name__ == "__main__":
    main()
