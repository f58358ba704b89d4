"""The native classes carry their documentation at run time (``help(hamflight.Controller)``), the
text of the type stubs (hamflight/_core.pyi) and no less: pyo3 takes it from the ``///`` comments
of python/src."""

import ast
import inspect
import pathlib
import pydoc
import re

import pytest

import hamflight
from hamflight import _core, sitl

STUBS = pathlib.Path(__file__).resolve().parents[1] / "hamflight" / "_core.pyi"

# The main classes, methods and functions: each documented in more than one line.
MAIN = [
    "Controller",
    "Controller.step",
    "Controller.__reduce__",
    "ControllerBatch",
    "ControllerBatch.step",
    "Blob",
    "Blob.load",
    "BlobError",
    "Setpoint",
    "StepResult",
    "Faults",
    "BatchResult",
    "Scenario",
    "Scenario.load",
    "Scenario.from_dict",
    "Scenario.__reduce__",
    "Plant",
    "Plant.step_rpm",
    "Plant.step_wrench",
    "FlightResult",
    "fly",
]


def runtime(dotted):
    obj = _core
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj


def normalized(doc):
    """The words of a docstring, reST markup aside: ``x`` and :role:`x` read as `x`."""
    doc = re.sub(r":[a-z]+:`", "`", doc).replace("``", "`")
    return " ".join(doc.split())


def stub_docstrings():
    """(dotted name, docstring) of every class, method, property, function and attribute (its
    docstring the string after it) the stubs document."""
    tree = ast.parse(STUBS.read_text(encoding="utf-8"))
    found = []

    def visit(nodes, prefix):
        for node, after in zip(nodes, nodes[1:] + [None]):
            if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
                doc = ast.get_docstring(node)
                if doc:
                    found.append((prefix + node.name, doc))
                if isinstance(node, ast.ClassDef):
                    visit(node.body, f"{prefix}{node.name}.")
            elif (prefix and isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                  and isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                  and isinstance(after.value.value, str)):
                found.append((prefix + node.target.id, inspect.cleandoc(after.value.value)))

    visit(tree.body, "")
    return found


STUB_DOCS = stub_docstrings()


def test_the_stubs_are_read():
    names = [n for n, _ in STUB_DOCS]
    assert len(names) > 30, names
    assert {"Controller", "Controller.step", "Blob.load", "Scenario.__reduce__", "Plant.step_rpm"} <= set(names)
    assert {"FlightResult.t_s", "FlightResult.est_p_m", "FlightResult.report"} <= set(names)


@pytest.mark.parametrize("name, doc", STUB_DOCS, ids=[n for n, _ in STUB_DOCS])
def test_the_runtime_docstring_is_the_stubs(name, doc):
    got = runtime(name).__doc__
    assert got, f"{name} has no docstring at run time"
    assert normalized(got) == normalized(doc), f"{name}:\n--- runtime:\n{got}\n--- _core.pyi:\n{doc}"


@pytest.mark.parametrize("name", MAIN)
def test_main_docstrings_are_more_than_one_line(name):
    doc = inspect.cleandoc(runtime(name).__doc__ or "")
    assert len(doc.splitlines()) > 1, f"{name}: {doc!r}"


def test_every_public_method_and_property_is_documented():
    missing = []
    for cls in (_core.Controller, _core.ControllerBatch, _core.Blob, _core.Setpoint, _core.StepResult,
                _core.Faults, _core.BatchResult, _core.Scenario, _core.Plant, _core.FlightResult):
        assert cls.__doc__, cls
        for name, member in vars(cls).items():
            if name.startswith("_") or not callable(getattr(member, "__get__", None)):
                continue
            if not getattr(getattr(cls, name), "__doc__", None):
                missing.append(f"{cls.__name__}.{name}")
    for f in (_core.fly, _core.controllers, _core.run_tool):
        if not f.__doc__:
            missing.append(f.__name__)
    assert not missing, missing


def help_text(obj):
    """What help(obj) prints, its words (the margin's `|` aside)."""
    lines = pydoc.render_doc(obj, renderer=pydoc.plaintext).splitlines()
    return " ".join(" ".join(re.sub(r"^[ |]*", "", line) for line in lines).split())


def test_help_shows_the_full_text():
    text = help_text(hamflight.Controller)
    for words in ("the nominal CF2X model", "GAIN_KEYWORDS", "motor_tau_s (the lag the composite law assumes)",
                  "the accelerometer's specific force", "the copy starts as after `reset()`"):
        assert words in text, words
    text = help_text(sitl.Scenario)
    assert "does not exist is the package's copy" in text and "validated again on unpickling" in text
    # The constructor's signature too.
    assert "law='composite'" in str(inspect.signature(hamflight.Controller))
