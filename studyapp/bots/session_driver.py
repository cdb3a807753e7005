"""A scripted participant at the session level: the real :class:`~studyapp.study.session.Session`, no rendering.

What ``studyapp run --no-render --bot P`` and the demo's simulated panel use: fast (no frames), yet each
trial's scene is built by the participant's own scene builder (on the CPU), every answer goes through the
same session methods and storage as a participant's, and is chosen by the same policy as the offscreen
participant's (:mod:`studyapp.bots.policies`): a ranking, a preference or ratings, by the trial's
paradigm, on its block's questions (:func:`studyapp.ui.paradigm.block_view`). A block's instructions page
is read and left at once, as a participant pressing "Start this part" would.
"""
from __future__ import annotations

import time
from typing import TYPE_CHECKING, Callable, Sequence

from studyapp.bots.policies import (
    POLICIES,
    choose_preference,
    choose_ranking,
    choose_ratings,
    questionnaire_answers,
    trial_rng,
)
from studyapp.errors import StudyappError
from studyapp.study.session import PlayStats, Session, State

if TYPE_CHECKING:
    from studyapp.study.design import Design
    from studyapp.study.schedule import TrialPlan
    from studyapp.study.storage import ResultsDB


def run_bot_session(
    design: Design,
    db: ResultsDB,
    participant: str,
    policy: str,
    seed: int = 0,
    on_trial: Callable[[TrialPlan], None] | None = None,
    *,
    row: int | None = None,
    groups: dict[str, str] | None = None,
    allow_rerun: bool = False,
    pace_s: float = 0.0,
    plans: Sequence[TrialPlan] | None = None,
    n_rows: int | None = None,
    consent: bool = True,
) -> Session:
    """Run (or resume) one participant with a scripted policy; returns the finished :class:`Session`.

    ``consent = False`` plays a participant who does not consent on the first page (the session ends there).
    ``on_trial(plan)`` is called after each answer is committed. ``pace_s`` waits that long per clip as
    if watching it (kill tests use it to land kills between commits).
    """
    if policy not in POLICIES:
        raise StudyappError(f"unknown bot policy {policy!r}; choose one of {', '.join(POLICIES)}")
    session = Session(design, db, participant, row=row, groups=groups, allow_rerun=allow_rerun, plans=plans,
                      n_rows=n_rows, on_saved=on_trial)
    try:
        if not consent and not session.resumed:  # a participant who does not consent: recorded, nothing else
            session.decline_consent()
            return session
        session.accept_consent()
        session.finish_instructions()
        session.record_env_check({"bot": policy, "bot_seed": int(seed)})
        cond_order = [c.id for c in design.conditions]
        ties = bool(getattr(design.playback, "allow_ties", False))
        from studyapp.render.scene import build_trial_scene
        from studyapp.study.stimuli import load_trial_media
        from studyapp.ui.paradigm import PREFERENCE, block_view, figure_labels, scene_labels

        while (plan := session.current_trial()) is not None:
            if session.block_instructions() is not None:
                session.finish_block_instructions()
            media = load_trial_media(design, plan)
            # The scene a participant's window would build (retargeting, avatar, media cut to the timeline),
            # on the CPU: a pilot without rendering fails where a participant would, and plays what they play.
            scene = build_trial_scene(None, media, labels=scene_labels(figure_labels(design, len(plan.slots)), len(plan.slots)))
            session.record_play_started(duration_s=scene.duration)
            if pace_s > 0:
                time.sleep(pace_s)
            session.record_play_finished(True, PlayStats())
            rng = trial_rng(seed, session.participant_id, plan.trial_index)
            block = block_view(design, plan)
            if block.paradigm in PREFERENCE:
                session.submit_preference(*choose_preference(policy, plan, media, block.criteria, rng,
                                                             levels=block.levels, reasons=block.reasons,
                                                             condition_order=cond_order))
            elif block.paradigm == "rating":
                session.submit_ratings(choose_ratings(policy, plan, media, block.criteria, rng,
                                                      condition_order=cond_order))
            else:
                session.submit_ranking(choose_ranking(policy, plan, media, block.criteria, rng,
                                                      condition_order=cond_order, allow_ties=ties))
        if session.state is State.QUESTIONNAIRE:
            rng = trial_rng(seed, session.participant_id, -1 & 0xFFFFFFFF)
            session.submit_questionnaire(questionnaire_answers(session.questionnaire_items, rng))
    finally:
        session.close()
    return session
