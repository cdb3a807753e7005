"""The paradigm pages in a real browser (headless Chromium, selenium): a block's instructions page, a pairwise
preference answered by clicks with a reason ticked, a rating answered by moving every slider with the
keyboard; what the database holds is what was chosen on the page. Then the experimenter's dashboard, logged
in, shows the completed participant on their row."""
from __future__ import annotations

import json
from pathlib import Path

from fixtures.synthetic import write_synthetic_study
from fixtures.web_serve import CHROME_MISSING, Page, Server, free_port, read_db

pytestmark = CHROME_MISSING
PID = "paradigmsInChromium01"


def _blocks_study(folder: Path) -> Path:
    path = write_synthetic_study(folder, n_stimuli=2, seconds=1.0, practice=False, name="blocks")
    path.write_text(path.read_text() + '''
[[blocks]]
id = "pair"
paradigm = "pairwise"
criteria = ["realism"]
conditions = ["synced", "lagged"]
reasons = ["Hands", "Timing"]
instructions = "Part one: which of the two looks more natural?"

[[blocks]]
id = "rate"
paradigm = "rating"
criteria = ["synchronization"]
conditions = ["lagged", "static"]
anchors = ["Bad", "Good"]
instructions = "Part two: rate each figure."
''')
    return path


def test_pairwise_and_rating_pages_in_chromium(tmp_path, chrome) -> None:
    # Chromium also reports an element redrawn under the driver as "Node with given id does not belong to the
    # document" (a plain WebDriverException): every lookup that polls treats any of them as "not there yet"
    from selenium.common.exceptions import WebDriverException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import WebDriverWait

    from studyapp.study.design import load_design

    design_path = _blocks_study(tmp_path / "study")
    design = load_design(design_path)
    assert [b.paradigm for b in design.trial_blocks] == ["pairwise", "rating"]
    db = tmp_path / "results.sqlite"
    port = free_port()
    server = Server(design_path, db, port, tmp_path / "videos", password="dashboard password 1")
    server.start()
    wait = WebDriverWait(chrome, 20)
    page = Page(chrome, 20)
    heading, click = page.heading, page.click



    def answered() -> int:
        return read_db(db, "SELECT COUNT(*) FROM trials")[0][0]

    def watch() -> None:
        click("#play")
        wait.until(lambda d: "locked" not in d.find_element(By.ID, "panel").get_attribute("class"))

    try:
        chrome.get(f"http://127.0.0.1:{port}/?PROLIFIC_PID={PID}")
        click("#agree")
        wait.until(lambda d: heading() == "Instructions")
        assert "say which figure you prefer" in chrome.find_element(By.TAG_NAME, "main").text
        click("#continue")
        click("#heard")
        wait.until(lambda d: heading() == "The next part")
        assert "Part one" in chrome.find_element(By.TAG_NAME, "main").text
        click("#continue")
        for k in range(2):                             # the pair block's two stimuli
            wait.until(lambda d: d.find_elements(By.ID, "opt-realism-2"))
            watch()
            if k == 0:                                 # by clicks
                click("#opt-realism-2")                # "Clearly B": the right figure
                click("#reason-1")                     # "Timing"
            else:                                      # by keys: 5 = clearly B; Down to the reasons, 2 = Timing
                body = chrome.find_element(By.TAG_NAME, "body")
                for key in ("5", Keys.ARROW_DOWN, "2"):
                    body.send_keys(key)
                assert chrome.find_element(By.ID, "reason-1").is_selected()
            click("#next")
            wait.until(lambda d: answered() == k + 1)
        wait.until(lambda d: heading() == "The next part")
        click("#continue")
        done = answered()
        while heading() != "Study complete":
            wait.until(lambda d: d.find_elements(By.ID, "rate-synchronization-0") or heading() == "Study complete")
            if heading() == "Study complete":
                break
            watch()
            assert not chrome.find_element(By.ID, "next").is_enabled()
            sliders = chrome.find_elements(By.CSS_SELECTOR, "input[type=range]")
            if done == 2:                             # every slider moved: 50 + 10 (i + 1) with its arrow keys
                for i, s in enumerate(sliders):
                    for _ in range(10 * (i + 1)):
                        s.send_keys(Keys.ARROW_RIGHT)
            else:                                     # the number keys jump to the anchors: 2 = "Good" (75),
                body = chrome.find_element(By.TAG_NAME, "body")  # Down = the next slider, 1 = "Bad" (25)
                for key in ("2", Keys.ARROW_DOWN, "1"):
                    body.send_keys(key)
            click("#next")
            wait.until(lambda d: answered() == done + 1)
            done += 1
        # the experimenter's dashboard: log in, one participant completed on its row
        chrome.get(f"http://127.0.0.1:{port}/dashboard")
        chrome.find_element(By.ID, "password").send_keys("dashboard password 1")
        chrome.find_element(By.CSS_SELECTOR, "#login button").click()
        wait.until(lambda d: d.find_elements(By.ID, "rows"))
        totals = {r.find_element(By.TAG_NAME, "th").text: r.find_element(By.TAG_NAME, "td").text
                  for r in chrome.find_elements(By.CSS_SELECTOR, "#totals tr")}
        assert totals["Participants"] == "1" and totals["Completed"] == "1"
        cells = [[td.text for td in tr.find_elements(By.TAG_NAME, "td")]
                 for tr in chrome.find_elements(By.CSS_SELECTOR, "#rows tr")][1:]
        assert cells[0][:2] == ["0", "1"] and all(c[1] == "0" for c in cells[1:])
        assert chrome.find_element(By.ID, "export").get_attribute("href").endswith("/dashboard/export.csv")
    finally:
        server.stop()

    pair = read_db(db, "SELECT slot, value, reasons FROM judgements j JOIN trials t USING (participant, trial_index) "
                       "WHERE t.paradigm = 'pairwise' ORDER BY trial_index, slot")
    assert len(pair) == 4 and all(r[1] == (-2.0 if r[0] == 0 else 2.0) for r in pair)
    assert all(json.loads(r[2]) == ["Timing"] for r in pair)
    rating = read_db(db, "SELECT trial_index, slot, value FROM judgements j JOIN trials t USING (participant, "
                         "trial_index) WHERE t.paradigm = 'rating' ORDER BY trial_index, slot")
    first = min(t for t, _, _ in rating)
    assert [v for t, _, v in rating if t == first] == [60, 70]
    assert [v for t, _, v in rating if t != first] == [75, 25]
    assert read_db(db, "SELECT status FROM participants") == [("done",)]
