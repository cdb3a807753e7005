"""One trial's playback state: media, scene, play/pause/replay, watched-once, the answers, frame stats.

The drawing lives in :mod:`studyapp.ui.screens.trial`; this class holds what must survive between
frames and talks to the :class:`~studyapp.study.session.Session` (plays, stats, the answers).

The answers are those of the trial's paradigm (:mod:`studyapp.ui.paradigm`): a
:class:`~studyapp.ui.ranking.RankingState` (``rank``), a :class:`~studyapp.ui.preference.PreferenceState`
(``pairwise``, ``mismatch``) or a :class:`~studyapp.ui.rating.RatingState` (``rating``), on the questions
of the trial's block; :meth:`TrialView.submit` hands them to the session method of that paradigm.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from studyapp.render.frames import PlayRecorder, clock_media_time
from studyapp.ui.paradigm import PREFERENCE, block_view, figure_labels, scene_labels, slot_names
from studyapp.ui.preference import PreferenceState
from studyapp.ui.ranking import RankingState
from studyapp.ui.rating import RatingState

if TYPE_CHECKING:
    from studyapp.audio.clock import MediaClock
    from studyapp.render.scene import TrialScene
    from studyapp.study.schedule import TrialPlan
    from studyapp.study.stimuli import TrialMedia
    from studyapp.ui.seams import ScreenApp


class TrialView:
    """State of the trial on screen. ``scene`` is built by the app's renderer when the trial loads."""

    def __init__(self, app: ScreenApp, plan: TrialPlan) -> None:
        self.app = app
        self.plan = plan
        self.media: TrialMedia | None = None
        self.scene: TrialScene | None = None
        self.block = block_view(app.design, plan)
        self.paradigm = self.block.paradigm
        #: The questions of this trial (its block's criteria), in order.
        self.criteria = self.block.criteria
        #: What the figures are called on screen ("A", "B" / "Left", "Right").
        self.names = slot_names(figure_labels(app.design, self.n_slots), self.n_slots)
        ids = [c.id for c in self.criteria]
        self.answer: RankingState | PreferenceState | RatingState
        if self.paradigm in PREFERENCE:
            self.answer = PreferenceState(ids, levels=self.block.levels, reasons=self.block.reasons)
        elif self.paradigm == "rating":
            self.answer = RatingState(ids, self.n_slots)
        else:
            self.answer = RankingState(ids, allow_ties=bool(getattr(app.design.playback, "allow_ties", False)))
        self.recorder: PlayRecorder | None = None
        self.watched = False          # played to the end at least once
        self.in_play = False          # a play is registered with the session (playing or paused)
        self.drawn_media_s: float | None = None
        self.error: str | None = None

    # -- loading ---------------------------------------------------------------------------------
    def load(self) -> None:
        from studyapp.render.scene import build_trial_scene
        from studyapp.study.stimuli import load_trial_media

        self.media = load_trial_media(self.app.design, self.plan)
        self.scene = build_trial_scene(self.app.renderer, self.media,
                                       labels=scene_labels(figure_labels(self.app.design, self.n_slots), self.n_slots))

    @property
    def n_slots(self) -> int:
        """Figures side by side in this trial (2, 3 or 4, by its paradigm)."""
        return len(self.plan.slots)

    @property
    def loaded(self) -> bool:
        return self.scene is not None

    @property
    def duration_s(self) -> float:
        return float(self.scene.duration) if self.scene is not None else 0.0

    # -- transport ---------------------------------------------------------------------------------
    @property
    def clock(self) -> MediaClock:
        return self.app.clock

    @property
    def state(self) -> str:
        """"ready" (never played), "playing", "paused", "ended" (last play reached the end or stopped)."""
        if not self.in_play:
            return "ended" if self.watched or self.app.session.plays else "ready"
        return "paused" if self.clock.paused else "playing"

    def can_play(self) -> bool:
        return not self.in_play and self.app.session.can_play() and self.loaded

    def play(self) -> None:
        """Start (or replay) the clip from the beginning, with sound."""
        if not self.can_play():
            return
        self.app.session.record_play_started(self.duration_s)
        self.in_play = True
        self.recorder = PlayRecorder(refresh_hz=self.app.refresh_hz)
        self.clock.play(self.media.audio, 0.0, duration_s=self.duration_s)

    def toggle_pause(self) -> None:
        if not self.in_play:
            return
        if self.clock.paused:
            self.clock.resume()
        else:
            self.clock.pause()

    def pause(self) -> None:
        if self.in_play and not self.clock.paused:
            self.clock.pause()

    def stop(self) -> None:
        """End the current play early (only offered after the clip was watched once)."""
        if self.in_play:
            self._finish(completed=False)

    def _finish(self, completed: bool) -> None:
        stats = self.recorder.stats() if self.recorder else None
        self.clock.stop()
        self.in_play = False
        self.app.session.record_play_finished(completed, stats)
        if completed:
            self.watched = True

    def update(self) -> None:
        """Once per frame before drawing: notice the end of the clip."""
        if self.in_play and not self.clock.paused and self.clock.finished:
            self._finish(completed=True)

    def media_time(self, now: float) -> float:
        """Clip time to draw now: the audio clock plus the time until this frame is shown."""
        if not self.in_play:
            return self.duration_s if self.watched else 0.0
        return clock_media_time(self.clock, now, self.app.predictor, self.duration_s)

    def after_flip(self, flip_time: float) -> None:
        if self.in_play and self.recorder is not None and self.drawn_media_s is not None \
                and not self.clock.paused:
            self.recorder.flip(flip_time, self.drawn_media_s, self.clock.position_s())
        self.drawn_media_s = None

    # -- answers -----------------------------------------------------------------------------------
    def ranking_open(self) -> bool:
        """The ranking panel shows once the design's watching rule is met (and stays open on replays)."""
        return self.watched or not bool(self.app.design.playback.must_watch_fully)

    @property
    def ranking(self) -> RankingState:
        """The ranking of a ``rank`` trial (an error on other paradigms: their answers are :attr:`answer`)."""
        if not isinstance(self.answer, RankingState):
            raise AttributeError(f"a {self.paradigm} trial has no ranking")
        return self.answer

    def answers_complete(self) -> bool:
        """Every question answered (every slider moved, for ratings)."""
        a = self.answer
        return a.all_moved() if isinstance(a, RatingState) else a.all_complete()

    def can_submit(self) -> bool:
        return self.answers_complete() and not self.in_play and self.app.session.can_rank()

    def submit(self) -> None:
        if not self.can_submit():
            return
        a = self.answer
        if isinstance(a, PreferenceState):
            self.app.session.submit_preference(a.answers(), a.submitted_reasons())
        elif isinstance(a, RatingState):
            self.app.session.submit_ratings(a.ratings())
        else:
            self.app.session.submit_ranking(a.ranks())
