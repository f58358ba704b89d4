"""The files shipped inside the package: the repository's scenario files (``scenarios/*.toml``)
and its default weight blob (``weights/default.hfw``), found without a checkout.

>>> from hamflight import data
>>> data.scenarios()[:2]                  # the packaged scenario names
['asym-calm-spiral', 'asym-rotor-loss']
>>> data.scenario("paper-spiral")         # pathlib.Path of the packaged file
>>> data.default_weights()                # pathlib.Path of the packaged weights/default.hfw

``sitl.fly``, ``sitl.Scenario.load``, ``Blob.load`` and every ``weights=`` argument fall back to
these copies when a relative path such as ``"scenarios/paper-spiral.toml"`` (or
``"paper-spiral.toml"``), ``"weights/default.hfw"`` (or ``"default.hfw"``) does not exist from
the working directory: the repository's paths work outside a checkout, and inside one the
checkout's file (the same file) is read first.

In the wheel the files are copies made at build time; in a checkout ``hamflight/scenarios`` and
``hamflight/weights`` are symbolic links to the repository's directories, so a development
install (``maturin develop``) finds the same files.
"""

from __future__ import annotations

import os
import pathlib
from importlib import resources
from typing import List, Optional, Union

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["scenarios", "scenario", "default_weights", "root"]


def root() -> pathlib.Path:
    """The installed package's directory (where ``scenarios/`` and ``weights/`` are)."""
    return pathlib.Path(os.fspath(resources.files(__package__)))


def scenarios() -> List[str]:
    """The names of the packaged scenario files (``scenario(name)`` gives each one's path)."""
    folder = root() / "scenarios"
    if not folder.is_dir():
        return []
    return sorted(p.stem for p in folder.glob("*.toml"))


def scenario(name: str) -> pathlib.Path:
    """The packaged scenario file ``name`` (``"paper-spiral"``, ``"paper-spiral.toml"`` or
    ``"scenarios/paper-spiral.toml"``); ``FileNotFoundError`` naming the choices otherwise."""
    found = _packaged(name, "scenarios")
    if found is None:
        raise FileNotFoundError(f"no packaged scenario {name!r}; the packaged ones: {', '.join(scenarios())}")
    return found


def default_weights() -> pathlib.Path:
    """The packaged ``weights/default.hfw`` (the blob ``Blob.default()`` holds, as a file)."""
    found = _packaged("default.hfw", "weights")
    if found is None:
        raise FileNotFoundError(f"weights/default.hfw is not in this installation ({root()})")
    return found


def _packaged(path: PathLike, folder: str) -> Optional[pathlib.Path]:
    """The package's copy of a relative ``path`` naming a file of the repository's ``folder``
    (``folder/NAME`` or ``NAME``; for scenarios ``.toml`` may be left out), or None."""
    p = pathlib.PurePath(os.fspath(path))
    if p.is_absolute():
        return None
    parts = p.parts
    if len(parts) == 2 and parts[0] == folder:
        name = parts[1]
    elif len(parts) == 1:
        name = parts[0]
    else:
        return None
    candidates = [name]
    if folder == "scenarios" and not name.endswith(".toml"):
        candidates.append(name + ".toml")
    for c in candidates:
        f = root() / folder / c
        if f.is_file():
            return f
    return None
