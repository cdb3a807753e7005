"""Blinding of bundles, tested as an attacker would: unzip the bundle and try to group one model's files.

The truth (which file is which condition on which clip) is computed independently from the key, which stays
with the experimenter; then every attribute a participant can read in the zip -- file names and their
fragments, zip entry fields and order, tag names, the order of tags and conditions, the conditions' keys,
the trial lists, the BVH headers -- is checked not to single out one condition across two or more clips.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import zipfile
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable, Hashable

import pandas as pd
import pytest

from studyapp import tomlfile
from studyapp.bots.session_driver import run_bot_session
from studyapp.resources import designs_dir
from studyapp.study.bundle import make_bundle, merge_results
from studyapp.study.design import load_design
from studyapp.study.export import export_dataframe
from studyapp.study.schedule import participant_schedule
from studyapp.study.storage import ResultsDB
from fixtures.synthetic import write_synthetic_study

CLI = [sys.executable, "-m", "studyapp.cli"]


@pytest.fixture(scope="module")
def demo_bundle(tmp_path_factory) -> dict[str, Any]:
    root = tmp_path_factory.mktemp("blind")
    shutil.copytree(designs_dir() / "demo", root / "demo")
    shutil.copy(designs_dir() / "demo.toml", root / "demo.toml")
    design = load_design(root / "demo.toml")
    info = make_bundle(root / "demo.toml", root / "send" / "study.zip", participants=6,
                       results=root / "demo.results.sqlite")
    zf = zipfile.ZipFile(info.path)
    return {"root": root, "design": design, "info": info, "zip": zf,
            "study": tomlfile.loads(zf.read("study.toml").decode("utf-8")),
            "schedule": json.loads(zf.read("schedule.json")), "manifest": json.loads(zf.read("manifest.json"))}


def _occurrences(b: dict[str, Any]) -> list[dict[str, Any]]:
    """Every motion a shipped trial plays, with the truth from the key and what the zip shows about it."""
    key = b["info"].key
    study = b["study"]
    conditions = {c["id"]: c for c in study["conditions"]}
    infos = {i.filename: i for i in b["zip"].infolist()}
    order = [i.filename for i in b["zip"].infolist()]
    out = []
    for s in study["stimuli"]:
        truth = key["trials"][s["id"]]
        for tok, cond in conditions.items():
            name = cond["motion"].replace("{" + tok + "}", s["tags"][tok])
            data = b["zip"].read(name)
            info = infos[name]
            out.append({
                # the truth, from the key only
                "condition": truth["conditions"][tok], "clip": truth["stimulus"],
                # what a participant can read
                "name": name, "token": tok, "tag key": tok,
                "tag position": list(s["tags"]).index(tok),
                "condition position": list(conditions).index(tok),
                "condition keys": tuple(sorted((k, str(v)) for k, v in cond.items() if k not in ("id", "motion"))),
                "zip fields": (info.date_time, info.compress_type, info.external_attr, info.extra, info.comment,
                               info.create_system, info.flag_bits),
                "zip position": order.index(name),
                "manifest position": list(b["manifest"]["files"]).index(name),
                "bvh header": data.split(b"MOTION")[0],
                "frame time": [ln for ln in data.splitlines() if ln.startswith(b"Frame Time")][0],
            })
    return out


def _groups_a_condition(occ: list[dict[str, Any]], attr: Callable[[dict[str, Any]], Hashable],
                        min_clips: int = 2) -> list[Any]:
    """Values of ``attr`` that pick files of one condition only, on ``min_clips`` or more different clips."""
    seen: dict[Hashable, set[tuple[str, str]]] = defaultdict(set)
    for o in occ:
        seen[attr(o)].add((o["condition"], o["clip"]))
    return [v for v, pairs in seen.items()
            if len({c for c, _ in pairs}) == 1 and len({clip for _, clip in pairs}) >= min_clips]


def test_no_shipped_attribute_groups_one_models_files_across_clips(demo_bundle) -> None:
    occ = _occurrences(demo_bundle)
    design = demo_bundle["design"]
    assert {o["condition"] for o in occ} == {c.id for c in design.conditions}
    assert len({o["clip"] for o in occ}) == len(design.stimuli)
    for attr in ("name", "token", "tag key", "tag position", "condition position", "condition keys", "zip fields",
                 "zip position", "manifest position", "bvh header", "frame time"):
        assert not _groups_a_condition(occ, lambda o: o[attr]), attr
    # name fragments: no 4 characters common to all of one condition's file names
    for cond in {o["condition"] for o in occ}:
        stems = {Path(o["name"]).stem[2:] for o in occ if o["condition"] == cond}
        assert len(stems) >= 2
        assert not set.intersection(*({s[i:i + 4] for i in range(len(s) - 3)} for s in stems)), cond
        # Names are random per bundle, so two of one model's names share some 4 hex characters by chance now
        # and then (one fresh-clone run met 'aa03'; 15 % of simulated bundles of 30 random names), three
        # names in none of 2,000: a fragment counts as grouping from three clips on.
        for fragment in {s[i:i + 4] for s in stems for i in range(len(s) - 3)}:
            assert not _groups_a_condition(occ, lambda o: fragment in o["name"], min_clips=3), (cond, fragment)
    # tokens mean nothing across trials: each token stands for every condition somewhere
    for tok in {o["token"] for o in occ}:
        assert {o["condition"] for o in occ if o["token"] == tok} == {c.id for c in design.conditions}, tok
    # the conditions differ in nothing but their token: same keys, same values
    conds = demo_bundle["study"]["conditions"]
    assert len({tuple(sorted(k for k in c)) for c in conds}) == 1
    assert len({json.dumps({k: v for k, v in c.items() if k != "id"}).replace(c["id"], "T") for c in conds}) == 1


def test_shipped_design_carries_no_schedule_inputs_and_no_real_ids(demo_bundle) -> None:
    study, design = demo_bundle["study"], demo_bundle["design"]
    for gone in ("seed", "ordering", "slot_assignment", "practice"):
        assert gone not in study, gone
    text = demo_bundle["zip"].read("study.toml").decode() + json.dumps(demo_bundle["schedule"]) + \
        json.dumps(demo_bundle["manifest"])
    for secret in [c.id for c in design.conditions] + [s.id for s in design.stimuli] + [s.audio.name for s in design.stimuli]:
        assert secret not in text, secret
    assert [s["id"] for s in study["stimuli"]] == sorted(s["id"] for s in study["stimuli"])  # no schedule order
    # one shipped stimulus per participant and trial, and the trial lists are the real schedules
    key = demo_bundle["info"].key
    for pid, mine in demo_bundle["schedule"]["participants"].items():
        real = participant_schedule(design, pid, mine["row"])
        assert len(mine["trials"]) == len(real)
        for plan, (sid, slots, practice, check) in zip(real, mine["trials"]):
            t = key["trials"][sid]
            assert (t["participant"], t["trial_index"], t["stimulus"]) == (pid, plan.trial_index, plan.stimulus_id)
            shown = tuple(("frozen:" if s.startswith("frozen:") else "") + t["conditions"][s.removeprefix("frozen:")]
                          for s in slots)
            assert shown == plan.slots and (practice, check) == (plan.is_practice, plan.is_attention_check)
            assert tuple(t["samples"][s.removeprefix("frozen:")] for s in slots) == plan.samples
    assert len({sid for m in demo_bundle["schedule"]["participants"].values() for sid, *_ in m["trials"]}) == \
        sum(len(m["trials"]) for m in demo_bundle["schedule"]["participants"].values())


def test_every_shipped_motion_is_the_labs_file_for_its_clip_and_condition(demo_bundle, tmp_path: Path) -> None:
    from studyapp.study.design import motion_path

    design = demo_bundle["design"]
    names = set()
    for o in _occurrences(demo_bundle):
        assert demo_bundle["zip"].read(o["name"]) == motion_path(design, o["condition"], o["clip"]).read_bytes()
        names.add(o["name"])
    # each (clip, condition) file is in the zip once, however many participants see it
    assert len(names) == len(design.stimuli) * len(design.conditions)


def test_remote_round_trip_gives_the_rows_of_a_lab_session(tmp_path: Path) -> None:
    """bundle -> `studyapp run STUDY.zip` with a bot -> results zip -> merge -> export: the same rows as the
    same participant, row and bot give in the lab (the random bot ranks slots, whatever they show)."""
    clip_s = 0.3
    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=4, seconds=clip_s, attention_check=True,
                                        questionnaire=True)
    design = load_design(design_path)
    results = design_path.with_name("tiny.results.sqlite")
    out = subprocess.run([*CLI, "bundle", str(design_path), "-o", str(tmp_path / "send" / "study.zip"),
                          "--participants", "3"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    home = tmp_path / "participant"
    home.mkdir()
    env = {**__import__("os").environ, "HOME": str(home), "XDG_CACHE_HOME": str(home / ".cache"),
           "XDG_DATA_HOME": str(home / ".local/share"), "STUDYAPP_RESULTS_DIR": str(home / "out")}
    run = subprocess.run([*CLI, "run", str(tmp_path / "send" / "study.zip"), "--participant", "R02", "--no-render",
                          "--bot", "random", "--seed", "5", "--bot-pace", str(clip_s)],
                         capture_output=True, text=True, timeout=600, env=env, cwd=home)
    assert run.returncode == 0, run.stderr
    [returned] = (home / "out").glob("results-*.zip")
    refused = subprocess.run([*CLI, "run", str(tmp_path / "send" / "study.zip"), "--participant", "ME", "--no-render",
                              "--bot", "random"], capture_output=True, text=True, timeout=600, env=env, cwd=home)
    assert refused.returncode == 2 and "not one of the participant ids" in refused.stderr, refused.stderr
    assert "cannot be read" not in refused.stderr and "schedule.json" not in refused.stderr, refused.stderr
    reports = merge_results(results, [returned])
    assert reports[0].ok, reports[0].problems
    remote = export_dataframe(results)

    lab_db = ResultsDB(tmp_path / "lab.sqlite", design)
    row = json.loads(zipfile.ZipFile(tmp_path / "send" / "study.zip").read("manifest.json"))["roster"]["R02"]
    run_bot_session(design, lab_db, "R02", "random", 5, row=row)
    lab_db.close()
    lab = export_dataframe(tmp_path / "lab.sqlite")
    cols = ["participant", "trial_index", "stimulus", "criterion", "condition", "slot", "rank", "sample",
            "is_practice", "is_attention_check", "attention_passed", "design_hash"]
    pd.testing.assert_frame_equal(remote[cols].sort_values(cols[:6]).reset_index(drop=True),
                                  lab[cols].sort_values(cols[:6]).reset_index(drop=True))
    assert len(remote) == len(participant_schedule(design, "R02", row)) * 3 * len(design.criteria)
