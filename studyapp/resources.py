"""Locate files that ship with the package (shaders, example designs, demo data).

In a built wheel the top-level ``shaders/`` and ``study_designs/`` folders are installed as
``studyapp/_data/...``; in a source checkout (editable install, tests) they sit next to the
package. Both layouts are supported so the same code runs for participants and developers.
"""
from __future__ import annotations

from pathlib import Path

_PKG = Path(__file__).resolve().parent


def _find(name: str) -> Path:
    for candidate in (_PKG / "_data" / name, _PKG.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(
        f"studyapp data folder {name!r} is missing from the installation "
        f"(looked in {_PKG / '_data'} and {_PKG.parent}); reinstall studyapp"
    )


def shader_dir() -> Path:
    """Folder holding the GLSL sources."""
    return _find("shaders")


def designs_dir() -> Path:
    """Folder holding the example study designs (including ``demo.toml``)."""
    return _find("study_designs")


def demo_design() -> Path:
    """Path of the built-in demo study design."""
    return designs_dir() / "demo.toml"


def read_shader(name: str) -> str:
    """Source text of one shader file, e.g. ``read_shader("skinned.vert")``."""
    return (shader_dir() / name).read_text(encoding="utf-8")
