"""The wheel a participant installs must carry the shaders, the example designs and the demo data.

Builds the real wheel, installs it without dependencies into a fresh virtual environment that borrows the
test environment's third-party packages, and runs the installed console script from a folder outside the
checkout, so nothing can be found through the source tree by accident.
"""
from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    try:
        import hatchling  # noqa: F401
    except ImportError:
        subprocess.run([sys.executable, "-m", "pip", "install", "-q", "hatchling"], check=True)
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out), str(ROOT)],
        check=True,
    )
    wheels = list(out.glob("studyapp-*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


def test_wheel_contains_shaders_designs_and_demo_data(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    shaders = {n for n in names if n.startswith("studyapp/_data/shaders/")}
    assert any(n.endswith(".vert") for n in shaders) and any(n.endswith(".frag") for n in shaders), shaders
    assert "studyapp/_data/study_designs/demo.toml" in names
    demo = [n for n in names if n.startswith("studyapp/_data/study_designs/demo/")]
    assert any(n.endswith(".wav") for n in demo) and any(n.endswith(".bvh") for n in demo), demo
    assert any(n.startswith("results_analysis/") for n in names)
    for src in (ROOT / "shaders").iterdir():
        assert f"studyapp/_data/shaders/{src.name}" in names, f"{src.name} missing from the wheel"
    # the slot labels' font and its license (matplotlib, which ships it too, is not a participant dependency)
    assert {"studyapp/render/fonts/DejaVuSans-Bold.ttf", "studyapp/render/fonts/LICENSE_DEJAVU"} <= names
    for src in (ROOT / "studyapp" / "web" / "assets").iterdir():   # the browser pages' script and style
        assert f"studyapp/web/assets/{src.name}" in names, f"{src.name} missing from the wheel"


def test_wheel_leaves_out_the_test_fixtures(wheel: Path) -> None:
    # The synthetic study generator lives in tests/fixtures: a participant's installation never needs it.
    names = zipfile.ZipFile(wheel).namelist()
    assert any(n.startswith("studyapp/study/") for n in names), "the wheel has no study package at all"
    assert not [n for n in names if "synthetic" in n or n.startswith(("tests/", "fixtures/"))], names


def test_installed_wheel_runs_outside_checkout(wheel: Path, tmp_path: Path) -> None:
    env_dir = tmp_path / "venv"
    # with the venv's own pip (ensurepip, offline), so the console scripts are written for this venv's python
    venv.EnvBuilder(with_pip=True).create(env_dir)
    bindir = env_dir / ("Scripts" if os.name == "nt" else "bin")
    py = bindir / ("python.exe" if os.name == "nt" else "python")
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    # Borrow numpy, moderngl, ... from the test environment, but not studyapp itself.
    (Path(site) / "borrowed.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)], check=True)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = lambda *a: subprocess.run([str(py), "-m", "studyapp.cli", *a], cwd=tmp_path, env=env,
                                    capture_output=True, text=True, timeout=300)
    # the README's promise: `pip install dist/*.whl`, then the `studyapp` command works
    for script, words in (("studyapp", "demo"), ("results-analysis", "--out")):
        exe = bindir / (script + (".exe" if os.name == "nt" else ""))
        helped = subprocess.run([str(exe), "--help"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert helped.returncode == 0 and words in helped.stdout, (script, helped.stdout + helped.stderr)
    where = subprocess.run([str(py), "-c", "import studyapp, studyapp.resources as r; print(studyapp.__file__); print(r.demo_design())"],
                           cwd=tmp_path, env=env, capture_output=True, text=True, check=True).stdout.split()
    assert str(ROOT) not in where[0], f"studyapp imported from the checkout: {where[0]}"
    assert "_data" in where[1] and Path(where[1]).is_file(), where
    helped = run("--help")
    assert helped.returncode == 0 and "demo" in helped.stdout, helped.stderr
    checked = run("validate", where[1])
    assert checked.returncode == 0, checked.stdout + checked.stderr
