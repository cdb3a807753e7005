"""``studyapp metrics`` and ``studyapp plan`` against independent computations.

metrics: a motion frozen for a known stretch gives that share of frozen frames as played; FGD through a
tiny ONNX encoder equals a numpy encoder plus an eigh-based Frechet distance; a wrong encoder is one line.
plan: the power of the participant-level Friedman equals a direct Monte-Carlo written here (sequential
Plackett-Luce draws, scipy's Friedman test), the search finds the N, and everything is reproducible.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from fixtures.synthetic import FPS, bvh_text, write_synthetic_study
from studyapp.cli import main
from studyapp.study.design import load_design
from studyapp.study.metrics import design_metrics, played_joints
from studyapp.study.plan import parse_strengths, plan_study, power_at, rated_conditions
from studyapp.study.stimuli import clear_cache

SECONDS = 4.0


@pytest.fixture()
def study(tmp_path):
    clear_cache()
    path = write_synthetic_study(tmp_path, n_stimuli=2, seconds=SECONDS, practice=False)
    # 'static' on s1: arms turning steadily at 10 deg/s, held from source frame 36 to 72 (1.2 s)
    t = np.arange(int(SECONDS * FPS)) / FPS
    a = 10.0 * t
    a[36:73] = a[36]
    a[73:] = a[36] + 10.0 * (t[73:] - t[72])
    (tmp_path / "motion" / "static" / "s1.bvh").write_text(bvh_text(a))
    yield path
    clear_cache()


def test_frozen_share_as_played_is_the_held_time(study):
    table = design_metrics(load_design(study))
    assert len(table) == 6 and set(table["condition"]) == {"synced", "lagged", "static"}
    row = table[(table.condition == "static") & (table.stimulus == "s1")].iloc[0]
    # played at 60 fps: 1.2 s held = 72 of the 239 frame-to-frame steps of a 4 s trial, plus the last one: the
    # source's last frame (at 119/30 s) is shown until the trial ends at 4 s
    assert row["fps"] == 60.0
    assert row["frozen_share"] == pytest.approx((72 + 1) / 239, abs=1e-12)
    assert (table["n_onsets"] > 0).all()


def _tiny_encoder(path, n_features: int, window: int, n_out: int = 4, seed: int = 0) -> np.ndarray:
    """An ONNX encoder: mean over the window of x @ W, written with onnx.helper; returns W."""
    from onnx import TensorProto, helper, numpy_helper

    w = np.random.default_rng(seed).normal(0, 1, (n_features, n_out)).astype(np.float32)
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["x", "W"], ["h"]),
         helper.make_node("ReduceMean", ["h"], ["z"], axes=[1], keepdims=0)],
        "enc", [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["batch", window, n_features])],
        [helper.make_tensor_value_info("z", TensorProto.FLOAT, ["batch", n_out])],
        [numpy_helper.from_array(w, "W")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    path.write_bytes(model.SerializeToString())
    return w.astype(np.float64)


def _frechet_eigh(a: np.ndarray, b: np.ndarray) -> float:
    def sym_sqrt(s):
        v, q = np.linalg.eigh(s)
        return (q * np.sqrt(np.clip(v, 0, None))) @ q.T
    s1, s2 = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    r = sym_sqrt(s1)
    return float(((a.mean(0) - b.mean(0)) ** 2).sum() + np.trace(s1) + np.trace(s2) - 2 * np.trace(sym_sqrt(r @ s2 @ r)))


def test_fgd_through_an_onnx_encoder_equals_numpy(study, tmp_path):
    from studyapp.models.encoder import MotionEncoder

    design = load_design(study)
    joints = {sid: played_joints(design, sid, ("synced", "lagged", "static"), (1, 1, 1))[0] for sid in ("s1", "s2")}
    n_joints = joints["s1"][0].shape[1]
    window = 30
    w = _tiny_encoder(tmp_path / "enc.onnx", 3 * n_joints, window)
    table = design_metrics(design, encoder=MotionEncoder(tmp_path / "enc.onnx"), fgd_reference="synced")

    def feats(ci):  # windows every 15 frames, root-relative, flattened joint-major; a plain loop
        out = []
        for sid in ("s1", "s2"):
            pos = joints[sid][ci]
            for s in range(0, len(pos) - window + 1, window // 2):
                x = (pos[s:s + window] - pos[s:s + window, :1]).reshape(window, -1)
                out.append((x @ w).mean(axis=0))
        return np.array(out)

    ref = feats(0)
    fgd = table.groupby("condition")["fgd"].first()
    assert fgd["synced"] == 0.0
    for ci, cid in ((1, "lagged"), (2, "static")):
        assert fgd[cid] == pytest.approx(_frechet_eigh(feats(ci), ref), rel=1e-4)
    assert fgd["static"] > fgd["lagged"]  # a still figure is farther from the synced motion than a delayed copy


def test_an_encoder_of_the_wrong_shape_is_one_clear_line(study, tmp_path, capsys):
    _tiny_encoder(tmp_path / "bad.onnx", 10, 30)
    assert main(["metrics", str(study), "--fgd-encoder", str(tmp_path / "bad.onnx")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad.onnx" in err and "expects 10 values per frame" in err and "joints" in err
    assert main(["metrics", str(study), "--fgd-encoder", str(tmp_path / "none.onnx")]) == 2
    assert "model file not found" in capsys.readouterr().err


def test_metrics_command_writes_the_table(study, tmp_path, capsys):
    out = tmp_path / "m.csv"
    assert main(["metrics", str(study), "--out", str(out)]) == 0
    import pandas as pd

    table = pd.read_csv(out)
    assert list(table.columns[:3]) == ["condition", "stimulus", "sample"] and len(table) == 6
    assert "Mean per condition" in capsys.readouterr().out


# --- plan -----------------------------------------------------------------------------------------------


def _direct_power(n: int, m: int, strengths, n_sim: int, alpha: float, seed: int) -> float:
    """Plackett-Luce drawn place by place (rng.choice over the remaining strengths); scipy's Friedman on each
    participant's mean rank per condition."""
    rng = np.random.default_rng(seed)
    s = np.asarray(strengths, float)
    k = len(s)
    hits = 0
    for _ in range(n_sim):
        means = np.zeros((n, k))
        for p in range(n):
            for _ in range(m):
                left = list(range(k))
                for place in range(1, k + 1):
                    w = s[left] / s[left].sum()
                    c = left.pop(int(rng.choice(len(left), p=w)))
                    means[p, c] += place / m
        hits += stats.friedmanchisquare(*means.T).pvalue < alpha
    return hits / n_sim


