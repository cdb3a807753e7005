"""The README's first Quick-start command, offscreen: ``studyapp demo --offscreen --out DIR`` in a real process.

It must leave a still, a video, screenshots, a results database holding the demo participant and the
scripted panel, and an analysis whose mean ranks show what the demo's three synthetic models were built
to show (synced best synchronized; lagged and synced alike in diversity, static worst; realism disagreeing
with diversity: the quiet static figure above the mistimed lagged one).
"""
from __future__ import annotations

import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest


@pytest.mark.timeout(600)
def test_offscreen_demo_writes_everything_and_the_expected_ranking(tmp_path: Path) -> None:
    out = tmp_path / "demo-out"
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    run = subprocess.run([sys.executable, "-m", "studyapp.cli", "demo", "--offscreen", "--out", str(out)],
                         capture_output=True, text=True, env=env, timeout=580)
    assert run.returncode == 0, run.stderr[-2000:]

    summary = json.loads((out / "demo-summary.json").read_text())
    assert summary["participants"] == 13
    # the database is left as one file, and every participant finished
    assert sorted(p.name for p in out.glob("demo.results.sqlite*")) == ["demo.results.sqlite"]
    con = sqlite3.connect(f"file:{out / 'demo.results.sqlite'}?mode=ro", uri=True)
    try:
        status = dict(con.execute("SELECT id, status FROM participants").fetchall())
    finally:
        con.close()
    assert len(status) == 13 and set(status.values()) == {"done"} and "demo" in status

    from PIL import Image

    still = np.asarray(Image.open(out / "first_trial.png").convert("RGB"), dtype=np.int16)
    assert still.shape == (720, 1280, 3)
    # three figures: each third of the frame has pixels far from its background
    for third in np.array_split(still, 3, axis=1):
        background = np.median(third.reshape(-1, 3), axis=0)
        assert (np.abs(third - background).max(axis=2) > 60).mean() > 0.01
    assert (out / "first_trial.mp4").stat().st_size > 10_000
    # the short video: 1280x720 picture with sound, and the sound no longer than the picture (~4 s)
    import av

    with av.open(str(out / "first_trial.mp4")) as c:
        v = c.streams.video[0]
        assert (v.codec_context.width, v.codec_context.height) == (1280, 720)
        n_video = sum(1 for _ in c.decode(video=0))
    with av.open(str(out / "first_trial.mp4")) as c:
        a = c.streams.audio[0]
        audio_s = sum(f.samples for f in c.decode(audio=0)) / a.rate
    video_s = n_video / 30.0
    assert 3.0 <= video_s <= 4.05, video_s
    assert abs(audio_s - video_s) < 0.15, (audio_s, video_s)
    assert len(list((out / "screens").glob("*.png"))) >= 5

    stats = json.loads((out / "analysis" / "stats.json").read_text())
    for criterion in ("realism", "synchronization", "diversity"):
        assert stats[criterion]["block"] == "participant" and stats[criterion]["n_blocks"] == 13
        assert stats[criterion]["p"] < 0.001, (criterion, stats[criterion]["p"])
    for criterion in ("synchronization", "diversity"):
        ranks = stats[criterion]["mean_rank"]
        assert ranks["static"] == max(ranks.values()), (criterion, ranks)
    sync = stats["synchronization"]["mean_rank"]
    assert sync["synced"] < sync["lagged"] < sync["static"], sync
    # The criteria disagree: a quiet figure is plausible but not diverse, gestures 300 ms late are diverse
    # but look dubbed. The report's realism and diversity orders differ.
    real, div = stats["realism"]["mean_rank"], stats["diversity"]["mean_rank"]
    assert real["synced"] < real["static"] < real["lagged"], real
    assert sorted(real, key=real.get) != sorted(div, key=div.get), (real, div)
    report = (out / "analysis" / "report.html").read_text()
    assert "Friedman" in report
