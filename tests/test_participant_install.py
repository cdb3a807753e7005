"""A participant's install (``pip install studyapp``, no extras) runs a study; experimenters' commands on it
say in one line what to install.

The child processes run with pandas, scipy, matplotlib, onnxruntime, onnx, av, starlette, uvicorn and psycopg
refused by an import hook (``tests/fixtures/participant_install.py``), as on a computer that installed only the
base dependencies. The demo design's offscreen run on that install is in ``tests/test_designs_run_offscreen.py``.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from fixtures.participant_install import EXPERIMENTER_ONLY, participant_env
from fixtures.synthetic import write_synthetic_study
from studyapp.resources import designs_dir

CLI = [sys.executable, "-m", "studyapp.cli"]


def _run(args: list, env: dict, cwd: Path | None = None, timeout: int = 180) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env,
                          cwd=cwd)


def test_the_participant_install_refuses_the_extras(tmp_path: Path) -> None:
    """The hook is real: the extras' packages cannot be imported in the child, numpy and the UI's can."""
    env = participant_env(tmp_path / "site")
    probe = ("import importlib\nfor m in %r:\n    try:\n        importlib.import_module(m)\n        print('IMPORTED', m)\n"
             "    except ModuleNotFoundError:\n        print('refused', m)\nimport numpy, moderngl, imgui_bundle, PIL\n"
             % (EXPERIMENTER_ONLY,))
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [w for m in EXPERIMENTER_ONLY for w in ("refused", m)]


def test_a_bundle_participant_needs_no_extras(tmp_path: Path) -> None:
    """``studyapp run STUDY.zip --no-render --bot careful`` completes on the participant's install, and the lab
    merges its results file (the careful bot's smoothing and peaks and the audio code are numpy, not scipy)."""
    from studyapp.cli import main

    design = write_synthetic_study(tmp_path / "study", n_stimuli=2, practice=False)
    lab_db = tmp_path / "lab.sqlite"
    assert main(["bundle", str(design), "-o", str(tmp_path / "send" / "study.zip"), "--participants", "1",
                 "--results", str(lab_db)]) == 0
    home = tmp_path / "participant"
    home.mkdir()
    env = {**participant_env(tmp_path / "site"), "HOME": str(home), "XDG_CACHE_HOME": str(home / ".cache"),
           "XDG_DATA_HOME": str(home / "data"), "STUDYAPP_RESULTS_DIR": str(home / "out")}
    remote = _run(["run", tmp_path / "send" / "study.zip", "--participant", "R01", "--no-render", "--bot", "careful",
                   "--bot-pace", "1.0"], env, cwd=home)
    assert remote.returncode == 0, remote.stdout + remote.stderr
    assert "Traceback" not in remote.stderr
    [results_zip] = (home / "out").glob("results-*-R01-*.zip")
    assert main(["merge", str(lab_db), str(results_zip), "--design", str(design)]) == 0
    out = tmp_path / "lab.csv"
    assert main(["export", str(lab_db), "--csv", str(out)]) == 0
    df = pd.read_csv(out)
    assert set(df["participant"]) == {"R01"} and set(df["condition"]) == {"synced", "lagged", "static"}
    assert df["rank"].notna().all()


def _one_error_line(done: subprocess.CompletedProcess) -> str:
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and "Traceback" not in done.stderr, done.stdout + done.stderr
    return lines[0]


@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> dict:
    """A results database with one participant (made with every package installed, as in the lab)."""
    from studyapp.cli import main

    folder = tmp_path_factory.mktemp("lab")
    design = write_synthetic_study(folder / "study", n_stimuli=2, practice=False)
    db = folder / "lab.sqlite"
    assert main(["run", str(design), "--participant", "P1", "--no-render", "--bot", "ordered", "--results",
                 str(db)]) == 0
    main(["export", str(db), "--csv", str(folder / "lab.csv")])
    return {"design": design, "db": db, "csv": folder / "lab.csv", "env": participant_env(folder / "site")}


@pytest.mark.parametrize("args,package,extra", [
    (["export", "{db}", "--csv", "{out}/x.csv"], "pandas", "analysis"),
    (["schedule", "{design}", "--participants", "4"], "pandas", "analysis"),
    (["validate", "{live}"], "onnxruntime", "models"),
    (["run", "{live}", "--participant", "L1", "--results", "{out}/l.sqlite", "--no-render", "--bot", "ordered"],
     "onnxruntime", "models"),
    (["prerender", "{design}", "--cache", "{out}/cache", "--quiet"], "av", "video"),
], ids=["export", "schedule", "validate-live-model", "run-live-model", "prerender"])
def test_an_experimenters_command_names_its_extra(args: list, package: str, extra: str, lab: dict,
                                                  tmp_path: Path) -> None:
    fill = {"db": lab["db"], "design": lab["design"], "out": tmp_path,
            "live": designs_dir() / "live_model_example.toml"}
    done = _run([a.format(**fill) for a in args], lab["env"])
    line = _one_error_line(done)
    assert line == f'error: studyapp {args[0]} needs {package}, which is not installed: pip install "studyapp[{extra}]"'
    assert not (tmp_path / "cache").exists()  # prerender stopped before rendering anything


def test_results_analysis_names_its_extra(lab: dict, tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "results_analysis.cli", str(lab["csv"]), "--out", str(tmp_path / "a")],
                          capture_output=True, text=True, timeout=120, env=lab["env"])
    assert _one_error_line(done) == ('error: results-analysis needs pandas, which is not installed: '
                                     'pip install "studyapp[analysis]"')
    assert not (tmp_path / "a").exists()


def test_serve_names_the_server_extra(lab: dict) -> None:
    done = _run(["serve", lab["design"], "--port", "0"], lab["env"])
    assert _one_error_line(done) == ('error: studyapp serve needs starlette, uvicorn, av and pandas, which are not '
                                     'installed: pip install "studyapp[server]"')


def test_demo_names_every_missing_package_at_once(lab: dict, tmp_path: Path) -> None:
    done = _run(["demo", "--offscreen", "--out", tmp_path / "demo"], lab["env"])
    assert _one_error_line(done) == ('error: studyapp demo needs pandas, scipy, matplotlib and av, which are not '
                                     'installed: pip install "studyapp[analysis,video]"')
    assert not (tmp_path / "demo").exists()
