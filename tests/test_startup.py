"""`studyapp --help` and argument errors must not pay for what only a command's work needs.

Not a timing test (timings live in benchmarks/): it checks which heavy packages the shell imports before a
command runs, in a fresh interpreter, which is what makes `--help` cost a bare ``import numpy`` or less.
"""
import json
import subprocess
import sys

HEAVY = ("pandas", "scipy", "moderngl", "matplotlib", "onnxruntime", "av", "imgui_bundle", "glfw", "sounddevice")


def test_help_imports_no_heavy_package():
    code = ("import sys, contextlib, io\n"
            "from studyapp.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try: main(['--help'])\n"
            "    except SystemExit: pass\n"
            f"print(__import__('json').dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out.strip().splitlines()[-1]) == []


#: What `validate` may never import: its work reads the design, BVH/NPZ motion and WAV samples (numpy's own
#: readers: no pandas, no scipy.io), but no signal processing, plotting, rendering, model or playback package.
VALIDATE_NEVER = ("pandas", "scipy.io", "scipy.signal", "scipy.ndimage", "matplotlib", "moderngl", "onnxruntime", "av", "imgui_bundle",
                  "glfw", "sounddevice")


def test_validate_imports_only_what_its_checks_need():
    code = ("import sys, contextlib, io\n"
            "from studyapp.cli import main\n"
            "from studyapp.resources import demo_design\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try: main(['validate', str(demo_design())])\n"
            "    except SystemExit: pass\n"
            f"print(__import__('json').dumps(sorted(m for m in {VALIDATE_NEVER!r} if m in sys.modules)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out.strip().splitlines()[-1]) == []


def test_a_trials_media_and_scene_import_no_pandas_or_scipy():
    """The first trial frame's data path (design, schedule, motion, face, audio, retargeting, palettes) runs on
    numpy alone: pandas and scipy.io cost a participant about a second before the first frame."""
    code = ("import sys, json\n"
            "from studyapp.resources import demo_design\n"
            "from studyapp.study.design import load_design\n"
            "from studyapp.study.schedule import participant_schedule\n"
            "from studyapp.study.stimuli import load_trial_media\n"
            "from studyapp.render.scene import build_trial_scene\n"
            "design = load_design(demo_design())\n"
            "plan = [p for p in participant_schedule(design, 'P01', row=0) if not p.is_practice][0]\n"
            "scene = build_trial_scene(None, load_trial_media(design, plan))\n"
            "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in ('pandas', 'scipy'))))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out.strip().splitlines()[-1]) == []
