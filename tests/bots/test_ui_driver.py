"""The scripted participant goes through the real session and UI code offscreen (EGL)."""
import numpy as np
import pytest

from studyapp.bots.ui_driver import UIBot

pytestmark = pytest.mark.gl


def _expected_ranks(design, db, pid, policy, seed):
    """What the policy chooses for each trial, computed without the UI."""
    from studyapp.bots.policies import choose_ranking, trial_rng
    from studyapp.study.stimuli import load_trial_media

    out = {}
    for t in db.trials(pid):
        plan = next(p for p in _plans(design, db, pid) if p.trial_index == t["trial_index"])
        media = load_trial_media(design, plan) if policy == "careful" else None
        ranks = choose_ranking(policy, plan, media, design.criteria, trial_rng(seed, pid, plan.trial_index),
                               condition_order=[c.id for c in design.conditions])
        out[plan.trial_index] = ranks
    return out


def _plans(design, db, pid):
    from studyapp.study.schedule import participant_schedule

    return participant_schedule(design, pid, db.participant(pid).latin_row)


def scene_blobs(img, top, bottom):
    """For each third of the view between rows top and bottom: does it hold a figure (dark pixels on the
    light background)? The background gradient is light grey; figures have dark trousers and hair."""
    view = img[top:bottom].astype(int)
    dark = view.sum(axis=2) < 250
    w = view.shape[1]
    thirds = [dark[:, k * w // 3:(k + 1) * w // 3] for k in range(3)]
    return [int(t.sum()) for t in thirds], dark


@pytest.mark.parametrize("policy", ["ordered"])  # deterministic choices, known in advance
def test_bot_completes_study_through_ui(tiny_study, tmp_path, policy, secrets_of):
    design, db = tiny_study
    bot = UIBot(design, db, "P1", policy, 5, out_dir=tmp_path / "shots")
    try:
        assert bot.run() == 0
        drawn = set(bot.app.ui.drawn)
    finally:
        bot.close()
    rec = db.participant("P1")
    assert rec.status == "done"
    trials = db.trials("P1")
    assert len(trials) == len(_plans(design, db, "P1")) == 3  # 1 practice + 2 clips
    # every trial's ranks are exactly what the policy chose: drag (1st question), clicks (2nd), keys (3rd)
    expected = _expected_ranks(design, db, "P1", policy, 5)
    got = {}
    for r in db.responses("P1"):
        got.setdefault(r["trial_index"], {}).setdefault(r["criterion"], {})[r["slot"]] = r["rank"]
    assert got == {k: {c: {s: float(v) for s, v in d.items()} for c, d in e.items()} for k, e in expected.items()}
    # frame statistics recorded per trial; the virtual clock has no A/V offset
    for t in trials:
        assert t["frames_shown"] >= 5 and t["refresh_hz"] == pytest.approx(60.0)
        assert t["worst_av_offset_ms"] == pytest.approx(0.0, abs=1e-6)
        assert t["plays"] == 1
    assert len(db.questionnaire("P1")) == 3
    # nothing the participant saw names a condition
    leaks = [(sec, s) for sec, s in _leaks(drawn, secrets_of(design))]
    assert leaks == []
    # a screenshot of every screen
    names = sorted(p.name for p in (tmp_path / "shots").glob("*.png"))
    for screen in ("welcome", "instructions", "env_check", "practice_ready", "practice_playing",
                   "practice_ranking", "trials_ranked", "questionnaire", "done"):
        assert any(screen in n for n in names), (screen, names)
    _check_trial_pixels(tmp_path / "shots")


def _load_rgb(path):
    import matplotlib.image as mimage

    img = mimage.imread(path)[..., :3]
    return (img * 255).astype(np.uint8) if img.dtype != np.uint8 else img


def _check_trial_pixels(folder):
    playing = _load_rgb(next(folder.glob("*_trials_playing.png")))
    h = playing.shape[0]
    counts, _ = scene_blobs(playing, int(0.1 * h), int(0.85 * h))
    assert all(c > 500 for c in counts), counts  # a figure in each third
    ranking = _load_rgb(next(folder.glob("*_trials_ranking.png")))
    # the ranking panel (dark UI) fills the lower part; the figures are still visible above it
    lower = ranking[int(0.6 * h):].astype(int).sum(axis=2)
    assert np.median(lower) < 200
    counts, _ = scene_blobs(ranking, int(0.08 * h), int(0.45 * h))
    assert all(c > 100 for c in counts), counts


def _leaks(drawn, secrets):
    from studyapp.ui.widgets import Painter

    p = Painter()
    for s in drawn:
        p.record(s)
    return p.leaks(secrets)




def test_focus_loss_and_space_pause_playback(tiny_study):
    from imgui_bundle import imgui

    design, db = tiny_study
    bot = UIBot(design, db, "P3", "random", 1)
    try:
        for _ in range(200):
            bot.frame()
            key = bot.app.screen_key()
            if key == "practice:ready":
                break
            bot.steps.popleft()() if bot.steps else bot._plan(key)
        assert bot.app.screen_key() == "practice:ready"
        bot.app.input.tap(imgui.Key.space)          # Space starts the clip...
        for _ in range(3):
            bot.frame()
        view = bot.app.trial_view()
        assert view.state == "playing"
        bot.app.input.focus(False)                  # ...losing the window focus pauses it
        bot.frame()
        assert view.state == "paused" and bot.clock.paused
        t = bot.clock.position_s()
        for _ in range(5):
            bot.frame()
        assert bot.clock.position_s() == t          # nothing moves while paused
        bot.app.input.focus(True)
        bot.app.input.tap(imgui.Key.space)          # Space resumes
        for _ in range(3):
            bot.frame()
        assert view.state == "playing" and bot.clock.position_s() > t
        assert not view.ranking_open()              # the answers stay closed until the clip ends
    finally:
        bot.close()


def test_whole_study_with_the_keyboard_only(tiny_study):
    """Enter / Space / digits / arrows only: every screen can be operated without a mouse."""
    from imgui_bundle import imgui

    from studyapp.ui.input import digit_key

    design, db = tiny_study
    bot = UIBot(design, db, "K1", "random", 1)
    q = bot.app.input
    K = imgui.Key

    def run(n=3):
        for _ in range(n):
            bot.frame()

    def press(key, n=3):
        q.tap(key)
        run(n)

    try:
        run(2)
        for screen in ("welcome", "instructions"):
            assert bot.app.screen_key() == screen
            press(K.enter)
        run(3)  # the environment check measures, then waits for Enter
        assert bot.app.screen_key() == "env_check"
        press(K.enter)
        orders = {}
        for _ in range(len(bot.session.plans)):
            for _ in range(50):
                if bot.app.screen_key().endswith(":ready"):
                    break
                bot.frame()
            press(K.space)  # play
            for _ in range(50):
                if bot.app.screen_key().endswith(":ranking"):
                    break
                bot.frame()
            plan = bot.session.current_trial()
            order = [(plan.trial_index + k) % 3 for k in range(3)]  # a different order per trial
            orders[plan.trial_index] = order
            for _crit in design.criteria:  # the highlight moves on when a question is complete
                for slot in order:
                    press(digit_key(slot + 1), 2)
            assert bot.app.screen_key().endswith(":ranked")
            press(K.enter, 4)
        assert bot.app.screen_key() == "questionnaire"
        press(digit_key(5))                 # first item is selected: 5
        press(K.down_arrow)
        press(digit_key(2))
        press(K.down_arrow)                 # the text item takes the keyboard
        q.type_text("fine")
        run(3)
        press(K.enter)                      # leaves the text box
        press(K.enter, 4)                   # submits
        assert bot.session.finished
    finally:
        bot.close()
    ranks = {}
    for r in db.responses("K1"):
        ranks.setdefault(r["trial_index"], {}).setdefault(r["criterion"], {})[r["slot"]] = r["rank"]
    for trial, order in orders.items():
        for crit in design.criteria:
            assert [ranks[trial][crit.id][s] for s in order] == [1, 2, 3]
    answers = {a["item"]: a for a in db.questionnaire("K1")}
    assert answers["q1"]["value"] in (5, "5") and answers["q2"]["value"] in (2, "2")
    assert "fine" in str(answers["comments"]["value"])


# -- ties (designs with [playback] allow_ties) ------------------------------------------------------------

def _stored_ranks(db, pid):
    out = {}
    for r in db.responses(pid):
        out.setdefault(r["trial_index"], {}).setdefault(r["criterion"], {})[r["slot"]] = r["rank"]
    return out


def test_bot_enters_ties_through_ui_and_they_are_stored(tied_study, tmp_path, secrets_of):
    """Ties chosen by the policy go in by drag + link click, click + link click and "=" on the keyboard."""
    from studyapp.bots.policies import choose_ranking, trial_rng
    from studyapp.study.session import normalise_ranks
    from studyapp.ui.screens.instructions import HOW_TO_TIE
    from studyapp.ui.screens.ranking_panel import TIE_HINT

    design, db = tied_study
    seed = 4  # its draws tie on every question (so every entry method enters a tie) and leave some strict
    bot = UIBot(design, db, "T1", "random", seed, out_dir=tmp_path / "shots")
    try:
        assert bot.run() == 0
        plans = list(bot.session.plans)
        drawn = set(bot.app.ui.drawn)
    finally:
        bot.close()
    crits = [c.id for c in design.criteria]
    chosen = {p.trial_index: choose_ranking("random", p, None, design.criteria,
                                            trial_rng(seed, "T1", p.trial_index), allow_ties=True)
              for p in plans}
    for ci, crit in enumerate(crits):  # 0: drag, 1: click, 2: keyboard
        tied = [t for t, r in chosen.items() if len(set(r[crit].values())) < 3]
        assert tied, f"seed {seed} gives no tie on question {ci}: the test would not test that entry method"
    assert any(len(set(r[c].values())) == 3 for r in chosen.values() for c in crits)
    expected = {t: {c: dict(enumerate(v)) for c, v in normalise_ranks(r, crits, True).items()}
                for t, r in chosen.items()}
    assert _stored_ranks(db, "T1") == expected
    assert db.participant("T1").status == "done"
    assert HOW_TO_TIE in drawn and any(TIE_HINT in s for s in drawn)
    assert list(_leaks(drawn, secrets_of(design))) == []


def _to_screen(bot, target, limit=400):
    """Let the scripted participant click through until ``target`` is on screen; nothing queued after."""
    for _ in range(limit):
        bot.frame()
        key = bot.app.screen_key()
        if key == target:
            bot.steps.clear()
            return
        bot.steps.popleft()() if bot.steps else bot._plan(key)
    raise AssertionError(f"never reached {target!r} (on {bot.app.screen_key()!r})")


def _type(bot, keys):
    """Digits place the left / middle / right figure, "=" is typed as text (as GLFW delivers it)."""
    from studyapp.ui.input import digit_key

    for k in keys:
        if k == "=":
            bot.app.input.char("=")
        else:
            bot.app.input.tap(digit_key(int(k)))
        for _ in range(2):
            bot.frame()


def _pixel(rgb, rect, fx, fy):
    x0, y0, x1, y1 = rect
    return rgb[int(y0 + (y1 - y0) * fy), int(x0 + (x1 - x0) * fx)].astype(int)


def test_keyboard_ties_are_visible_and_stored(tied_study):
    from imgui_bundle import imgui

    from studyapp.ui.screens.ranking_panel import TIE_COLOR

    design, db = tied_study
    crits = [c.id for c in design.criteria]
    bot = UIBot(design, db, "K1", "random", 1)
    try:
        _to_screen(bot, "practice:ranking")
        _type(bot, "1=23")       # left = middle, best; right last
        _type(bot, "31=2")       # right best; left = middle after it
        _type(bot, "1=2=3")      # all equal
        bot.frame()
        assert bot.app.screen_key() == "practice:ranked"
        r = bot.app.trial_view().ranking
        assert r.ties == {crits[0]: [True, False], crits[1]: [False, True], crits[2]: [True, True]}
        # what the participant sees: the captions name the shared rank, tied links are amber "=" buttons
        shown = bot.app.ui.frame_strings
        assert shown.count("1st (tied)") == 5 and shown.count("2nd (tied)") == 2 and "3rd (worst)" in shown
        rgb = bot.screenshot("tied")
        amber = np.array(TIE_COLOR[:3]) * 255
        rects = bot.app.ui.rects
        for crit, ties in r.ties.items():
            for link, tied in enumerate(ties):
                px = _pixel(rgb, rects[("tie", crit, link)], 0.2, 0.15)  # beside the sign, on the button
                assert (np.abs(px - amber).max() < 25) == tied, (crit, link, px)
            for place in range(3):  # tied boxes have an amber outline
                px = _pixel(rgb, rects[("place", crit, place)], 0.5, 0.0)
                assert (np.abs(px - amber).max() < 40) == r.is_tied(crit, place), (crit, place, px)
        bot.app.input.tap(imgui.Key.enter)
        for _ in range(4):
            bot.frame()
    finally:
        bot.close()
    stored = _stored_ranks(db, "K1")
    assert len(stored) == 1
    (ranks,) = stored.values()
    assert ranks == {crits[0]: {0: 1.5, 1: 1.5, 2: 3.0}, crits[1]: {0: 2.5, 1: 2.5, 2: 1.0},
                     crits[2]: {0: 2.0, 1: 2.0, 2: 2.0}}


def test_equals_does_nothing_when_the_design_does_not_allow_ties(tiny_study):
    design, db = tiny_study
    crit = design.criteria[0].id
    bot = UIBot(design, db, "K2", "random", 1)
    try:
        _to_screen(bot, "practice:ranking")
        _type(bot, "1=23")
        bot.frame()
        r = bot.app.trial_view().ranking
        assert r.ranks()[crit] == {0: 1, 1: 2, 2: 3} and r.ties[crit] == [False, False]
        assert not any(isinstance(k, tuple) and k[0] == "tie" for k in bot.app.ui.rects)
        assert not any("tied" in s for s in bot.app.ui.drawn)
        assert "3rd (worst)" in bot.app.ui.frame_strings
    finally:
        bot.close()


def test_fast_typing_with_key_rollover_ties_the_right_figures(tied_study):
    """ "1", then "=" and "2" typed so fast that 2 goes down before = comes up: both land in one frame,
    and the tie must still join the first two places (1 = 2), as typed."""
    from imgui_bundle import imgui

    from studyapp.ui.input import digit_key

    design, db = tied_study
    crit = design.criteria[-1].id
    seen = {}

    class Typist(UIBot):
        def _plan_trial(self, key):
            sub = key.split(":")[1] if ":" in key else ""
            if sub != "ranking" or self._planned_for is not None:
                return super()._plan_trial(key)
            self._planned_for = -1
            q = self.app.input
            self.click(("crit", crit))
            self.steps.append(lambda: (q.key(digit_key(1), True), q.char("1"), q.key(digit_key(1), False)))
            self.wait(3)
            self.steps.append(lambda: (q.key(imgui.Key.equal, True), q.char("="), q.key(digit_key(2), True),
                                       q.char("2"), q.key(imgui.Key.equal, False), q.key(digit_key(2), False)))
            self.wait(12)

            def done():
                r = self.app.trial_view().ranking
                seen["order"], seen["ties"] = list(r.order[crit]), list(r.ties[crit])
                self.app.quit = True

            self.steps.append(done)

    bot = Typist(design, db, "R1", "ordered", 1)
    try:
        bot.run()
    finally:
        bot.close()
    assert seen == {"order": [0, 1, None], "ties": [True, False]}


def test_bot_ranks_only_the_questions_of_its_rank_block(tmp_path):
    """A rank block that asks one criterion (realism, then a mismatch block for speech: Nagy et al.'s separate
    blocks): the offscreen bot answers the questions on screen, the block's, and finishes the study."""
    from fixtures.paradigm_studies import write_paradigm_study
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB

    blocks = '''
[[blocks]]
id = "real"
paradigm = "rank"
criteria = ["realism"]
stimuli = ["s1"]

[[blocks]]
id = "fit"
paradigm = "mismatch"
criteria = ["synchronization"]
conditions = ["FaceCapGes"]
stimuli = ["s2", "s4"]
'''
    design = load_design(write_paradigm_study(tmp_path, blocks, seconds=1.0))
    db = ResultsDB(tmp_path / "r.sqlite", design)
    bot = UIBot(design, db, "P1", "careful", 3)
    try:
        assert bot.run() == 0
    finally:
        bot.close()
    assert db.participant("P1").status == "done"
    assert {(r["trial_index"], r["criterion"]) for r in db.responses("P1")} == {(0, "realism")}