def test_power_matches_a_direct_monte_carlo(study):
    design = load_design(study)
    m = rated_conditions(design, 1).shape[1]
    assert m == 2
    strengths = [3.0, 1.5, 1.0]
    ours = power_at(design, 10, strengths, n_sim=600, seed=1)
    direct = _direct_power(10, m, strengths, 600, 0.05, seed=2)
    se = np.sqrt(2 * 0.25 / 600)
    assert abs(ours - direct) < 3.5 * se, (ours, direct)
    assert 0.2 < ours < 0.95  # a case where power is neither trivial 0 nor 1
    # equal strengths: the rate of false positives, at most alpha (the test is conservative with ties)
    null = power_at(design, 10, [1.0, 1.0, 1.0], n_sim=600, seed=3)
    assert null < 0.05 + 3 * np.sqrt(0.05 * 0.95 / 600)


def test_plan_finds_n_reports_balance_and_length_and_is_reproducible(study):
    design = load_design(study)
    s = parse_strengths("3,1.5,1", design)
    a = plan_study(design, 12, s, n_sim=200, max_n=64, seed=5)
    b = plan_study(design, 12, s, n_sim=200, max_n=64, seed=5)
    assert (a.power, a.n_for_target, a.curve) == (b.power, b.n_for_target, b.curve)
    n = a.n_for_target
    assert n is not None and a.curve[n] >= 0.8 and a.curve.get(n - 1, 0.0) < 0.8
    assert a.trial_seconds == pytest.approx(2 * SECONDS) and a.n_trials == 2
    assert a.session_seconds == pytest.approx(2 * SECONDS + 2 * 15.0)
    slots = a.balance["slot_x_condition"]
    assert (slots.to_numpy() == 12 * 2 / 3).all()  # 12 participants (2 rows), 2 trials each: 8 per slot
    with pytest.raises(Exception, match="3 conditions"):
        parse_strengths("1,2", design)


def test_plan_command_on_the_demo(capsys):
    from studyapp.resources import demo_design

    assert main(["plan", str(demo_design()), "-n", "12", "--strengths", "2,1.5,1", "--simulations", "100",
                 "--max-n", "16"]) == 0
    out = capsys.readouterr().out
    assert "Power with 12 participants:" in out and "Conditions (rows) x slots (columns):" in out
    assert "Session length: 6 trials" in out
    assert main(["plan", str(demo_design()), "-n", "12", "--strengths", "2,0,1"]) == 2
    assert "--strengths" in capsys.readouterr().err


