"""The shipped designs: the demo study, the documented example and the live-model example."""
from __future__ import annotations

import math
import re
import tomllib

import numpy as np
import pytest

from studyapp.bots.careful import careful_scores
from studyapp.resources import demo_design, designs_dir
from studyapp.study import design as D
from studyapp.study.design import load_design, validate_design
from studyapp.study.schedule import n_rows, participant_schedule
from studyapp.study.stimuli import load_trial_media


@pytest.fixture(scope="module")
def demo():
    return load_design(demo_design())


def test_demo_design_is_what_the_demo_needs(demo) -> None:
    assert demo.condition_ids == ["synced", "lagged", "static"]
    assert [s.id for s in demo.stimuli] == ["clip01", "clip02", "clip03", "clip04"]
    assert [s.tags["speaker"] for s in demo.stimuli] == ["spk1", "spk1", "spk2", "spk2"]
    assert all(s.audio.is_file() and s.face is not None and s.face.is_file() for s in demo.stimuli)
    assert demo.ordering == "balanced-latin-square" and demo.slot_assignment == "balanced"
    assert demo.slot_labels == ("A", "B", "C") and demo.practice == ["clip01"]
    assert len(demo.attention_checks) == 1
    likert = [q for q in demo.questionnaire if q.kind == "likert"]
    assert 3 <= len(likert) <= 4 and len({q.scale for q in likert}) == 1
    assert [q.kind for q in demo.questionnaire].count("text") == 1
    assert n_rows(demo) == 12


@pytest.mark.parametrize("name", ["demo.toml", "example_beat.toml", "live_model_example.toml", "smplx_example.toml"])
def test_shipped_designs_validate(name: str) -> None:
    problems = validate_design(designs_dir() / name)
    assert problems == [], "\n".join(map(str, problems))


def test_example_shows_every_key() -> None:
    text = (designs_dir() / "example_beat.toml").read_text()
    from studyapp.study.design.schema import toml_keys

    schemas = {table: toml_keys(cls) for table, cls in D.TABLES.items()}
    missing = [f"{table}.{key}" for table, schema in schemas.items() for key in schema
               if not re.search(rf"^\s*#?\s*\[*(\w+\.)?{key}\b", text, re.M)]
    assert missing == []
    raw = tomllib.loads(text)
    assert {a["kind"] for a in raw["attention_checks"]} == set(D.ATTENTION_KINDS)


def test_live_example_uses_a_live_model() -> None:
    d = load_design(designs_dir() / "live_model_example.toml")
    live = [c for c in d.conditions if c.is_live]
    assert len(live) == 1 and D.model_path(d, live[0]).is_file()


def _order(scores, slots) -> list[str]:
    return [slots[i] for i in np.argsort(scores, kind="stable")[::-1]]


def test_careful_viewer_ranks_the_demo_as_documented(demo) -> None:
    """The expected ranking written in demo.toml, on every trial of two participants' schedules."""
    seen = set()
    for row in (0, 1):
        for plan in participant_schedule(demo, f"P{row}", row):
            media = load_trial_media(demo, plan)
            s = careful_scores(media)
            if plan.is_attention_check:
                frozen = next(i for i, c in enumerate(plan.slots) if c.startswith("frozen:"))
                assert int(np.argmin(s["realism"])) == frozen
                assert demo.attention_checks[0].passed(
                    plan.slots, {"realism": tuple(int(r) for r in 3 - np.argsort(np.argsort(s["realism"])))})
                continue
            assert _order(s["synchronization"], plan.slots) == ["synced", "lagged", "static"], plan
            assert _order(s["diversity"], plan.slots)[-1] == "static", plan
            assert _order(s["realism"], plan.slots) == ["synced", "static", "lagged"], plan
            seen.add(plan.stimulus_id)
    assert seen == {"clip01", "clip02", "clip03", "clip04"}


@pytest.mark.parametrize("module", ["design", "ordering", "schedule", "stimuli"])  # bots.careful: test_docstrings
def test_docstring_examples_run(module: str) -> None:
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(f"studyapp.study.{module}"), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


def test_example_media_carries_per_slot_name_maps() -> None:
    from studyapp.study.schedule import TrialPlan

    d = load_design(designs_dir() / "example_beat.toml")
    media = load_trial_media(d, TrialPlan(0, "clip04", ("model_c", "model_a", "frozen:model_c"), False, True, 0))
    assert media.name_maps == ({"Spine3": "UpperChest"}, {}, {"Spine3": "UpperChest"})
    assert not hasattr(media, "name_map")  # one map for all slots was the trap: each slot has its own
    assert media.duration_s == 8.0  # the example's duration_s
    # every medium is cut to the timeline: 8 s at each medium's own rate
    assert [m.n_frames for m in media.motions] == [math.ceil(8.0 * m.fps) for m in media.motions]
    assert len(media.audio.samples) == round(8.0 * media.audio.sample_rate)
    warm = [p for p in participant_schedule(d, "P1", 0) if p.is_practice]
    assert [p.stimulus_id for p in warm] == ["warmup"]
    assert "warmup" not in [p.stimulus_id for p in participant_schedule(d, "P1", 0) if not p.is_practice]
