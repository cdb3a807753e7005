"""The participant UI's seams, typed: what it needs from the session, and what the screens need from the app.

Each :class:`~typing.Protocol` lists exactly what the UI uses, no more, so a reader sees the contract at
the seam and a stand-in (a test's fake session, a future front end) knows what to provide:

* :class:`ParticipantSession`: the running :class:`~studyapp.study.session.Session` as the screens drive it
  (the state machine's steps, the trial on screen, the progress labels). The UI never touches storage.
* :class:`ScreenApp`: what a screen (:mod:`studyapp.ui.screens`) and the trial's playback state
  (:class:`~studyapp.ui.trial.TrialView`) read from and ask of :class:`~studyapp.ui.app.StudyApp`.

The design is not a Protocol: the UI hands it on whole to :func:`~studyapp.study.stimuli.load_trial_media`,
so the honest type is the :class:`~studyapp.study.design.Design` data class itself. The clock is the audio
layer's :class:`~studyapp.audio.clock.MediaClock`.

>>> from studyapp.study.session import Session
>>> missing = [m for m in ("current_trial", "submit_ranking", "progress_label", "end_message", "finished")
...            if not hasattr(Session, m)]
>>> missing
[]
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Protocol

if TYPE_CHECKING:
    from studyapp.audio.clock import MediaClock
    from studyapp.render.frames import FlipPredictor
    from studyapp.render.renderer import Renderer
    from studyapp.render.scene import TrialScene
    from studyapp.study.design import Design, QuestionItem
    from studyapp.study.schedule import TrialPlan
    from studyapp.study.session import PlayStats, ResumePoint, State
    from studyapp.ui.envcheck import EnvReport
    from studyapp.ui.layer import ImGuiLayer
    from studyapp.ui.trial import TrialView
    from studyapp.ui.widgets import Painter


class ParticipantSession(Protocol):
    """The session as the UI drives it (implemented by :class:`studyapp.study.session.Session`)."""

    participant_id: str
    state: State
    plans: list[TrialPlan]
    results_file: Path | None   # the remote run's results file, written when the session finishes

    @property
    def plays(self) -> int: ...
    @property
    def questionnaire_items(self) -> list[QuestionItem]: ...
    @property
    def finished(self) -> bool: ...
    @property
    def end_message(self) -> str: ...
    @property
    def resume_point(self) -> ResumePoint | None: ...

    def accept_consent(self) -> State: ...
    def decline_consent(self) -> State: ...
    def finish_instructions(self) -> State: ...
    def record_env_check(self, info: Mapping[str, Any] | None = None) -> State: ...
    def current_trial(self) -> TrialPlan | None: ...
    def trial_number(self) -> int: ...
    def phase_total(self) -> int: ...
    def progress_label(self) -> str: ...
    def can_play(self) -> bool: ...
    def record_play_started(self, duration_s: float | None = None) -> int: ...
    def record_play_finished(self, completed: bool,
                             stats: PlayStats | Mapping[str, Any] | None = None) -> None: ...
    def can_rank(self) -> bool: ...
    def submit_ranking(self, ranks: Mapping[str, Mapping[Any, Any]],
                       stats: PlayStats | Mapping[str, Any] | None = None) -> State: ...
    def submit_preference(self, levels: Mapping[str, int], reasons: Sequence[str] = ()) -> State: ...
    def submit_ratings(self, ratings: Mapping[str, Mapping[int, float]]) -> State: ...
    def block_instructions(self) -> str | None: ...
    def finish_block_instructions(self) -> object: ...
    def submit_questionnaire(self, answers: Mapping[str, Any]) -> State: ...
    def close(self) -> None: ...


class ScreenApp(Protocol):
    """What the screens and the trial view use of the app (implemented by :class:`studyapp.ui.app.StudyApp`)."""

    design: Design
    session: ParticipantSession
    clock: MediaClock
    ui: Painter
    layer: ImGuiLayer
    predictor: FlipPredictor
    refresh_hz: float | None
    db_path: Path | str | None
    # this frame
    fb_size: tuple[int, int]
    scale: float
    now: float
    # screen state that outlives a frame
    env_report: EnvReport | None
    test_sound_played: bool
    answers: dict[str, Any]
    question_active: int
    question_moved: bool
    focus_text: bool
    typing: bool
    declining: bool
    quit: bool
    page_pad_x: float | None   # the page's side margin, set by the page, read by its bottom row
    upload_status: Callable[[], str] | None   # the final screen's line on a bundle run's uploads

    @property
    def renderer(self) -> Renderer: ...
    @property
    def results_file(self) -> Path | None: ...

    def trial_view(self) -> TrialView | None: ...
    def request_scene(self, scene: TrialScene, t: float, rect: tuple[float, float, float, float]) -> None: ...
    def request_trial_load(self) -> None: ...
    def request_env_check(self) -> None: ...
    def key_pressed(self, key: Any) -> bool: ...
    def typed_text(self) -> str: ...
    def estimated_minutes(self) -> int: ...
    def play_test_sound(self) -> None: ...
    def env_info(self) -> dict[str, Any]: ...
