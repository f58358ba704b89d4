#!/usr/bin/env python3
"""Checks that code outside host-train/src reaches host-train through its front door only: the
crate root (`host_train::Scenario`) and the top-level layer modules (`host_train::fly::Report`,
`host_train::sim::Plant`), never a layer's submodule (`host_train::fly::eval::Report`,
`use host_train::fly::eval`, `host_train::sim::scenario::Scenario`). The layers re-export what
outsiders need (host-train/src/<layer>/mod.rs, "the layer's front door").

Checked: host-train/tests, host-train/examples, python/src and tools/ (every .rs file). Reads
`use host_train::...;` statements whole (grouped trees like `use host_train::fly::{eval::Report,
Track}` spanning lines included), `host_train::a::b` paths anywhere in code, paths through a
layer imported by name (`use host_train::fly;` then `fly::eval::fly(..)`) and the code blocks of
doc comments (doctests). Comments, strings and prose are not checked. A layer's submodules are
read from its `mod` declarations in host-train/src. Exit 1 with file:line and the path on any
violation; `--self-test` checks the checker on synthetic cases."""
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SRC = os.path.join(ROOT, "host-train", "src")
DIRS = ["host-train/tests", "host-train/examples", "python/src", "tools"]
SKIP_DIRS = {"target", ".git", "node_modules", "build"}
CRATE = "host_train"
# Tags of a doc comment's ``` block that keep it a doctest.
DOCTEST_TAGS = {"rust", "no_run", "should_panic", "ignore", "compile_fail"}


