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


