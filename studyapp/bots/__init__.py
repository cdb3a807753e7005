"""Scripted participants: one home for how they answer and for the two ways they take part.

* :mod:`~studyapp.bots.policies`: the answer policies (``random``, ``ordered``, ``careful``) and the per-trial
  random generator, shared by both drivers so a trial is answered alike whichever drives it;
* :mod:`~studyapp.bots.careful`: what a careful viewer perceives in each slot (the ``careful`` policy's scores);
* :mod:`~studyapp.bots.session_driver`: through the real session, no rendering (``run --no-render``);
* :mod:`~studyapp.bots.ui_driver`: through the real participant UI, rendered offscreen (``run --offscreen``).

The package sits above :mod:`studyapp.ui` (it drives the participant's own app), below the shell; the shell
calls :func:`run_bot` only.

>>> POLICIES
('random', 'ordered', 'careful')
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

from studyapp.bots.policies import POLICIES

if TYPE_CHECKING:
    from studyapp.study.design import Design
    from studyapp.study.schedule import TrialPlan
    from studyapp.study.storage import ResultsDB

__all__ = ["POLICIES", "run_bot"]


def run_bot(design: Design, db: ResultsDB, participant_id: str, policy: str, seed: int = 0, *, render: bool,
            out_dir: Path | str | None = None, on_trial: Callable[[TrialPlan], None] | None = None,
            pace_s: float = 0.0, plans: Sequence[TrialPlan] | None = None, n_rows: int | None = None) -> int:
    """Run (or resume) one scripted participant; 0 when the session finished.

    ``render=True`` goes through the participant's UI offscreen (with ``out_dir``, a PNG of every screen is
    written there); ``render=False`` through the session only, fast. ``on_trial(plan)`` (called after each
    committed answer) and ``pace_s`` (seconds spent per clip as if watching it) apply to the latter only.
    ``plans`` and ``n_rows``: a schedule given instead of the design's (a bundle's participant).
    """
    if render:
        # imported here: a session-level pilot never loads the GL and ImGui stack
        from studyapp.bots.ui_driver import run_offscreen_bot

        return int(run_offscreen_bot(design, db, participant_id, policy, seed, out_dir=out_dir, plans=plans,
                                     n_rows=n_rows) or 0)
    from studyapp.bots.session_driver import run_bot_session

    session = run_bot_session(design, db, participant_id, policy, seed, on_trial=on_trial, pace_s=pace_s, plans=plans,
                              n_rows=n_rows)
    return 0 if session.finished else 1
