"""The scripted participant that uses the real UI offscreen (``studyapp run --offscreen --bot P``).

It renders every frame into an EGL framebuffer and acts only through :class:`~studyapp.ui.input.InputQueue`
events at the rectangles the screens drew their buttons at -- the same path a participant's mouse and
keyboard take. Its choices come from :func:`studyapp.bots.policies.choose_ranking` (random / ordered /
careful). To exercise every ranking method it drags the chips for the first question, clicks them for
the second and uses the number keys for the rest. The other paradigms likewise answer the first question
with the mouse and the rest with the keyboard: a preference by clicking an option box, then by clicking
the question (to highlight it) and pressing the option's number key, its reasons by ticking the first with
the mouse and the rest with their number keys; ratings by clicking each slider of the first question at
the point for its value (then Left/Right until it reads exactly that), and the others' by Up/Down to the
slider, Right (which sets an unset slider to 50), Page Up/Page Down and Left/Right. A block's instructions
page is left with its button. When the design allows ties and the policy chose some,
it enters them the same way: a click on the ``>`` between two places for the mouse questions, ``=`` typed
before the next figure for the keyboard ones. Time is virtual: each frame while a clip plays moves the
silent clock ahead by a fraction of the clip (``frames_per_play``; None plays every frame at ``fps``).
Its frames go through the same frame loop as the participant's window (:mod:`studyapp.render.loop`).
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from studyapp.audio.clock import SilentClock
from studyapp.bots import policies
from studyapp.errors import StudyappError
from studyapp.ui.app import StudyApp
from studyapp.ui.input import digit_key
from studyapp.ui.screens.common import FOOTER_PX

if TYPE_CHECKING:
    import moderngl

    from studyapp.study.design import Design
    from studyapp.study.schedule import TrialPlan
    from studyapp.study.storage import ResultsDB
    from studyapp.ui.seams import ParticipantSession
    from studyapp.ui.trial import TrialView

#: Rendered frames per clip play (virtual time jumps duration / this per frame).
FRAMES_PER_PLAY = 8


def center(rect: tuple[float, float, float, float]) -> tuple[float, float]:
    x0, y0, x1, y1 = rect
    return (x0 + x1) / 2.0, (y0 + y1) / 2.0


def slider_point(rect: tuple[float, float, float, float], value: int) -> tuple[float, float]:
    """Where to click on the 0..100 slider drawn at ``rect`` (x0, y0, x1, y1) for ``value``: ImGui's own geometry
    for an integer slider (2 px grab padding, a grab of ``max(track / 101, grab_min_size)`` centred on the value)."""
    from imgui_bundle import imgui

    x0, y0, x1, y1 = rect
    track = (x1 - x0) - 4.0
    grab = min(max(track / 101.0, imgui.get_style().grab_min_size), track)
    return x0 + 2.0 + grab / 2 + (track - grab) * value / 100.0, (y0 + y1) / 2


def save_png(rgb: np.ndarray, path: Path) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.ascontiguousarray(rgb, np.uint8)).save(path, format="png")


class UIBot:
    """Drives a :class:`StudyApp` offscreen, one rendered frame per step."""

    def __init__(self, design: Design, db: ResultsDB, participant_id: str, policy: str, seed: int, *,
                 size: tuple[int, int] = (1280, 720), out_dir: Path | str | None = None,
                 max_frames_per_trial: int = 400, session: ParticipantSession | None = None, fps: float = 60.0,
                 frames_per_play: int | None = FRAMES_PER_PLAY, consent: bool = True) -> None:
        from studyapp.render.context import create_offscreen_context
        from studyapp.render.loop import FrameLoop, OffscreenFrames, VirtualTimer
        from studyapp.study.session import Session

        if policy not in policies.POLICIES:
            raise StudyappError(f"unknown bot policy {policy!r}; choose one of {', '.join(policies.POLICIES)}")
        self.design = design
        self.policy = policy
        self.seed = int(seed)
        #: False: the participant does not consent ("I do not agree", then confirms), which ends the session
        self.consent = bool(consent)
        self.size = (int(size[0]), int(size[1]))
        self.out_dir = Path(out_dir) if out_dir is not None else None
        self.max_frames_per_trial = int(max_frames_per_trial)
        self.session = session or Session(design, db, participant_id)
        self.ctx = create_offscreen_context()
        self.target = OffscreenFrames(self.ctx, self.size)
        self.clock = SilentClock(virtual=True, reason="offscreen scripted participant")
        self.frames_per_play = frames_per_play
        self.app = StudyApp(design, self.session, self.ctx, self.clock, refresh_hz=float(fps),
                            display=("offscreen", self.size, float(fps), 1.0), bench_frames=3)
        # frames_per_play None: the clip plays in real frames, the clock moving 1/fps per frame with the loop
        timer = VirtualTimer(fps, clocks=[self.clock] if frames_per_play is None else [])
        self.loop = FrameLoop(self.target, timer, self._draw, self.app.after_flip, capture=False)
        self.steps: deque[Callable[[], None]] = deque()
        self.shots: list[Path] = []
        self._shot_keys: set[str] = set()
        self._planned_for: Any = None
        self.last_rgb: np.ndarray | None = None
        self._prev_key: str | None = None
        self._q_planned = False
        self._per_trial = 0
        self._last_trial: int | None = None

    # -- frame loop ----------------------------------------------------------------------------------
    @property
    def t(self) -> float:
        """The virtual time of the next frame."""
        return self.loop.timer.now()

    @property
    def frames(self) -> int:
        return self.loop.frames

    def _draw(self, fbo: moderngl.Framebuffer, size: tuple[int, int], now: float) -> None:
        # Fast mode: the clip advances first by a fraction of its length, then the frame is drawn and
        # "flipped" at that same instant (virtual time does not pass while drawing).
        view = self.app._view
        if self.frames_per_play and view is not None and view.in_play and not self.clock.paused:
            self.clock.advance(max(view.duration_s / self.frames_per_play, 1.0 / 60.0))
        self.app.frame(fbo, size, now, 1.0)

    def frame(self) -> None:
        """One frame at the virtual time :attr:`t`, through the frame loop."""
        self.loop.step()

    def screenshot(self, name: str) -> np.ndarray:
        rgb = self.target.read_rgb()
        self.last_rgb = rgb
        if self.out_dir is not None:
            path = self.out_dir / f"{len(self.shots) + 1:02d}_{name}.png"
            save_png(rgb, path)
            self.shots.append(path)
        return rgb

    def run(self) -> int:
        total_limit = self.max_frames_per_trial * (len(self.session.plans) + 6)
        while not self.app.quit and self.frames < total_limit:
            self.step()
        return 0 if self.session.finished else 1

    def step(self) -> None:
        """One frame, then the next input action (or a plan for the screen shown)."""
        self.frame()
        key = self.app.screen_key()
        # A new screen is complete on its second frame (ImGui hides a new window for one frame).
        if key not in self._shot_keys and self._stable(key):
            self._shot_keys.add(key)
            self.screenshot(key.replace(":", "_"))
        plan = self.session.current_trial()
        cur = None if plan is None else plan.trial_index
        self._per_trial = self._per_trial + 1 if cur == self._last_trial else 0
        self._last_trial = cur
        if cur is not None and self._per_trial > self.max_frames_per_trial:
            raise StudyappError(f"the scripted participant got stuck on trial {cur} "
                                f"(screen {key!r}) after {self._per_trial} frames")
        if self.steps:
            self.steps.popleft()()
        else:
            self._plan(key)

    def _stable(self, key: str) -> bool:
        stable = self._prev_key == key
        self._prev_key = key
        return stable and not key.endswith((":loading", ":measuring"))

    def close(self) -> None:
        self.app.shutdown()
        self.target.release()
        self.session.close()

    # -- input helpers --------------------------------------------------------------------------------
    def _rect(self, key: Any) -> tuple[float, float, float, float]:
        r = self.app.ui.rects.get(key)
        if r is None:
            raise StudyappError(f"the scripted participant cannot find {key!r} on screen {self.app.screen_key()!r}")
        return r

    def _ensure_visible(self, key: Any, tries: int = 60) -> Callable[[], None]:
        """A step that scrolls the page (mouse wheel) until the item is inside the window."""
        q = self.app.input
        w, h = self.size

        def step(left: int = tries) -> None:
            x0, y0, x1, y1 = self._rect(key)
            # on a full page, the fixed footer (its main button) covers the body's last pixels
            page = self.app.screen_key().split(":")[0] not in ("practice", "trials") and isinstance(key, tuple)
            bottom = h - (FOOTER_PX * self.app.scale if page else 0.0)
            if left <= 0 or (y0 >= 0 and y1 <= bottom):
                return
            # The wheel scrolls the window under the mouse: alternate between the item's edge of the
            # screen (bottom panels) and the middle of the screen (scrolling page bodies).
            y = min(max(y0, 2), h - 2) if left % 2 else h / 2
            q.mouse_move(min(max((x0 + x1) / 2, 2), w - 2), y)
            q.scroll(0.0, -1.0 if y1 > bottom else 1.0)
            self.steps.appendleft(lambda: step(left - 1))
            self.steps.appendleft(lambda: None)
        return step

    def click(self, key: Any) -> None:
        """Queue a click on the item drawn under ``key`` (looked up when the step runs)."""
        q = self.app.input
        self.steps.append(self._ensure_visible(key))
        self.steps.append(lambda: q.mouse_move(*center(self._rect(key))))
        self.steps.append(lambda: q.mouse_button(0, True))
        self.steps.append(lambda: q.mouse_button(0, False))
        self.steps.append(lambda: None)

    def drag(self, src: Any, dst: Any) -> None:
        """Press on ``src``, move in steps (past the drag threshold) onto ``dst``, release."""
        q = self.app.input
        state: dict[str, tuple[float, float]] = {}

        def press():
            state["a"] = center(self._rect(src))
            q.mouse_move(*state["a"])

        def down():
            q.mouse_button(0, True)

        def move(frac: float):
            def f():
                if "b" not in state:
                    state["b"] = center(self._rect(dst))
                (ax, ay), (bx, by) = state["a"], state["b"]
                q.mouse_move(ax + (bx - ax) * frac, ay + (by - ay) * frac)
            return f

        self.steps.extend([self._ensure_visible(src), press, down, move(0.05), move(0.3), move(0.7), move(1.0), move(1.0),
                           lambda: q.mouse_button(0, False), lambda: None])

    def key(self, imgui_key: Any) -> None:
        q = self.app.input
        self.steps.append(lambda: q.key(imgui_key, True))
        self.steps.append(lambda: q.key(imgui_key, False))
        self.steps.append(lambda: None)

    def char(self, ch: str) -> None:
        """Queue a typed character (what GLFW's char callback delivers for symbols like ``=``)."""
        q = self.app.input
        self.steps.append(lambda: q.char(ch))
        self.steps.append(lambda: None)

    def wait(self, n: int = 1) -> None:
        for _ in range(n):
            self.steps.append(lambda: None)

    # -- what to do next --------------------------------------------------------------------------------
    def _plan(self, key: str) -> None:
        state = key.split(":")[0]
        if state == "welcome":
            if self.consent or self.session.resume_point is not None:
                self.click("consent")
            else:
                self.click("decline")
                self.wait(2)
                self.click("decline_confirm")
        elif state == "instructions":
            self.click("continue")
        elif state == "env_check":
            if self.app.env_report is None:
                self.wait()
            else:
                self.click("test_sound")
                self.click("continue")
        elif state in ("practice", "trials"):
            self._plan_trial(key)
        elif state == "questionnaire":
            self._plan_questionnaire()
        elif state in ("done", "ended_early", "declined"):
            self.click("close")
        else:
            self.wait()

    def _plan_trial(self, key: str) -> None:
        from studyapp.ui.ranking import order_and_ties

        sub = key.split(":")[1] if ":" in key else ""
        if sub == "block":
            self.click("block_continue")
            self.wait(2)
            return
        view = self.app.trial_view()
        if view is None or not view.loaded or sub in ("loading", "playing"):
            self.wait()
            return
        if sub == "ready":
            self.click("play")
            return
        if sub == "ranking" and self._planned_for != view.plan.trial_index:
            self._planned_for = view.plan.trial_index
            plan = view.plan
            rng = policies.trial_rng(self.seed, self.session.participant_id, plan.trial_index)
            # the block's criteria, as on screen: a rank block of a multi-block design may ask only some
            ranks = policies.choose_ranking(self.policy, plan, view.media, view.criteria, rng,
                                   condition_order=[c.id for c in self.design.conditions],
                                   allow_ties=view.ranking.allow_ties)
            for ci, crit in enumerate(view.criteria):
                order, ties = order_and_ties(ranks[crit.id])  # best first
                if ci == 0:      # drag and drop
                    for place, slot in enumerate(order):
                        self.drag(("chip", crit.id, slot), ("place", crit.id, place))
                elif ci == 1:    # click in order best -> worst
                    for slot in order:
                        self.click(("chip", crit.id, slot))
                else:            # keyboard: select the question, then 1/2/3, "=" before a tied figure
                    self.click(("crit", crit.id))
                    for k, slot in enumerate(order):
                        if k and ties[k - 1]:
                            self.char("=")
                        self.key(digit_key(slot + 1))
                    continue
                for link, tied in enumerate(ties):
                    if tied:
                        self.click(("tie", crit.id, link))
            self.wait(2)
            return
        if sub == "answering" and self._planned_for != view.plan.trial_index:
            self._planned_for = view.plan.trial_index
            if view.paradigm == "rating":
                self._plan_ratings(view)
            else:
                self._plan_preference(view)
            self.wait(2)
            return
        if sub in ("ranked", "answered"):
            self.click("next")
            self.wait(2)
            return
        self.wait()

    def _rng(self, view: TrialView) -> np.random.Generator:
        return policies.trial_rng(self.seed, self.session.participant_id, view.plan.trial_index)

    def _plan_preference(self, view: TrialView) -> None:
        plan, block = view.plan, view.block
        levels, reasons = policies.choose_preference(
            self.policy, plan, view.media, block.criteria, self._rng(view), levels=block.levels,
            reasons=block.reasons, condition_order=[c.id for c in self.design.conditions])
        options = view.answer.options  # type: ignore[union-attr]
        for ci, crit in enumerate(block.criteria):
            if ci == 0:   # the mouse
                self.click(("option", crit.id, levels[crit.id]))
            else:         # the keyboard: highlight the question, then the option's number key
                self.click(("crit", crit.id))
                self.key(digit_key(options.index(levels[crit.id]) + 1))
        for k, reason in enumerate(reasons):
            i = block.reasons.index(reason)
            if k == 0:
                self.click(("reason", i))
            else:
                self.click("reasons")
                self.key(digit_key(i + 1))

    def _plan_ratings(self, view: TrialView) -> None:
        block = view.block
        ratings = policies.choose_ratings(self.policy, view.plan, view.media, block.criteria, self._rng(view),
                                          condition_order=[c.id for c in self.design.conditions])
        for ci, crit in enumerate(block.criteria):
            for slot in range(view.n_slots):
                target = int(ratings[crit.id][slot])
                if ci == 0:   # the mouse: click where the value is, then fix the last point or two by keys
                    key = ("slider", crit.id, slot)
                    self.steps.append(self._ensure_visible(key))
                    self.steps.append(lambda k=key, v=target: self.app.input.mouse_move(*slider_point(self._rect(k), v)))
                    self.steps.append(lambda: self.app.input.mouse_button(0, True))
                    self.steps.append(lambda: self.app.input.mouse_button(0, False))
                    self.steps.append(lambda: None)
                # the keyboard: Up/Down to the slider, then (unset) Right, Page Up/Down, Left/Right; after a
                # click this only corrects the point or two a click can be off
                self.steps.append(lambda c=crit.id, s=slot, v=target: self._key_slider(c, s, v))

    def _front(self, keys: list[Any]) -> None:
        """Put presses of ``keys`` (in order) at the front of the queued steps."""
        q = self.app.input
        for k in reversed(keys):
            self.steps.appendleft(lambda: None)
            self.steps.appendleft(lambda k=k: q.key(k, False))
            self.steps.appendleft(lambda k=k: q.key(k, True))

    def _key_slider(self, crit: str, slot: int, target: int) -> None:
        """Queue, first, the keys that take the slider ``(crit, slot)`` from where it is to ``target``."""
        from imgui_bundle import imgui

        r = self.app.trial_view().answer
        row = r.rows().index((crit, slot))
        moves = row - r.active
        keys: list[Any] = [imgui.Key.down_arrow if moves > 0 else imgui.Key.up_arrow] * abs(moves)
        start = r.values[crit][slot]
        if start is None:
            keys.append(imgui.Key.right_arrow)   # sets an unset slider to 50
            start = 50
        tens = int(round((target - start) / 10))
        keys += [imgui.Key.page_up if tens > 0 else imgui.Key.page_down] * abs(tens)
        rest = target - (start + 10 * tens)
        keys += [imgui.Key.right_arrow if rest > 0 else imgui.Key.left_arrow] * abs(rest)
        self._front(keys)

    def _plan_questionnaire(self) -> None:
        if self._q_planned:
            self.wait()
            return
        self._q_planned = True
        items = self.session.questionnaire_items
        rng = policies.trial_rng(self.seed, self.session.participant_id, 10**6)
        answers = policies.questionnaire_answers(items, rng)
        for q in items:
            answer = answers[q.id]
            if q.kind == "likert":
                self.click(("likert", q.id, int(answer)))
            elif q.kind == "choice":
                for k, option in enumerate(q.options):
                    if option == answer or (q.multiple and option in answer):
                        self.click(("choice", q.id, k))
            else:
                self.click((q.kind, q.id))  # the number or text box
                text = str(answer)
                q_input = self.app.input
                self.steps.append(lambda t=text: q_input.type_text(t))
                self.wait(len(text) + 2)
                self.click(("question", q.id))  # click elsewhere: the text box lets go of the keyboard
        self.wait(2)
        self.click("submit")


def run_offscreen_bot(design: Design, db: ResultsDB, participant_id: str, policy: str, seed: int,
                      out_dir: Path | str | None = None, max_frames_per_trial: int = 400,
                      size: tuple[int, int] = (1280, 720), *, plans: Sequence[TrialPlan] | None = None,
                      n_rows: int | None = None) -> int:
    """A scripted participant through the real session and UI code, without a display.

    Frames are rendered offscreen (EGL); a virtual silent clock jumps ahead so a 10 s clip takes a few
    frames; clicks, drags and key presses are synthesized through :mod:`studyapp.ui.input`. With
    ``out_dir`` a PNG of every screen is written there. Returns 0 when the session finished. ``plans`` and
    ``n_rows``: a schedule given instead of the design's (a bundle's participant, see :class:`Session`).
    """
    from studyapp.study.session import Session

    session = Session(design, db, participant_id, plans=plans, n_rows=n_rows) if plans is not None else None
    bot = UIBot(design, db, participant_id, policy, seed, size=size, out_dir=out_dir,
                max_frames_per_trial=max_frames_per_trial, session=session)
    try:
        return bot.run()
    finally:
        bot.close()
