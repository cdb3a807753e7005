"""Design-file limits of issue 16, on the shipped demo design edited the way the fuzzer edits it.

Before: arrays nested 100,000 deep and a NUL in a path ended in tracebacks (RecursionError, "embedded null
byte"), and a format specification in a motion pattern (``{stimulus:>99999999}``) made ``validate`` build
100 MB file names. Now each is a problem line naming the file, the line and the key, exit status 1.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from studyapp import tomlfile
from studyapp.study.design import validate_design

REPO = Path(__file__).resolve().parents[2]
DEMO = REPO / "study_designs" / "demo.toml"


def _design(tmp_path: Path, text: str) -> Path:
    os.symlink(REPO / "study_designs" / "demo", tmp_path / "demo")
    path = tmp_path / "design.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _validate_cli(path: Path, *flags: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "studyapp.cli", "validate", *flags, str(path)], capture_output=True,
                          text=True, timeout=120, cwd=REPO)


@pytest.mark.parametrize("value", ["[" * 100_000 + "]" * 100_000, "{a=" * 1000 + "1" + "}" * 1000])
def test_deep_nesting_is_one_syntax_problem(tmp_path, value):
    path = _design(tmp_path, DEMO.read_text(encoding="utf-8") + f"\ndeep = {value}\n")
    line = DEMO.read_text(encoding="utf-8").count("\n") + 2
    [problem] = validate_design(path, check_files=False)
    assert problem.line == line
    opening = [i for i, ch in enumerate(value) if ch in "[{"]
    column = len("deep = ") + opening[tomlfile.MAX_DEPTH] + 1  # the first bracket past the limit
    assert str(problem).startswith(f"{path}:{line}: line {line}, column {column}: TOML syntax error")
    assert f"nest more than {tomlfile.MAX_DEPTH} deep" in str(problem)


def test_nesting_inside_strings_and_comments_does_not_count():
    text = 'a = "' + "[" * 100 + '"  # ' + "{" * 100 + "\nb = '''\n" + "[" * 100 + "\n'''\nc = [[1], [2]]\n"
    assert tomlfile.loads(text)["c"] == [[1], [2]]


def test_a_ten_megabyte_design_is_refused_with_bounded_memory(tmp_path):
    """Fuzz case 3848 (seed 16): a 10 MB line of quotes and brackets took `validate --quick` past 1.5 GB."""
    line = ('x = """' + "[a\\" * 2_500_000)[:10_000_000]
    path = _design(tmp_path, DEMO.read_text(encoding="utf-8") + "\n" + line + "\n")
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30)); "
            "from studyapp.cli import main; sys.exit(main(sys.argv[1:]))")
    proc = subprocess.run([sys.executable, "-c", code, "validate", "--quick", str(path)], capture_output=True,
                          text=True, timeout=120, cwd=REPO)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr + proc.stdout, proc.stderr[-2000:]
    assert f"a TOML file read here has at most {tomlfile.MAX_CHARS:,}" in proc.stdout + proc.stderr


def test_thousands_of_problems_are_placed_in_one_pass(tmp_path):
    """Fuzz case 4244 (seed 16): 10,000 copies of a broken condition made `validate --quick` spend more than
    30 s of CPU finding each problem's line (a scan of every line per problem); now one pass serves all."""
    block = '\n[[conditions]]\nid = "c"\nmotion = "demo/motion/static/{}.bvh"\n'
    path = _design(tmp_path, DEMO.read_text(encoding="utf-8") + block * 10_000)
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_CPU, (20, 20)); "
            "from studyapp.cli import main; sys.exit(main(sys.argv[1:]))")
    proc = subprocess.run([sys.executable, "-c", code, "validate", "--quick", str(path)], capture_output=True,
                          text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 1, proc.stderr[-1500:]
    first = DEMO.read_text(encoding="utf-8").count("\n") + 4  # the motion line of the first copy
    assert f"design.toml:{first}: conditions[3].motion: pattern" in proc.stdout, proc.stdout[:1500]


def test_strings_of_megabytes_are_skipped_in_linear_memory():
    """The bracket scan's string pattern matches runs at once (no per-character backtracking state): a
    3.5 MB string reads within 300 MB of address space (a lazy per-character pattern needed about 400 MB)."""
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (300 << 20, 300 << 20)); "
            "from studyapp import tomlfile; "
            "text = 'a = \"\"\"' + 'x[y' * 1_150_000 + '\"\"\"\\nb = [[1]]\\n'; "
            "assert len(text) < tomlfile.MAX_CHARS; print(tomlfile.loads(text)['b'])")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 0 and proc.stdout.strip() == "[[1]]", proc.stderr[-1500:]


@pytest.mark.parametrize("spec", ["{stimulus:>99999999}", "{stimulus!r}", "{stimulus.__class__}", "{0}"])
def test_a_format_specification_in_a_motion_pattern_is_refused(tmp_path, spec):
    text = DEMO.read_text(encoding="utf-8").replace("synced/{stimulus}.bvh", f"synced/{spec}.bvh")
    path = _design(tmp_path, text)
    proc = _validate_cli(path, "--quick")
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    line = text[: text.index(spec)].count("\n") + 1
    assert proc.stdout.splitlines()[0].startswith(
        f"{path}:{line}: conditions[0].motion: pattern 'demo/motion/synced/{spec}.bvh': placeholder {spec} ")
    assert "only bare names are allowed" in proc.stdout


def test_a_nul_in_a_path_is_refused(tmp_path):
    text = DEMO.read_text(encoding="utf-8").replace('"demo/audio/clip02.wav"', '"demo/audio/clip\\u000002.wav"')
    path = _design(tmp_path, text)
    proc = _validate_cli(path)
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    line = text[: text.index("clip\\u0000")].count("\n") + 1
    assert proc.stdout.splitlines() == [
        f"{path}:{line}: stimuli[1].audio: contains a NUL character (\\u0000), which no file name or text may hold "
        "-- fix: delete it (a damaged file? check the rest of it too)"]


def test_a_deeply_nested_name_map_file_is_one_message(tmp_path):
    """``view --name-map FILE`` reads its TOML through the same reader (it used tomllib directly)."""
    from studyapp.errors import InputError
    from studyapp.study.preview import _name_map_file

    path = tmp_path / "map.toml"
    path.write_text("Hips = " + "[" * 5000 + "]" * 5000 + "\n", encoding="utf-8")
    with pytest.raises(InputError) as err:
        _name_map_file(path)
    assert str(err.value) == (f"{path}: not a TOML name map: arrays and inline tables nest more than "
                              f"{tomlfile.MAX_DEPTH} deep (at line 1, column {len('Hips = ') + tomlfile.MAX_DEPTH + 1})")
