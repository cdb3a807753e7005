"""``studyapp serve`` as a command: a real process renders the missing trial videos through ``studyapp
prerender``'s code, then serves them; a participant's pages and the real MP4 bytes name no condition; the
dashboard takes its password from ``--password-file``; bad arguments get one clear line."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from fixtures.synthetic import write_synthetic_study
from studyapp.cli.serve import dashboard_password
from studyapp.errors import InputError
from studyapp.web.database import open_results

ROOT = Path(__file__).resolve().parents[2]
NAMES = ("FaceCapGes", "DiffSHEG", "CaMN", "Ours (diffusion)")


def _one_clip_study(folder: Path) -> Path:
    """One 1-second stimulus, no practice: 6 slot orders, rendered as one group (seconds)."""
    path = write_synthetic_study(folder, n_stimuli=1, seconds=1.0, practice=False, name="one")
    text = path.read_text()
    for old, new in (("synced", "FaceCapGes"), ("lagged", "DiffSHEG"), ("static", "CaMN")):
        text = text.replace(f'id = "{old}"', f'id = "{new}"')
    text = text.replace('id = "FaceCapGes"', 'id = "FaceCapGes"\nlabel = "Ours (diffusion)"')
    path.write_text(text + '\n[online]\ncompletion_code = "XYZ12345"\n')
    return path


def test_serve_renders_the_videos_then_serves_a_participant(tmp_path) -> None:
    design = _one_clip_study(tmp_path / "study")
    (tmp_path / "pw").write_text("a long enough password\n")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "studyapp.cli", "serve", str(design), "--port", str(port),
                             "--size", "64x48", "--fps", "5", "--password-file", str(tmp_path / "pw")],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    try:
        give_up = time.monotonic() + 90
        while True:
            assert proc.poll() is None, proc.stdout.read().decode()
            try:
                httpx.get(base + "/a/app.css", timeout=1)
                break
            except httpx.TransportError:
                assert time.monotonic() < give_up, "the server did not start"
                time.sleep(0.2)
        videos = sorted((design.parent / "prerendered").glob("*.mp4"))
        assert len(videos) == 6 and all(len(v.stem) == 64 for v in videos)   # content hashes, nothing else
        with httpx.Client(base_url=base) as c:
            entry = c.get("/?PROLIFIC_PID=abc&STUDY_ID=s1&SESSION_ID=x1")
            import json
            import re

            st = json.loads(re.search(r'type="application/json">(.*?)</script>', entry.text, re.S).group(1))
            go = c.post("/start", json={"nonce": st["nonce"], "csrf": st["entry_csrf"], "consent": True,
                                        "params": st["params"]}).json()["go"]
            page = c.get(go).text
            csrf = json.loads(re.search(r'type="application/json">(.*?)</script>', page, re.S).group(1))["csrf"]
            c.post(go + "continue", json={}, headers={"X-CSRF-Token": csrf})
            trial = c.post(go + "sound", json={}, headers={"X-CSRF-Token": csrf}).json()
            mp4 = c.get(trial["video"])
            assert mp4.status_code == 200 and mp4.content[4:8] == b"ftyp" and len(mp4.content) > 1000
            assert mp4.content in [v.read_bytes() for v in videos]
            for blob in (entry.content, page.encode(), json.dumps(trial).encode(), mp4.content):
                for name in NAMES:
                    assert name.lower().encode() not in blob.lower()
            assert c.post("/dashboard/login", json={"password": "a long enough password"}).status_code == 200
            assert c.get("/dashboard/export.csv", timeout=60).status_code == 200   # first use imports pandas
    finally:
        proc.send_signal(signal.SIGTERM)
        out = proc.communicate(timeout=20)[0].decode()
    assert "6 trial videos in" in out and "Serving" in out


def test_the_dashboard_password_comes_from_a_file_or_the_environment(tmp_path, monkeypatch) -> None:
    monkeypatch.delenv("STUDYAPP_SERVE_PASSWORD", raising=False)
    assert dashboard_password(None) is None
    monkeypatch.setenv("STUDYAPP_SERVE_PASSWORD", "from the environment")
    assert dashboard_password(None) == "from the environment"
    f = tmp_path / "pw"
    f.write_text("from a file ok\nsecond line ignored\n")
    assert dashboard_password(f) == "from a file ok"
    f.write_text("short\n")
    with pytest.raises(InputError, match="at least 8 characters"):
        dashboard_password(f)
    with pytest.raises(InputError, match="cannot read the password file"):
        dashboard_password(tmp_path / "missing")


def test_a_database_url_the_server_cannot_use_is_one_clear_line(tmp_path) -> None:
    with pytest.raises(InputError, match="mysql:// is not a database this server can use"):
        open_results("mysql://u@h/db", None)


def test_serve_refuses_a_bad_online_table(tmp_path) -> None:
    design = _one_clip_study(tmp_path / "study")
    design.write_text(design.read_text().replace('completion_code = "XYZ12345"',
                                                 'completion_code = "XYZ12345"\nabandon_after_min = 0\n'
                                                 'completion_url = "ftp://x"\nfoo = 1'))
    r = subprocess.run([sys.executable, "-m", "studyapp.cli", "validate", str(design)], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode != 0
    assert "online.abandon_after_min: must be more than 0 minutes" in r.stdout + r.stderr
    assert "online.completion_url: 'ftp://x' is not a web address" in r.stdout + r.stderr
    assert "online.foo: unknown key 'foo'" in r.stdout + r.stderr


def test_serve_without_the_server_extra_says_what_to_install(monkeypatch, tmp_path) -> None:
    import argparse

    from studyapp.cli.serve import _cmd_serve

    monkeypatch.setitem(sys.modules, "uvicorn", None)     # as on a participant's install
    with pytest.raises(InputError, match=r'pip install "studyapp\[server\]"'):
        _cmd_serve(argparse.Namespace(design=tmp_path / "x.toml"))