def layer_submodules(src=SRC):
    """{layer: {submodule names}} from `mod` declarations in host-train/src/<layer>/mod.rs (or
    <layer>.rs), for every module declared in lib.rs."""
    with open(os.path.join(src, "lib.rs"), encoding="utf-8") as fh:
        lib = strip_comments_and_strings(fh.read())
    decl = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+((?:r#)?\w+)\s*[;{]", re.M)
    layers = {}
    for layer in decl.findall(lib):
        subs = set()
        for cand in (os.path.join(src, layer, "mod.rs"), os.path.join(src, layer + ".rs")):
            if os.path.exists(cand):
                with open(cand, encoding="utf-8") as fh:
                    subs |= set(decl.findall(strip_comments_and_strings(fh.read())))
        layers[layer] = subs
    return layers


def strip_comments_and_strings(text, keep_doc_code=False):
    """The text with comments and string literals blanked (newlines kept). With `keep_doc_code`,
    the code inside ``` blocks of `///` and `//!` doc comments (those not marked as another
    language) stays, so that doctests are checked."""
    out, i, n = [], 0, len(text)
    fence = None  # inside a doc comment's ``` block: "code" (a doctest) or "other" (```text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            line = text[i:j]
            doc = re.match(r"//[/!](?!/) ?", line)
            if keep_doc_code and doc:
                body = line[doc.end():]
                mark = re.match(r"\s*```\s*([\w,-]*)\s*$", body)
                if mark:
                    tags = [t for t in mark.group(1).split(",") if t]
                    if fence:
                        fence = None
                    elif all(t in DOCTEST_TAGS or t.startswith("edition") for t in tags):
                        fence = "code"
                    else:
                        fence = "other"
                    out.append(" " * len(line))
                elif fence == "code":
                    code = re.sub(r"^(\s*)#(?: |$)", r"\1 ", body)
                    out.append(" " * (len(line) - len(code)) + code)
                else:
                    out.append(" " * len(line))
            else:
                out.append(" " * len(line))
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
        elif (c in "br" or c == '"') and re.match(r'b?r#*"|b?"', text[i:i + 3 + 8]) and (
                i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'(b?)(r(#*))?"', text[i:])
            if m.group(2):
                end = '"' + m.group(3)
                j = text.find(end, i + m.end())
                j = n if j < 0 else j + len(end)
            else:
                j = i + m.end()
                while j < n and text[j] != '"':
                    j += 2 if text[j] == "\\" else 1
                j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "'" and re.match(r"'(\\.|\\u\{[0-9a-fA-F]+\}|[^\\'])'", text[i:i + 12]):
            m = re.match(r"'(\\.|\\u\{[0-9a-fA-F]+\}|[^\\'])'", text[i:i + 12])
            out.append(" " * len(m.group(0)))
            i += len(m.group(0))
        else:
            out.append(c)
            i += 1
    return "".join(out)


def use_paths(tree):
    """(path segments, alias) for every leaf of a use tree: `a::{b, c::{d as e}}` gives
    (['a', 'b'], None) and (['a', 'c', 'd'], 'e'); `self` leaves name their parent."""
    tree = " ".join(tree.split())
    if "{" not in tree:
        path, _, alias = tree.partition(" as ")
        segs = [s.strip() for s in path.split("::") if s.strip()]
        return [(segs, alias.strip() or None)]
    j = tree.index("{")
    head = [s.strip() for s in tree[:j].split("::") if s.strip()]
    inner = tree[j + 1:tree.rindex("}")]
    parts, depth, cur = [], 0, ""
    for ch in inner:
        depth += (ch == "{") - (ch == "}")
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    parts.append(cur)
    leaves = []
    for part in parts:
        if not part.strip():
            continue
        for segs, alias in use_paths(part):
            if segs == ["self"]:
                segs = []
            leaves.append((head + segs, alias))
    return leaves


def deep(segs, layers):
    """Whether `host_train::<segs>` goes behind the front door: its first segment is a layer and
    its second one of that layer's submodules."""
    return len(segs) >= 2 and segs[0] in layers and segs[1] in layers[segs[0]]


def violations(text, layers):
    """(line, path as written) for every path behind the front door in a Rust source."""
    code = strip_comments_and_strings(text, keep_doc_code=True)
    line_of = lambda pos: code.count("\n", 0, pos) + 1
    found, covered = [], []
    uses = [(m, use_paths(m.group(1))) for m in
            re.finditer(r"\b(?:pub(?:\([^)]*\))?\s+)?use\s+(?:::)?([^;]*);", code)]
    # Other names of the crate: `use host_train as ht;`, `use host_train::{self as ht}`,
    # `extern crate host_train as ht;`.
    crate_names = {CRATE}
    crate_names |= set(re.findall(r"\bextern\s+crate\s+" + CRATE + r"\s+as\s+(\w+)", code))
    crate_names |= {a for _, leaves in uses for s, a in leaves if s == [CRATE] and a}
    layer_names = {}  # local name -> layer, from `use host_train::fly;` and the like
    for m, leaves in uses:
        if not any(s and s[0] in crate_names for s, _ in leaves):
            continue
        covered.append(m.span())
        for segs, alias in leaves:
            if not segs or segs[0] not in crate_names:
                continue
            rest = segs[1:]
            if deep(rest, layers):
                found.append((line_of(m.start()), f"use {'::'.join(segs)}"
                              + (f" as {alias}" if alias else "")))
            elif len(rest) == 1 and rest[0] in layers:
                layer_names[alias or rest[0]] = rest[0]
    # Paths in code, outside `use` statements.
    names = "|".join(sorted(re.escape(c) for c in crate_names))
    for m in re.finditer(r"(?<![\w:])(?:::)?(?:" + names + r")((?:\s*::\s*(?:r#)?\w+)+)", code):
        if any(a <= m.start() < b for a, b in covered):
            continue
        segs = [s.strip() for s in m.group(1).split("::") if s.strip()]
        if deep(segs, layers):
            found.append((line_of(m.start()), " ".join(m.group(0).split())))
    for local, layer in layer_names.items():
        pat = r"(?<![\w:])" + re.escape(local) + r"\s*::\s*((?:r#)?\w+)"
        for m in re.finditer(pat, code):
            if any(a <= m.start() < b for a, b in covered):
                continue
            if m.group(1) in layers[layer]:
                found.append((line_of(m.start()), " ".join(m.group(0).split())
                              + f" (`{local}` is host_train::{layer})"))
    return sorted(set(found))


def self_test():
    layers = {
        "fly": {"eval", "track", "events"},
        "sim": {"plant", "scenario"},
        "data": {"collect", "import"},
        "train": {"data", "fused"},
        "control": {"registry", "adapter"},
    }
    cases = [
        ("use host_train::fly::{Report, Track};", 0),
        ("use host_train::fly::{eval::Report, Track};", 1),
        ("use host_train::fly::{eval::Report, track};", 2),
        ("use host_train::fly::{eval::{self, Report}, track};", 3),
        ("use host_train::fly::{self, Report};\nfn f() { fly::Report::new(); }", 0),
        ("use host_train::{\n    fly::{Report, fly_scenario},\n"
         "    sim::{\n        plant::Plant,\n    },\n};", 1),
        ("use host_train::{fly, sim::Scenario};\nfn f() { fly::eval::fly(); }", 1),
        ("use host_train::fly as f;\nfn g() { f::Report::new(); f::track::go(); }", 1),
        ("use host_train::fly::eval;", 1),
        ("use host_train::fly::eval as ev;", 1),
        ("use host_train::sim::scenario::*;", 1),
        ("use host_train::sim::*;", 0),
        ("use host_train::Scenario;\nfn f() { Scenario::from_toml_str(\"\"); }", 0),
        ("fn f() { host_train::fly::eval::fly(&sc, &mut c); }", 1),
        ("fn f() { host_train::fly::fly_scenario(&sc, &mut c); }", 0),
        ("fn f() { host_train::Scenario::from_toml_str(s); }", 0),
        ("fn f() { host_train::sim::Scenario::load(s); }", 0),
        ("fn f() {\n    host_train::data::\n        import::run(&a);\n}", 1),
        ("fn f() { let x = host_train::data::run_import(&a); }", 0),
        ("fn f() { host_train::train::data::load(d); }", 1),
        ("fn f() { host_train::data::load_dataset(d); }", 0),
        ("// host_train::fly::eval::fly in a comment\nfn f() {}", 0),
        ("/* host_train::fly::eval::fly */ fn f() {}", 0),
        ("fn f() { println!(\"host_train::fly::eval::fly\"); }", 0),
        ("fn f() { let s = r#\"host_train::sim::plant::Plant\"#; }", 0),
        ("/// Flies ([`host_train::fly::eval`] prose).\nfn f() {}", 0),
        ("/// ```\n/// use host_train::fly::eval::Report;\n/// ```\nfn f() {}", 1),
        ("/// ```\n/// # use host_train::fly::eval::Report;\n/// ```\nfn f() {}", 1),
        ("/// ```text\n/// host_train::fly::eval::Report\n/// ```\nfn f() {}", 0),
        ("use host_train as ht;\nfn f() { ht::fly::eval::fly(); ht::fly::Report::new(); }", 1),
        ("use other::fly;\nfn f() { fly::eval::x(); }", 0),
        ("fn f() { my_host_train::fly::eval::x(); }", 0),
        ("fn f() { let c = '\"'; host_train::sim::plant::Plant::new(); }", 1),
        ("pub use host_train::fly::events::EventMetrics;", 1),
        ("use host_train as ht;\nuse ht::fly::{eval::Report, Track};", 1),
        ("extern crate host_train as ht;\nfn f() { ht::sim::plant::Plant::new(); }", 1),
        ("use host_train::{self as ht, fly::Report};\nfn f() { ht::fly::track::go(); }", 1),
        ("#[arg(default_value = host_train::control::registry::DEFAULT_WEIGHTS)]", 1),
        ("use host_train::fly::eval::{\n    fly,\n    Report,\n};", 2),
        ("fn f() -> host_train::fly::Report { todo!() }", 0),
    ]
    bad = 0
    for src, want in cases:
        got = violations(src, layers)
        if len(got) != want:
            bad += 1
            print(f"self-test: {len(got)} violation(s), want {want}, in:\n{src}\n  -> {got}")
    if bad:
        print(f"self-test: {bad} of {len(cases)} cases wrong")
        return 1
    print(f"front door self-test: {len(cases)} cases ok")
    return 0


def main(argv):
    if "--self-test" in argv[1:]:
        return self_test()
    layers = layer_submodules()
    bad, files, paths = [], 0, 0
    for d in DIRS:
        for base, dirs, names in os.walk(os.path.join(ROOT, d)):
            dirs[:] = sorted(x for x in dirs if x not in SKIP_DIRS)
            for f in sorted(names):
                if not f.endswith(".rs"):
                    continue
                path = os.path.join(base, f)
                rel = os.path.relpath(path, ROOT)
                with open(path, encoding="utf-8") as fh:
                    text = fh.read()
                if CRATE not in text:
                    continue
                files += 1
                code = strip_comments_and_strings(text, keep_doc_code=True)
                paths += len(re.findall(r"\b" + CRATE + r"\b", code))
                bad += [f"{rel}:{line}: `{p}`" for line, p in violations(text, layers)]
    if bad:
        print("paths behind host-train's front door (re-export the item from its layer, "
              "host-train/src/<layer>/mod.rs, and import it from there):")
        print("\n".join(bad))
        return 1
    print(f"host-train front door: {files} files outside host-train/src name host_train "
          f"{paths} times, none behind a layer ({len(layers)} layers, "
          f"{sum(len(s) for s in layers.values())} submodules)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
