"""A real browser takes a Prolific participant through the whole study served by a real server process:
headless Chromium (Debian's ``chromium`` + ``chromium-driver``) driven by selenium. On the way the page is
reloaded mid-clip and the server is killed with SIGKILL and started again; at the end the browser is on the
completion URL and the results database holds every answer exactly once.

The server is ``studyapp serve``'s app (:func:`studyapp.cli.serve.make_app`) with 1-second stand-in videos
(``fixtures.web_serve``); the ranking is done by dragging labels with the pointer on one clip and with the
keyboard on the others. The test knows the right answer to the attention check the way the experimenter does:
from the participant's schedule, never from the page.
"""
from __future__ import annotations

import time

from fixtures.web_serve import CHROME_MISSING, Page, Server, free_port, read_db as _read
from fixtures.web_study import COMPLETION_CODE, write_web_study
from studyapp.study.design import load_design
from studyapp.study.schedule import participant_schedule

PID = "60b1browser0000000000001"

pytestmark = CHROME_MISSING


def test_a_participant_completes_the_study_in_chromium_through_a_reload_and_a_server_kill(tmp_path, chrome) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    # Chromium also reports an element redrawn under the driver as "Node with given id does not belong to the
    # document" (a plain WebDriverException): every lookup that polls treats any of them as "not there yet"
    from selenium.common.exceptions import WebDriverException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import WebDriverWait

    port = free_port()
    complete = f"http://127.0.0.1:{port}/complete?cc={COMPLETION_CODE}"
    design_path = write_web_study(tmp_path / "study", completion_url=complete)
    design = load_design(design_path)
    db = tmp_path / "results.sqlite"
    server = Server(design_path, db, port, tmp_path / "videos")
    server.start()
    wait = WebDriverWait(chrome, 20)
    page = Page(chrome, 20)
    heading, click = page.heading, page.click

    def find(css: str):
        return wait.until(lambda d: d.find_element(By.CSS_SELECTOR, css))



    def answered() -> list[int]:
        return [r[0] for r in _read(db, "SELECT trial_index FROM trials WHERE participant = ? ORDER BY trial_index", PID)]

    def current_plan():
        row = _read(db, "SELECT latin_row FROM participants WHERE id = ?", PID)[0][0]
        done = set(answered())
        return next(p for p in participant_schedule(design, PID, row) if p.trial_index not in done)

    def best_first(plan) -> list[int]:
        worst = design.attention_checks[0].expected["condition"]
        return sorted(range(3), key=lambda s: plan.slots[s] == worst)     # the known-worst figure last

    def watch() -> None:
        click("#play")
        wait.until(lambda d: "locked" not in d.find_element(By.ID, "panel").get_attribute("class"))

    def rank_by_keyboard(order: list[int]) -> None:
        body = chrome.find_element(By.TAG_NAME, "body")
        for _ in design.criteria:          # a full question moves on to the next one
            for slot in order:
                body.send_keys(str(slot + 1))

    def rank_three_ways(order: list[int]) -> None:
        """First question by dragging labels into boxes, second by clicking labels, third by number keys."""
        first, second, third = (c.id for c in design.criteria)
        for box, slot in enumerate(reversed(order)):       # dragged worst first, each into its own box
            chip = chrome.find_element(By.ID, f"chip-{first}-{slot}")
            target = chrome.find_element(By.ID, f"box-{first}-{2 - box}")
            ActionChains(chrome).drag_and_drop(chip, target).perform()
        for slot in order:
            click(f"#chip-{second}-{slot}")
        body = chrome.find_element(By.TAG_NAME, "body")
        body.send_keys(Keys.ARROW_DOWN)
        for slot in order:
            body.send_keys(str(slot + 1))
        for c in (first, second, third):
            labels = [chrome.find_element(By.ID, f"box-{c}-{b}").find_element(By.TAG_NAME, "strong").text
                      for b in range(3)]
            assert labels == [design.slot_labels[s] for s in order], c

    def next_clip(n_before: int) -> None:
        click("#next")
        wait.until(lambda d: len(answered()) == n_before + 1)

    started = time.monotonic()
    try:
        chrome.get(f"http://127.0.0.1:{port}/?PROLIFIC_PID={PID}&STUDY_ID=st42&SESSION_ID=se42")
        assert heading() == "Welcome"
        click("#agree")
        wait.until(lambda d: heading() == "Instructions")
        click("#continue")
        wait.until(lambda d: heading() == "Sound check")
        click("#tone")
        click("#heard")
        wait.until(lambda d: heading() == "Practice clip 1 of 1")

        # practice: ranked by dragging, by clicking and by keyboard
        watch()
        rank_three_ways(best_first(current_plan()))
        next_clip(0)
        wait.until(lambda d: heading() == "Clip 1 of 3")

        # clip 1: the page is reloaded while the clip plays; it must be watched again before ranking
        click("#play")
        chrome.refresh()
        wait.until(lambda d: heading() == "Clip 1 of 3")
        assert "locked" in find("#panel").get_attribute("class") and not find("#next").is_enabled()
        watch()
        rank_by_keyboard(best_first(current_plan()))
        next_clip(1)
        wait.until(lambda d: heading() == "Clip 2 of 3")

        # the server is killed mid-session and started again: nothing answered is lost, the page continues
        before = answered()
        server.kill()
        assert answered() == before == [0, 1]
        server.start()
        chrome.refresh()          # the session lived in the database, not the server: the page just continues
        wait.until(lambda d: heading() == "Clip 2 of 3")
        for k in (2, 3):
            wait.until(lambda d: heading() == f"Clip {k} of 3")
            watch()
            rank_by_keyboard(best_first(current_plan()))
            chrome.find_element(By.TAG_NAME, "body").send_keys("\n")     # Enter: next clip
            wait.until(lambda d: len(answered()) == k + 1)

        wait.until(lambda d: heading() == "A few last questions")
        click("#q-q1-6")
        click("#q-q2-5")
        click("#q-device-2")
        click("#q-langs-1")
        click("#q-langs-3")
        find("#q-age").send_keys("34")
        find("#q-comments").send_keys("Looked fine.")
        click("#submit")
        wait.until(lambda d: heading() == "Study complete")
        assert COMPLETION_CODE in find("#code").text
        wait.until(lambda d: d.current_url == complete)     # Prolific's completion redirect
    except Exception:
        print(chrome.page_source[-3000:], chrome.get_log("browser") if hasattr(chrome, "get_log") else "")
        raise
    finally:
        server.stop()
    assert time.monotonic() - started < 60

    assert _read(db, "SELECT status FROM participants") == [("done",)]
    assert answered() == [0, 1, 2, 3]
    n_crit = len(design.criteria)
    assert _read(db, "SELECT COUNT(*), COUNT(DISTINCT trial_index) FROM responses") == [(4 * 3 * n_crit, 4)]
    assert _read(db, "SELECT attention_passed FROM trials WHERE is_attention_check = 1") == [(1,)]
    q = dict(_read(db, "SELECT item, value FROM questionnaire"))
    assert q == {"q1": "6", "q2": "5", "device": "Desktop", "langs": '["English", "Chinese"]', "age": "34",
                 "comments": "Looked fine."}
    machines = [m for (m,) in _read(db, "SELECT machine FROM sessions ORDER BY id")]
    # one session: the server's restart did not start another (nothing of it was in the server's memory)
    assert len(machines) == 1 and all('"frontend": "browser"' in m for m in machines)
    assert '"prolific_study_id": "st42"' in machines[0] and '"prolific_session_id": "se42"' in machines[0]
    # the reload left one play unfinished on clip 1; every answered clip had a complete play
    plays = _read(db, "SELECT trial_index, completed FROM plays ORDER BY id")
    assert (1, 0) in plays and {t for t, c in plays if c} == {0, 1, 2, 3}