def test_a_block_design_is_measured_on_the_pairs_it_plays(tmp_path):
    """A design with [[blocks]] has motion files only for the (condition, clip) pairs some trial plays: metrics
    measures exactly those (it opened every condition's file for every clip, and stopped at the first missing
    one), with the same numbers as when every file is there; a clip on which the blocks together play more
    conditions than a trial shows (5 here) is measured too (a scene holds at most 4 figures)."""
    from test_played_pairs import TWO_BLOCKS, TWO_BLOCKS_PLAYS, blocked_study

    clear_cache()
    only = blocked_study(tmp_path / "only", TWO_BLOCKS, seconds=1.0, only_played=True)
    full = blocked_study(tmp_path / "full", TWO_BLOCKS, seconds=1.0)
    got = design_metrics(load_design(only))
    rotation = {"s1", "s2", "s3", "s4"}
    assert sorted(zip(got["condition"], got["stimulus"])) == sorted(
        (c, s) for c, clips in TWO_BLOCKS_PLAYS.items() for s in clips if s in rotation)
    every = design_metrics(load_design(full)).set_index(["condition", "stimulus", "sample"])
    cols = ["beat_align", "l1_diversity_m", "acceleration_m_s2", "jerk_m_s3", "frozen_share"]
    np.testing.assert_allclose(got.set_index(["condition", "stimulus", "sample"])[cols].to_numpy(),
                               every.loc[got.set_index(["condition", "stimulus", "sample"]).index,
                                         cols].to_numpy())

    # five conditions on s1: a rank block of three and a rating block of two more
    five = blocked_study(tmp_path / "five", '''
[[blocks]]
id = "ranked"
paradigm = "rank"
criteria = ["realism"]
conditions = ["synced", "lagged", "static"]
stimuli = ["s1", "s2"]

[[blocks]]
id = "rated"
paradigm = "rating"
criteria = ["realism"]
conditions = ["extra", "extra2"]
stimuli = ["s1"]
''', seconds=1.0)
    import shutil

    shutil.copytree(tmp_path / "five" / "motion" / "lagged", tmp_path / "five" / "motion" / "extra2")
    five.write_text(five.read_text().replace('[slots]', f'[[conditions]]\nid = "extra2"\n'
                                             f'motion = "motion/extra2/{{stimulus}}.bvh"\nfps = {FPS}\n\n[slots]', 1))
    table = design_metrics(load_design(five))
    assert sorted(table.loc[table["stimulus"] == "s1", "condition"]) == sorted(
        ["synced", "lagged", "static", "extra", "extra2"])
    s1 = table[table["stimulus"] == "s1"].set_index("condition")
    assert s1.loc["extra2", "jerk_m_s3"] == pytest.approx(s1.loc["lagged", "jerk_m_s3"])  # the same motion
    clear_cache()


def test_plan_of_a_block_design_tests_the_conditions_its_rank_trials_show(tmp_path):
    """TWO_BLOCKS: a rank block on three conditions and a pairwise block adding a fourth. The fourth has no rank,
    so it sat at mean rank 0 for every participant: with equal strengths the 'power' was about 1 instead of the
    false-positive rate. Now the power is the direct Monte-Carlo's on the three ranked conditions, whatever
    strength the fourth is given, and plan says that strength is not used."""
    from test_played_pairs import TWO_BLOCKS, blocked_study

    design = load_design(blocked_study(tmp_path / "s", TWO_BLOCKS, seconds=0.5), check_files=False)
    assert design.condition_ids == ["synced", "lagged", "static", "extra"]
    m = rated_conditions(design, 1).shape[1]
    null = power_at(design, 10, [1.0, 1.0, 1.0, 1.0], n_sim=400, seed=3)
    assert null < 0.05 + 3 * np.sqrt(0.05 * 0.95 / 400)
    ours = power_at(design, 10, [3.0, 1.5, 1.0, 50.0], n_sim=600, seed=1)
    direct = _direct_power(10, m, [3.0, 1.5, 1.0], 600, 0.05, seed=2)
    assert abs(ours - direct) < 3.5 * np.sqrt(2 * 0.25 / 600), (ours, direct)
    r = plan_study(design, 6, parse_strengths("1,1,1,7", design), n_sim=50, max_n=8)
    assert "extra in no rank block: its strength is not used (other paradigms are not simulated)" in r.notes
    assert any("all strengths are equal" in n for n in r.notes)
