"""Issue 19's "done when", as a participant meets it: ``studyapp serve`` on the demo design, a real process that
pre-renders the demo's trial videos with the desktop's renderer (no stand-ins), and headless Chromium taking a
Prolific participant through the whole demo to the completion redirect.

The design is the shipped ``demo.toml`` with its own files, copied to a temporary folder with two changes that
keep the test short: every clip plays its first 2 s (the stimulus key ``duration_s``) and the completion URL
points at the test server (the real one leads to Prolific). Videos are rendered small (160x90, 10 fps: about
10 s on one core). On the way: each trial's ``<video>`` has loaded the served MP4 (its length is the clip's) and
decoded its sound track; an answer before the clip was watched is refused; the first trial is ranked by
dragging, the rest with the number keys; the page is reloaded mid-clip and the clip must be watched again.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

from fixtures.web_serve import CHROME_MISSING, Page, ROOT, free_port, read_db

pytestmark = CHROME_MISSING
PID = "5f1c0ffee0d3m0000000c0de"
CLIP_S = 2.0


def _short_demo(folder: Path, completion_url: str) -> Path:
    from studyapp.resources import demo_design

    shutil.copytree(demo_design().parent / "demo", folder / "demo")
    text = demo_design().read_text(encoding="utf-8")
    text, n = re.subn(r"(\ntags = \{ speaker)", f"\nduration_s = {CLIP_S}\\1", text)
    assert n == 4, "the demo's four stimuli"
    assert "https://app.prolific.com/submissions/complete?cc=DEMO1234" in text
    text = text.replace("https://app.prolific.com/submissions/complete?cc=DEMO1234", completion_url)
    path = folder / "demo.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _serve(design: Path, port: int, log: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with open(log, "wb") as out:
        proc = subprocess.Popen([sys.executable, "-m", "studyapp.cli", "serve", str(design), "--port", str(port),
                                 "--size", "160x90", "--fps", "10"], env=env, stdout=out, stderr=subprocess.STDOUT)
    give_up = time.monotonic() + 300          # the pre-rendering comes first
    while True:
        assert proc.poll() is None, log.read_text()[-3000:]
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/a/app.css", timeout=1).read()
            return proc
        except OSError:
            assert time.monotonic() < give_up, "the server did not start: " + log.read_text()[-3000:]
            time.sleep(0.3)


def test_the_demo_served_with_its_prerendered_videos_to_a_prolific_participant_in_chromium(tmp_path, chrome) -> None:
    import av
    # Chromium also reports an element redrawn under the driver as "Node with given id does not belong to the
    # document" (a plain WebDriverException): every lookup that polls treats any of them as "not there yet"
    from selenium.common.exceptions import WebDriverException
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    from studyapp.study.design import FROZEN_PREFIX, load_design
    from studyapp.study.schedule import participant_schedule

    port = free_port()
    complete = f"http://127.0.0.1:{port}/complete?cc=DEMO1234"
    design_path = _short_demo(tmp_path / "study", complete)
    design = load_design(design_path)
    db = design_path.with_name("demo.results.sqlite")          # serve's default: next to the design
    proc = _serve(design_path, port, tmp_path / "serve.log")

    # what `serve` pre-rendered: every trial of the demo, H.264 with the speech as an AAC track, CLIP_S long
    videos = sorted((design_path.parent / "prerendered").glob("*.mp4"))
    assert len(videos) == 30
    with av.open(str(videos[0])) as mp4:
        assert [s.type for s in mp4.streams] == ["video", "audio"]
        assert (mp4.streams.video[0].codec_context.name, mp4.streams.audio[0].codec_context.name) == ("h264", "aac")
        assert abs(mp4.duration / 1e6 - CLIP_S) < 0.2

    wait = WebDriverWait(chrome, 30)
    page = Page(chrome, 30)
    heading, click = page.heading, page.click



    def answered() -> list[int]:
        return [r[0] for r in read_db(db, "SELECT trial_index FROM trials WHERE participant = ? ORDER BY trial_index", PID)]

    def best_first() -> list[int]:
        """Slots best first, as a careful viewer ranks them: the frozen figure of the attention check last
        (the test knows which one it is from the schedule, as the experimenter does; never from the page)."""
        row = read_db(db, "SELECT latin_row FROM participants WHERE id = ?", PID)[0][0]
        done = set(answered())
        plan = next(p for p in participant_schedule(design, PID, row) if p.trial_index not in done)
        return sorted(range(3), key=lambda s: plan.slots[s].startswith(FROZEN_PREFIX))

    def video(prop: str):
        return chrome.execute_script(f"return document.getElementById('video').{prop};")

    def answer_before_watching() -> int:
        """An answer posted the way the page posts it, before the clip was watched: the server's status."""
        return chrome.execute_async_script(
            "var done = arguments[0], S = JSON.parse(document.getElementById('state').textContent);"
            "fetch(S.base + 'answer', {method: 'POST', headers: {'Content-Type': 'application/json',"
            " 'X-CSRF-Token': S.csrf}, body: JSON.stringify({ranks: {}})}).then(function (r) { done(r.status); });")

    def watch() -> None:
        wait.until(lambda d: video("readyState") >= 1)          # the served MP4's header is loaded
        assert abs(video("duration") - CLIP_S) < 0.2
        assert "locked" in chrome.find_element(By.ID, "panel").get_attribute("class")
        click("#play")
        wait.until(lambda d: "locked" not in d.find_element(By.ID, "panel").get_attribute("class"))
        assert video("webkitAudioDecodedByteCount") > 0 and video("webkitVideoDecodedByteCount") > 0

    def rank_by_drag(order: list[int]) -> None:
        for c in design.criteria:
            for box, slot in enumerate(reversed(order)):       # worst first, each into its own box
                chip = chrome.find_element(By.ID, f"chip-{c.id}-{slot}")
                ActionChains(chrome).drag_and_drop(chip, chrome.find_element(By.ID, f"box-{c.id}-{2 - box}")).perform()
            labels = [chrome.find_element(By.ID, f"box-{c.id}-{b}").find_element(By.TAG_NAME, "strong").text
                      for b in range(3)]
            assert labels == [design.slot_labels[s] for s in order], c.id

    def rank_by_keys(order: list[int]) -> None:
        body = chrome.find_element(By.TAG_NAME, "body")
        for _ in design.criteria:
            for slot in order:
                body.send_keys(str(slot + 1))

    def next_clip() -> None:
        n = len(answered())
        click("#next")
        wait.until(lambda d: len(answered()) == n + 1)

    try:
        chrome.get(f"http://127.0.0.1:{port}/?PROLIFIC_PID={PID}&STUDY_ID=demoStudy&SESSION_ID=demoSession")
        assert heading() == "Welcome"
        click("#agree")
        wait.until(lambda d: heading() == "Instructions")
        click("#continue")
        wait.until(lambda d: heading() == "Sound check")
        click("#heard")
        wait.until(lambda d: heading() == "Practice clip 1 of 1")
        assert answer_before_watching() == 422
        watch()
        assert chrome.find_element(By.ID, "hint").text.endswith("or press 1 = A, 2 = B, 3 = C.")
        rank_by_drag(best_first())
        next_clip()
        wait.until(lambda d: heading() == "Clip 1 of 5")
        click("#play")                                          # reloaded while the clip plays
        chrome.refresh()
        wait.until(lambda d: heading() == "Clip 1 of 5")
        assert not chrome.find_element(By.ID, "next").is_enabled()
        assert answer_before_watching() == 422                  # that play did not count
        watch()
        rank_by_keys(best_first())
        next_clip()
        for k in (2, 3, 4, 5):
            wait.until(lambda d: heading() == f"Clip {k} of 5")
            watch()
            rank_by_keys(best_first())
            next_clip()
        wait.until(lambda d: heading() == "A few last questions")
        for q in ("clear", "differences", "confident"):
            click(f"#q-{q}-6")
        click("#submit")
        wait.until(lambda d: heading() == "Study complete")
        assert "DEMO1234" in chrome.find_element(By.ID, "code").text
        wait.until(lambda d: d.current_url == complete)          # the completion redirect
    except Exception:
        print(chrome.page_source[-3000:])
        raise
    finally:
        proc.terminate()
        proc.wait(20)

    assert read_db(db, "SELECT status FROM participants") == [("done",)]
    assert answered() == [0, 1, 2, 3, 4, 5]
    assert read_db(db, "SELECT attention_passed FROM trials WHERE is_attention_check = 1") == [(1,)]
    assert read_db(db, "SELECT COUNT(*) FROM responses") == [(6 * 3 * len(design.criteria),)]
    plays = read_db(db, "SELECT trial_index, completed FROM plays ORDER BY id")
    assert (1, 0) in plays and {t for t, c in plays if c} == set(range(6))
    (machine,) = read_db(db, "SELECT machine FROM sessions")[0]
    assert '"prolific_study_id": "demoStudy"' in machine and '"prolific_session_id": "demoSession"' in machine
