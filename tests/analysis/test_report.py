"""The written analysis: stats.json numbers vs scipy, tables, figures (pixels), self-contained HTML, CLI."""
from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pandas as pd
import pytest
from scipy import stats

from results_analysis import analyze, simulate_results
from results_analysis.cli import main

STRENGTHS = {"realism": [6.0, 1.5, 1.0], "synchronization": [5.0, 1.0, 1.0], "diversity": [1.0, 1.0, 1.0]}


@pytest.fixture(scope="module")
def study() -> pd.DataFrame:
    # FaceCapGes clearly best on realism and synchronization; no difference on diversity.
    return simulate_results(24, 8, strengths=STRENGTHS, fail_attention=["P07"], seed=5)


@pytest.fixture(scope="module")
def written(study: pd.DataFrame, tmp_path_factory) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("analysis")
    a = analyze(study, out, title="Test study", block="trial", groups=["speaker", "device"], exclude_failed_attention=True,
                conover=True, n_boot=400, seed=1)
    return out, a


def test_stats_json_matches_scipy_on_the_same_blocks(study: pd.DataFrame, written) -> None:
    out, _ = written
    s = json.loads((out / "stats.json").read_text())
    rated = study[~study.is_practice & ~study.is_attention_check & (study.participant != "P07")]
    for crit in ("realism", "synchronization", "diversity"):
        wide = rated[rated.criterion == crit].pivot(index=["participant", "trial_index"], columns="condition",
                                                    values="rank")
        ref = stats.friedmanchisquare(*wide.to_numpy().T)
        e = s[crit]
        assert e["n_blocks"] == len(wide) == 23 * 8 and e["k"] == 3 and e["df"] == 2
        assert e["chi2"] == pytest.approx(ref.statistic) and e["p"] == pytest.approx(ref.pvalue)
        assert e["kendall_w"] == pytest.approx(ref.statistic / (len(wide) * 2))
        n = len(wide)
        f = (n - 1) * ref.statistic / (n * 2 - ref.statistic)
        assert e["iman_davenport_f"] == pytest.approx(f)
        assert e["iman_davenport_p"] == pytest.approx(stats.f.sf(f, 2, 2 * (n - 1)))
        assert e["mean_rank"] == pytest.approx(wide.mean().to_dict())
        assert e["critical_difference"] == pytest.approx(
            stats.studentized_range.ppf(0.95, 3, np.inf) / np.sqrt(2) * np.sqrt(3 * 4 / (6 * n)))
        assert set(e["posthoc"]) == {"nemenyi", "wilcoxon_holm", "conover"}
        for row in e["posthoc"]["wilcoxon_holm"]:
            assert {"a", "b", "statistic", "p", "p_adjusted"} <= set(row)
    assert s["realism"]["p"] < 1e-6 and s["diversity"]["p"] > 0.001
    assert s["realism"]["mean_rank"]["FaceCapGes"] < 1.6
    assert s["_meta"]["excluded"] == [{"participant": "P07", "reason": "failed 1 of 1 attention check(s)"}]


def test_tables_written(written) -> None:
    out, a = written
    names = {p.name for p in (out / "tables").iterdir()}
    assert names >= {"friedman.csv", "conditions.csv", "posthoc_nemenyi.csv", "posthoc_wilcoxon_holm.csv",
                     "posthoc_conover.csv", "bradley_terry.csv", "exclusions.csv", "by_speaker.csv", "by_device.csv"}
    by = pd.read_csv(out / "tables" / "by_speaker.csv")
    assert sorted(by["level"].unique()) == ["speaker1", "speaker2", "speaker3", "speaker4"]
    # every speaker has 2 clips: 23 participants x 2 trials per level and criterion
    assert (by["n_blocks"] == 46).all()
    cond = pd.read_csv(out / "tables" / "conditions.csv")
    shares = cond[[c for c in cond.columns if c.startswith("share_rank_")]].sum(axis=1)
    assert shares.to_numpy() == pytest.approx(np.ones(len(cond)))


def test_figures_are_real_images(written) -> None:
    out, _ = written
    for name in ("rank_shares", "critical_difference", "mean_ranks", "bradley_terry"):
        png = mpimg.imread(out / "figures" / f"{name}.png")
        assert png.shape[0] > 300 and png.shape[1] > 800, name
        assert (out / "figures" / f"{name}.svg").read_text().lstrip().startswith("<?xml")
        # not blank: a good share of non-white pixels
        assert (png[..., :3].mean(axis=2) < 0.9).mean() > 0.01, name
    bars = mpimg.imread(out / "figures" / "rank_shares.png")[..., :3]
    # the darkest rank-1 blue of the stacked bars is present
    dark_blue = (np.abs(bars - np.array([0.03, 0.27, 0.58])) < 0.08).all(axis=2)
    assert dark_blue.sum() > 2000
    cd = mpimg.imread(out / "figures" / "critical_difference.png")[..., :3]
    red = (np.abs(cd - np.array([0xb2, 0x18, 0x2b]) / 255) < 0.1).all(axis=2)
    assert red.sum() > 50  # the CD scale bar


