"""The notes a command prints about a design (DesignWarning) are one line each, as `validate` prints them."""
import os
import subprocess
import sys
from pathlib import Path

from fixtures.paradigm_studies import write_paradigm_study

MIXED = '''
[[blocks]]
id = "rates"
paradigm = "rating"
criteria = ["realism", "synchronization"]
stimuli = ["s1"]
'''


def test_schedule_prints_a_design_note_as_one_line(tmp_path: Path) -> None:
    """A block asking motion quality and speech together is a note (Nagy et al. 2025); `schedule` (like `run`,
    `bundle`) prints it as ``note: FILE:LINE: ...``, not as Python's warning with a source line under it."""
    design = write_paradigm_study(tmp_path, MIXED, seconds=0.5)
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-m", "studyapp.cli", "schedule", str(design), "--participants", "1"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"note: {design}:"), lines
    assert "motion quality and about speech" in lines[0] and "Warning" not in lines[0]
