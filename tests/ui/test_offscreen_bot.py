"""The scripted participant goes through the real session and UI code offscreen (EGL)."""
import numpy as np
import pytest

from studyapp.ui.bot import UIBot

pytestmark = pytest.mark.gl


def _expected_ranks(design, db, pid, policy, seed):
    """What the policy chooses for each trial, computed without the UI."""
    from studyapp.study.bots import choose_ranking, trial_rng
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
