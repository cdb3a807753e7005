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


#: What `validate` may never import: its work reads the design, BVH/NPZ motion (pandas) and WAV samples
#: (scipy.io), but no signal processing, plotting, rendering, model or playback package.
VALIDATE_NEVER = ("scipy.signal", "scipy.ndimage", "matplotlib", "moderngl", "onnxruntime", "av", "imgui_bundle",
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
