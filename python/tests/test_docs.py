"""Every ```python block of docs/python.md runs, each on its own (a fresh namespace, a fresh
temporary working directory), against the installed package.

The repository's relative paths in the snippets (``scenarios/...``, ``weights/default.hfw``)
resolve to the package's copies there (``hamflight.data``), as the page says they do outside a
checkout; the flight logs the import snippet reads are written first (``LOG_FIXTURES``). A
block that cannot run here (one that needs a Crazyflie and its radio) is marked in the markdown
by ``<!-- doc-test: skip (REASON) -->`` on the line before its fence; the number of such blocks
is asserted (``EXPECTED_SKIPPED``), so none is skipped silently. Shell blocks are not run.
"""

from __future__ import annotations

import pathlib
import re
from dataclasses import dataclass
from typing import List, Optional

import pytest

DOC = pathlib.Path(__file__).resolve().parents[2] / "docs" / "python.md"

# What docs/python.md holds today: a block added, removed or newly skipped changes these, on
# purpose (and a parser that stopped finding blocks fails here rather than passing on nothing).
EXPECTED_RUN = 8
EXPECTED_SKIPPED = 0

# Fence languages the page may use; a ```py or ```python3 block would otherwise not run unnoticed.
KNOWN_LANGUAGES = {"python", "sh"}

# The flight logs (hamflight-cf's CSV) the import snippet names, written into its directory.
LOG_FIXTURES = ("flight00.csv", "flight01.csv", "flight02.csv")

FENCE = re.compile(r"^(\s*)```(.*)$")
MARKER = re.compile(r"^\s*<!--\s*doc-test:\s*(.*?)\s*-->\s*$")
SKIP = re.compile(r"^skip \((.+)\)$")


@dataclass
class Block:
    line: int  # 1-based line of the first code line
    language: str
    code: str
    skip: Optional[str]  # the reason, when marked


def blocks(text: str) -> List[Block]:
    """The fenced blocks of a markdown page, with their skip markers. A marker must name its
    reason and be followed (on the next non-blank line) by a ```python fence; a fence must close."""
    lines = text.splitlines()
    out: List[Block] = []
    pending: Optional[tuple] = None  # (line number, reason) of a marker not yet used
    i = 0
    while i < len(lines):
        line = lines[i]
        m = MARKER.match(line)
        if m:
            if pending is not None:
                raise ValueError(f"line {pending[0]}: doc-test marker not followed by a ```python block")
            directive = SKIP.match(m.group(1))
            if directive is None:
                raise ValueError(f"line {i + 1}: unknown doc-test marker {m.group(1)!r} (expected `skip (REASON)`)")
            pending = (i + 1, directive.group(1))
            i += 1
            continue
        m = FENCE.match(line)
        if m:
            indent, language = m.group(1), m.group(2).strip()
            start = i + 1
            end = next((j for j in range(start, len(lines)) if lines[j].strip() == "```"), None)
            if end is None:
                raise ValueError(f"line {i + 1}: unclosed ``` fence")
            body = [ln[len(indent):] if ln.startswith(indent) else ln for ln in lines[start:end]]
            skip = None
            if pending is not None:
                if language != "python":
                    raise ValueError(f"line {pending[0]}: doc-test marker before a ```{language} block")
                skip = pending[1]
                pending = None
            out.append(Block(start + 1, language, "\n".join(body) + "\n", skip))
            i = end + 1
            continue
        if line.strip() and pending is not None:
            raise ValueError(f"line {pending[0]}: doc-test marker not followed by a ```python block")
        i += 1
    if pending is not None:
        raise ValueError(f"line {pending[0]}: doc-test marker not followed by a ```python block")
    return out


PAGE = blocks(DOC.read_text(encoding="utf-8"))
PYTHON = [b for b in PAGE if b.language == "python"]


def test_the_page_has_the_expected_blocks():
    languages = {b.language for b in PAGE}
    assert languages <= KNOWN_LANGUAGES, f"unknown fence languages in {DOC}: {languages - KNOWN_LANGUAGES}"
    skipped = [b for b in PYTHON if b.skip]
    assert len(PYTHON) - len(skipped) == EXPECTED_RUN, [b.line for b in PYTHON if not b.skip]
    assert len(skipped) == EXPECTED_SKIPPED, [(b.line, b.skip) for b in skipped]
    assert all(b.code.strip() for b in PYTHON)


def test_the_parser_reads_markers_and_rejects_stray_ones():
    page = "\n".join([
        "text",
        "```python",
        "x = 1",
        "```",
        "<!-- doc-test: skip (needs a Crazyflie) -->",
        "",
        "```python",
        "radio()",
        "```",
        "```sh",
        "ls",
        "```",
        "- a list item:",
        "  ```python",
        "  y = 2",
        "  ```",
    ])
    got = [(b.line, b.language, b.code, b.skip) for b in blocks(page)]
    assert got == [
        (3, "python", "x = 1\n", None),
        (8, "python", "radio()\n", "needs a Crazyflie"),
        (11, "sh", "ls\n", None),
        (15, "python", "y = 2\n", None),
    ]
    for bad in (
        "<!-- doc-test: skip (why) -->\ntext\n```python\nx\n```",  # marker not before the fence
        "<!-- doc-test: skip (why) -->\n```sh\nls\n```",  # on a block that is never run
        "<!-- doc-test: skip -->\n```python\nx\n```",  # no reason
        "<!-- doc-test: skpi (why) -->\n```python\nx\n```",  # a typo
        "<!-- doc-test: skip (why) -->",  # nothing after it
        "```python\nx = 1\n",  # unclosed
    ):
        with pytest.raises(ValueError):
            blocks(bad)


def write_log_fixtures(directory: pathlib.Path) -> None:
    """Hover logs as ``hamflight-cf log`` writes them (test_crazyflie's synthetic flight)."""
    from test_crazyflie import synthetic_hover

    for name in LOG_FIXTURES:
        synthetic_hover(directory / name)


@pytest.mark.parametrize("block", PYTHON, ids=[f"python.md:{b.line}" for b in PYTHON])
def test_snippet_runs(block, tmp_path, monkeypatch):
    if block.skip:
        pytest.skip(f"docs/python.md:{block.line}: {block.skip}")
    monkeypatch.chdir(tmp_path)
    if any(name in block.code for name in LOG_FIXTURES):
        write_log_fixtures(tmp_path)
    # Padded so that a traceback names the page's own line numbers.
    code = compile("\n" * (block.line - 1) + block.code, str(DOC), "exec")
    exec(code, {"__name__": "__doc_snippet__"})