def test_report_reads_like_a_results_section(written) -> None:
    out, a = written
    md = (out / "report.md").read_text()
    fr = a.criteria["realism"].friedman
    assert f"χ²(2) = {fr.chi2:.2f}, p < .001, Kendall's W = {fr.kendall_w:.2f}" in md
    assert "Nemenyi post-hoc tests (critical difference CD =" in md
    assert "Holm" in md and "normal approximation" in md and "continuity" in md
    assert "P07 (failed 1 of 1 attention check(s))" in md
    assert "did not show a significant difference" in md  # diversity has no effect
    for fig in ("rank_shares", "critical_difference", "mean_ranks"):
        assert f"figures/{fig}.png" in md


def test_html_is_self_contained(written) -> None:
    out, _ = written
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 4
    assert not re.search(r'src="(?!data:)', html) and "<link" not in html
    assert "<table>" in html and "χ²(2)" in html


def test_cli_end_to_end(tmp_path: Path, study: pd.DataFrame, capsys) -> None:
    csv = tmp_path / "results.csv"
    study.to_csv(csv, index=False)
    q = tmp_path / "q.csv"
    rng = np.random.default_rng(0)
    rows = [(p, f"q{i}", "presence", int(np.clip(round(3 + rng.normal()), 1, 5)))
            for p in study.participant.unique() for i in range(4)]
    pd.DataFrame(rows, columns=["participant", "item", "scale", "value"]).to_csv(q, index=False)
    code = main([str(csv), "--out", str(tmp_path / "out"), "--block", "participant", "--group", "device",
                 "--questionnaire", str(q), "--exclude", "P01,P02", "--bootstrap", "200"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "realism: chi2(2) =" in printed and "P01 (excluded by name" in printed
    s = json.loads((tmp_path / "out" / "stats.json").read_text())
    assert s["realism"]["block"] == "participant" and s["realism"]["n_blocks"] == 22
    assert s["realism"]["sensitivity"]["block"] == "trial"
    assert (tmp_path / "out" / "tables" / "questionnaire_reliability.csv").exists()
    assert "Cronbach" in (tmp_path / "out" / "report.md").read_text()


def test_cli_reports_bad_input_with_exit_code_2(tmp_path: Path, study: pd.DataFrame, capsys) -> None:
    bad = study.copy()
    bad.loc[3, "rank"] = 0
    csv = tmp_path / "bad.csv"
    bad.to_csv(csv, index=False)
    assert main([str(csv), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"error: {csv}: line 5, column 'rank': rank 0 is outside 1..3" in err
    assert main([str(csv), "--out", str(tmp_path / "o"), "--group", "nope"]) == 2


def test_cli_missing_columns_lists_only_the_users_columns(tmp_path: Path, capsys) -> None:
    csv = tmp_path / "short.csv"
    csv.write_text("participant,trial_index,stimulus,criterion,condition,score\nP1,0,clip1,realism,A,1\n")
    assert main([str(csv), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: {csv}: column(s) rank: missing required column(s); "
                   "found: participant, trial_index, stimulus, criterion, condition, score\n")
    assert "_where" not in err and not (tmp_path / "o").exists()


def test_console_script_is_installed(tmp_path: Path) -> None:
    exe = Path(sys.executable).with_name("results-analysis")
    if not exe.exists():
        pytest.skip("console script not installed in this environment")
    r = subprocess.run([str(exe), "--help"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "--block" in r.stdout and "--exclude-failed-attention" in r.stdout


def test_edge_cases_two_conditions_and_complete_ties(tmp_path: Path) -> None:
    two = simulate_results(8, 3, conditions=["A", "B"], strengths=[3.0, 1.0], seed=2)
    a = analyze(two, tmp_path / "two", block="trial", n_boot=100)
    rated = two[~two.is_practice & ~two.is_attention_check & (two.criterion == "realism")]
    wide = rated.pivot(index=["participant", "trial_index"], columns="condition", values="rank")
    # k = 2: Friedman's chi2 equals the squared sign-test z (no ties possible within a block)
    wins = int((wide["A"] < wide["B"]).sum())
    n = len(wide)
    assert a.criteria["realism"].friedman.chi2 == pytest.approx((2 * wins - n) ** 2 / n)
    tied = simulate_results(5, 2, seed=3)
    tied["rank"] = 1.0
    t = analyze(tied, tmp_path / "tied", n_boot=50).criteria["realism"]
    assert t.friedman.chi2 == 0.0 and t.friedman.p == 1.0
    assert (t.posthoc["wilcoxon_holm"]["p"] == 1.0).all()
    assert t.bradley_terry["strength"].to_numpy() == pytest.approx(np.full(3, 1 / 3))
    assert json.loads((tmp_path / "tied" / "stats.json").read_text())["realism"]["chi2"] == 0.0


def test_package_never_imports_studyapp(tmp_path: Path) -> None:
    code = ("import sys; sys.modules['studyapp'] = None\n"
            "from results_analysis import analyze, simulate_results\n"
            f"analyze(simulate_results(4, 2, seed=1), {str(tmp_path / 'o')!r}, n_boot=20)\n"
            "assert not any(m == 'studyapp' or m.startswith('studyapp.') for m in sys.modules if sys.modules[m])\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "o" / "report.html").exists()


def test_report_names_the_pairs_where_post_hoc_tests_disagree(written) -> None:
    out, a = written
    paras = (out / "report.md").read_text().split("\n\n")
    s = json.loads((out / "stats.json").read_text())
    for crit in a.criteria:
        # the post-hoc paragraph follows the criterion's opening paragraph
        post = paras[next(i for i, p in enumerate(paras) if p.startswith(f"**{crit}.**")) + 1]
        nem = {(r["a"], r["b"]): r["significant"] for r in s[crit]["posthoc"]["nemenyi"]}
        wil = {(r["a"], r["b"]): r["p_adjusted"] < 0.05 for r in s[crit]["posthoc"]["wilcoxon_holm"]}
        differ = [f"{x} vs {y} (significant only with {'Wilcoxon' if wil[(x, y)] else 'Nemenyi'})"
                  for (x, y) in nem if nem[(x, y)] != wil[(x, y)]]
        expected = ("led to the same conclusions" if not differ
                    else "agreed with the Nemenyi tests except for " + " and ".join(differ))
        assert expected in post, crit
    table3 = next(p for p in paras if p.startswith("| criterion | pair |"))
    for line in table3.splitlines()[2:]:
        v = line.split(" | ")[4]
        assert float(v) * 2 == int(float(v) * 2) and not v.endswith(".000"), line  # a rank sum, as printed by R


# Rankings of (ours, sixdnet, baseline), 6 participants x 3 trials: with only rank differences of 1 and 2 the
# Wilcoxon signed ranks are tied averages, and here every V is a half-integer (ours vs sixdnet: V = 31.5).
HALF_V_RANKINGS = "132 213 123 213 123 123 123 231 231 231 123 123 123 312 132 132 123 231".split()


def _half_v_study() -> pd.DataFrame:
    rows = [{"participant": f"P{i // 3 + 1}", "trial_index": i % 3, "stimulus": f"clip{i % 3 + 1}",
             "criterion": "realism", "condition": cond, "rank": float(r)}
            for i, ranking in enumerate(HALF_V_RANKINGS) for cond, r in zip(("ours", "sixdnet", "baseline"), ranking)]
    return pd.DataFrame(rows)


def _md_table(md: str, header_start: str) -> list[dict[str, str]]:
    block = next(p for p in md.split("\n\n") if p.startswith(header_start))
    lines = block.splitlines()
    head = [c.strip() for c in lines[0].strip("|").split("|")]
    return [dict(zip(head, (c.strip() for c in line.strip("|").split(" | ")))) for line in lines[2:]]


def test_prose_and_tables_print_the_same_numbers(tmp_path: Path) -> None:
    df = _half_v_study()
    wide = df.pivot(index=["participant", "trial_index"], columns="condition", values="rank")
    v_ref, _ = stats.wilcoxon(wide["ours"], wide["sixdnet"], zero_method="wilcox", correction=True)
    d = (wide["ours"] - wide["sixdnet"]).to_numpy()
    d = d[d != 0]
    v_ours_six = stats.rankdata(np.abs(d))[d > 0].sum()  # R's V: sum of the ranks of positive differences
    assert v_ours_six == 31.5 and min(v_ours_six, len(d) * (len(d) + 1) / 2 - v_ours_six) == v_ref
    a = analyze(df, tmp_path, title="Half ranks", block="trial", n_boot=50, seed=0)
    md = (tmp_path / "report.md").read_text()
    html = (tmp_path / "report.html").read_text()
    c = a.criteria["realism"]
    wil = c.posthoc["wilcoxon_holm"].set_index(["a", "b"])
    assert (wil["statistic"] % 1 == 0.5).all()  # the data really exercise half-integer V
    prose = next(p for p in md.split("\n\n") if p.startswith("Nemenyi post-hoc") or p.startswith("For completeness"))
    t3 = {tuple(r["pair"].split(" – ")): r for r in _md_table(md, "| criterion | pair |")}
    assert t3[("ours", "sixdnet")]["Wilcoxon V"] == "31.5"
    assert "ours vs sixdnet: V = 31.5, " in prose and "ours vs sixdnet: V = 31.5, " in html
    for (x, y), r in t3.items():
        # the very string of the table cell appears in the sentence about the same pair
        assert f"{x} vs {y}: V = {r['Wilcoxon V']}, r_rb = {r['r_rb']}, p_adj " in prose, (x, y)
        assert f"(difference {r['Δ mean rank']}, " in prose, (x, y)
        cell = r["Nemenyi p_adj"]
        assert (f"p_adj {cell})" if cell.startswith("<") else f"p_adj = {cell})") in prose, (x, y)
    opening = next(p for p in md.split("\n\n") if p.startswith("**realism.**"))  # no label: the id
    (t1,) = _md_table(md, "| criterion | n | χ² |")
    assert f"χ²({t1['df']}) = {t1['χ²']}, " in opening and f"Kendall's W = {t1['W']} " in opening
    assert f") = {t1['F_ID']}, " in opening and f"CD = {t1['CD']} at α = .05" in prose
    assert t1["χ²"] == f"{c.friedman.chi2:.2f}"  # two decimals in both places, not 3 in the table
    for r in _md_table(md, "| criterion | condition |"):
        assert f"{r['condition']} {r['mean rank']} (95% CI {r['95% CI']}; ranked first in {r['rank 1']})" in opening


def test_cli_title_comes_from_the_results_database(tmp_path: Path, study: pd.DataFrame) -> None:
    storage = pytest.importorskip("studyapp.study.storage")  # the tests may use studyapp; the package never does
    from types import SimpleNamespace

    conditions = sorted(study.condition.unique())
    design = SimpleNamespace(design_hash="h", title="Gesture realism\nstudy 2026", stimuli=[],
                             conditions=[SimpleNamespace(id=c) for c in conditions])
    db_path = tmp_path / "study.results.sqlite"
    db = storage.ResultsDB(db_path, design)
    rated = study[~study.is_practice & ~study.is_attention_check & study.participant.isin(["P01", "P02", "P03"])]
    for pid in ("P01", "P02", "P03"):
        db.add_participant(pid, n_rows=1)
        for t, trial in rated[rated.participant == pid].groupby("trial_index"):
            db.save_trial(storage.TrialRecord(
                participant=pid, trial_index=int(t), stimulus=str(trial.stimulus.iloc[0]), is_practice=False,
                is_attention_check=False, slots=tuple(conditions), answered_at="2026-01-01T00:00:00", plays=1,
                response_time_s=1.0, attention_passed=None),
                [storage.Response(r.criterion, r.condition, conditions.index(r.condition), float(r.rank))
                 for r in trial.itertuples()])
    db.close()

    def heading(out: str, *extra: str) -> str:
        assert main([str(db_path), "--out", str(tmp_path / out), "--bootstrap", "20", *extra]) == 0
        md = (tmp_path / out / "report.md").read_text()
        html = (tmp_path / out / "report.html").read_text()
        first = md.splitlines()[0]
        assert f"<h1>{first[2:]}</h1>" in html and f"<title>{first[2:]}</title>" in html
        return first

    # the stored title (one line: a heading cannot hold a newline), not the file name
    assert heading("stored") == "# Gesture realism study 2026"
    assert heading("given", "--title", "Mine") == "# Mine"  # --title still wins
    # an untitled study (studyapp stores '') falls back to the file name, as does a CSV export
    with storage.ResultsDB(db_path) as rdb, rdb.transaction() as con:  # through studyapp: the row stays sealed
        con.execute("UPDATE study SET title = ''")
    assert heading("untitled") == "# Results: study.results.sqlite"
    csv = tmp_path / "export.csv"
    rated.to_csv(csv, index=False)
    assert main([str(csv), "--out", str(tmp_path / "csv"), "--bootstrap", "20"]) == 0
    assert (tmp_path / "csv" / "report.md").read_text().startswith("# Results: export.csv\n")


def test_disagreeing_post_hoc_tests_are_named_in_words(tmp_path: Path) -> None:
    """On the half-V data the Wilcoxon test separates ours from sixdnet while Nemenyi does not: the report
    must say so in the exact words a reader sees, not only when the tests agree."""
    df = _half_v_study()
    a = analyze(df, tmp_path, title="Half ranks", block="trial", n_boot=50, seed=0)
    c = a.criteria["realism"]
    nem = c.posthoc["nemenyi"].set_index(["a", "b"])["significant"]
    wil = c.posthoc["wilcoxon_holm"].set_index(["a", "b"])["p_adjusted"] < 0.05
    assert not nem[("ours", "sixdnet")] and wil[("ours", "sixdnet")]  # the data really disagree there
    md = (tmp_path / "report.md").read_text()
    assert "agreed with the Nemenyi tests except for ours vs sixdnet (significant only with Wilcoxon)" in md
