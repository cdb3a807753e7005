"""Camera matrices and the framing rule shared by every slot of a trial.

All slots use one camera (same position, lens and aspect), so no model looks bigger, closer or better lit
than another. The camera frames a box (metres, world space) that holds what the study needs to see:

* ``"upper-body"`` (the default): from just below the hips to the top of the head, with the hands' and
  arms' whole range over the clip inside. Gestures are what participants judge, so the legs are left out
  and the figure is as large as the frame allows.
* ``"full-body"``: head to feet, with the same hands' range.

The box is fitted to the aspect of the viewport the camera is drawn into (:meth:`Camera.view_proj`
refits it), so a slot that becomes wider when the ranking panel opens shows a larger figure, not more
empty floor. Hands count relative to the hips: the scene follows each slot's hips
(:func:`follow_offsets`), so a walking clip does not shrink the figure.

>>> cam = Camera(eye=np.array([0, 1.2, 4.0]), target=np.array([0, 1.2, 0.0]), fov_y=30.0)
>>> m = cam.view_proj(aspect=0.6)
>>> p = m @ np.array([0, 1.2, 0, 1.0]); np.round(p[:2] / p[3], 6).tolist()
[0.0, 0.0]

A framed box stays inside the frame at any aspect, and fills its height when the frame is wide:

>>> box = (np.array([-0.4, 0.8, -0.2]), np.array([0.4, 1.8, 0.2]))
>>> cam = fit_box(box, aspect=0.6)
>>> def ndc(c, p, aspect): q = c.view_proj(aspect) @ np.r_[p, 1.0]; return q[:2] / q[3]
>>> corners = [np.array([x, y, z]) for x in (-0.4, 0.4) for y in (0.8, 1.8) for z in (-0.2, 0.2)]
>>> all(np.abs(ndc(cam, p, a)).max() <= 1.0 for p in corners for a in (0.4, 0.6, 1.33, 2.0))
True
>>> top, bottom = ndc(cam, np.array([0, 1.8, 0.2]), 2.0)[1], ndc(cam, np.array([0, 0.8, 0.2]), 2.0)[1]
>>> round(float(top - bottom) / 2, 2)  # share of the frame's height (3 % are left for the camera's tilt)
0.97
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pyrr import matrix44

#: The framings a design may ask for (``[display] framing``); the first is the default.
FRAMINGS = ("upper-body", "full-body")
DEFAULT_FRAMING = FRAMINGS[0]
#: Vertical field of view (degrees): a short telephoto, little perspective distortion between slots.
FOV_Y = 24.0
#: How far below the hips joint the upper-body frame reaches (metres): the hips stay clear of the edge.
BELOW_HIPS = 0.10
#: Space around the box (metres) so nothing touches the frame edge.
MARGIN = 0.05


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL projection matrix for column vectors (pyrr builds it for row vectors: transpose)."""
    return matrix44.create_perspective_projection(fov_y_deg, aspect, near, far, dtype=np.float64).T


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """World-to-camera matrix for column vectors (pyrr builds it for row vectors: transpose)."""
    return matrix44.create_look_at(np.asarray(eye, np.float64), np.asarray(target, np.float64),
                                   np.asarray(up, np.float64), dtype=np.float64).T


@dataclass(frozen=True, eq=False)
class Camera:
    """A perspective camera looking at ``target`` from ``eye`` (metres), vertical field of view in degrees.

    ``box`` (``(lo, hi)``, metres) is what the camera frames, when it was made by :func:`fit_box`; then
    :meth:`view_proj` refits it to the aspect it is drawn at, and ``eye``/``target`` are the fit at the
    aspect the scene was made for (the renderer's lighting uses ``eye``). ``top_reserve`` is the
    fraction of the frame height kept free above the box (slot labels).
    """

    eye: np.ndarray
    target: np.ndarray
    fov_y: float = FOV_Y
    near: float = 0.1
    far: float = 30.0
    box: tuple[np.ndarray, np.ndarray] | None = None
    top_reserve: float = 0.0

    def view(self) -> np.ndarray:
        return look_at(self.eye, self.target)

    def for_aspect(self, aspect: float) -> "Camera":
        """This camera refitted to a viewport of ``aspect`` (itself when it frames no box)."""
        if self.box is None:
            return self
        return fit_box(self.box, aspect, fov_y=self.fov_y, top_reserve=self.top_reserve)

    def view_proj(self, aspect: float) -> np.ndarray:
        cam = self.for_aspect(aspect)
        return perspective(cam.fov_y, aspect, cam.near, cam.far) @ cam.view()


def fit_box(box: tuple[np.ndarray, np.ndarray], aspect: float, fov_y: float = FOV_Y,
            top_reserve: float = 0.0) -> Camera:
    """A front camera (a little above the box centre, looking along -Z) that shows all of ``box``.

    The frame is centred horizontally on x = 0 (every slot's figure stands there). When the height
    decides the distance the box fills the frame's height; when the width decides, the spare height goes
    below the box (legs, floor), keeping the head near the top of the frame, but never much below the floor.
    """
    lo = np.asarray(box[0], np.float64)
    hi = np.asarray(box[1], np.float64)
    top = hi[1] + (hi[1] - lo[1]) * top_reserve / max(1e-6, 1 - top_reserve)
    half_w = max(abs(lo[0]), abs(hi[0]))
    half_h = (top - lo[1]) / 2
    tan_y = np.tan(np.radians(fov_y) / 2)
    # distance so that both the height and the width fit at the front of the box; 3 % more because the
    # camera looks down a little (below), which tips the box's far corners towards the frame's edge
    dist = 1.03 * max(half_h / tan_y, half_w / (tan_y * aspect)) + hi[2]
    vis = (dist - hi[2]) * tan_y  # half the visible height at the front of the box
    centre_y = top - vis  # the box top (or the label space) at the top of the frame
    # raise the frame when it would show much below the floor, but never so far that the box bottom leaves
    centre_y = max(centre_y, min(vis - 0.08, lo[1] + vis))
    # a camera slightly above the centre looking a little down reads as eye level for a seated viewer
    eye = np.array([0.0, centre_y + 0.05 * dist * tan_y, dist])
    target = np.array([0.0, centre_y, 0.0])
    return Camera(eye=eye, target=target, fov_y=fov_y, near=max(0.05, dist - hi[2] - 1.0), far=dist - lo[2] + 6.0,
                  box=(lo, hi), top_reserve=top_reserve)


def fit_camera(points: np.ndarray, aspect: float, fov_y: float = FOV_Y, margin: float = MARGIN,
               percentile: float = 99.5, top_reserve: float = 0.0) -> Camera:
    """A camera that frames ``points`` (``(N, 3)``, metres), ignoring extremes beyond ``percentile``.

    Extremes are ignored so one glitching frame cannot shrink every avatar.

    >>> pts = np.array([[-0.3, 0.9, 0.0], [0.3, 1.7, 0.1]])
    >>> lo, hi = fit_camera(pts, 0.6, percentile=100).box
    >>> lo.round(2).tolist(), hi.round(2).tolist()
    ([-0.35, 0.85, -0.05], [0.35, 1.75, 0.15])
    """
    return fit_box(robust_box(points, points, percentile, margin), aspect, fov_y=fov_y, top_reserve=top_reserve)


def robust_box(lows: np.ndarray, highs: np.ndarray, percentile: float = 99.5,
               margin: float = MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)``: the ``100 - percentile`` percentile of ``lows`` and the ``percentile`` of ``highs``
    (``(N, 3)`` each), widened by ``margin`` and made symmetric about x = 0."""
    lo = np.percentile(np.asarray(lows, np.float64).reshape(-1, 3), 100 - percentile, axis=0) - margin
    hi = np.percentile(np.asarray(highs, np.float64).reshape(-1, 3), percentile, axis=0) + margin
    half_x = max(abs(lo[0]), abs(hi[0]))
    lo[0], hi[0] = -half_x, half_x
    return lo, hi


def framing_box(framing: str, points: np.ndarray, legs: np.ndarray, hips_y: float,
                rest_bounds: tuple[np.ndarray, np.ndarray], head_only: bool = False,
                percentile: float = 99.5) -> tuple[np.ndarray, np.ndarray]:
    """The box a framing shows, from the skin's extent over the clip and the avatar's rest pose.

    ``points`` is ``(F, J, K, 3)``: for every frame (all slots stacked on F) and joint, K world points
    that bound the skin the joint carries (the corners of its vertices' box, moved with the joint), already
    following the hips (:func:`follow_offsets`); ``legs`` a ``(J,)`` mask of leg and foot joints;
    ``hips_y`` the rest pose's hips height; ``rest_bounds`` the rest pose mesh's ``(lo, hi)``. Frames
    beyond ``percentile`` (per side) are ignored, so one glitching frame cannot shrink every figure.

    * Upper body: every non-leg joint's skin over the clip (hands and arms wherever they go, a leaning
      head), at least from ``BELOW_HIPS`` under the hips to the rest pose's head top.
    * Full body: every joint's skin over the clip, at least from the rest pose's soles to its head top.
    * ``head_only`` (no legs, no hands: an ARKit face model or a bust): the whole rest mesh and wherever
      the joints move it, whatever ``framing`` says, so the face camera shows the mouth and chin.

    >>> pts = np.array([[[[0, 1.0, 0]], [[0, 1.75, 0.1]], [[0.4, 0.7, 0]], [[0, 0.0, 0]]]])  # hips, head, hand, foot
    >>> legs = np.array([False, False, False, True])
    >>> bounds = (np.array([-0.9, 0.0, -0.1]), np.array([0.9, 1.76, 0.1]))
    >>> lo, hi = framing_box("upper-body", pts, legs, 1.0, bounds)
    >>> lo.round(2).tolist(), hi.round(2).tolist()
    ([-0.45, 0.65, -0.05], [0.45, 1.81, 0.15])
    >>> framing_box("full-body", pts, legs, 1.0, bounds)[0].round(2).tolist()
    [-0.45, -0.05, -0.05]
    """
    if framing not in FRAMINGS:
        raise ValueError(f"framing must be one of {FRAMINGS}, got {framing!r}")
    legs = np.asarray(legs, bool)
    pts = np.asarray(points, np.float64)
    pts = pts.reshape(pts.shape[0], len(legs), -1, 3)
    rlo, rhi = (np.asarray(b, np.float64) for b in rest_bounds)
    keep = ~legs if framing == "upper-body" and not head_only else np.ones(len(legs), bool)
    flat = pts[:, keep].reshape(len(pts), -1, 3)
    lo, hi = robust_box(flat.min(axis=1), flat.max(axis=1), percentile, MARGIN)  # per frame, then over frames
    hi[1] = max(hi[1], rhi[1] + MARGIN)  # the head top, even where the joints do not reach it
    if head_only:
        blo, bhi = robust_box(rlo[None], rhi[None], 100.0, MARGIN)
        return np.minimum(lo, blo), np.maximum(hi, bhi)
    if framing == "upper-body":
        lo[1] = min(lo[1], hips_y - BELOW_HIPS)
    else:
        lo[1] = min(lo[1], rlo[1] - MARGIN)
    return lo, hi


def follow_offsets(hips_xz: np.ndarray, fps: float, start_xz: np.ndarray, window_s: float = 1.0) -> np.ndarray:
    """``(F, 2)`` horizontal offsets that keep a figure's hips where they started, smoothed over ``window_s``.

    Subtracting them from a slot's world positions is the same picture as a camera that follows the hips
    (the floor is plain): a walking figure stays full size in its slot, while the sway of the hips within a
    step (faster than ``window_s``) still shows.

    >>> walk = np.c_[np.linspace(0, 3, 91), np.zeros(91)]   # 3 m in 3 s at 30 fps, start to end
    >>> float(np.abs(walk - follow_offsets(walk, 30.0, np.zeros(2))).max()) < 1e-9
    True
    >>> sway = np.c_[0.05 * np.sin(np.linspace(0, 6 * np.pi, 91)), np.zeros(91)]  # 3 steps' hip sway
    >>> round(float(np.abs(sway - follow_offsets(sway, 30.0, np.zeros(2)))[30:60, 0].max()), 2)  # still shows
    0.05
    """
    xz = np.asarray(hips_xz, np.float64).reshape(-1, 2)
    n = max(1, int(round(window_s * fps)) | 1)  # odd, so the average is centred
    if len(xz) == 0:
        return xz.copy()
    pad = n // 2
    # mirrored through the end points ("odd" reflection), so a steady walk is followed exactly to its ends
    padded = np.pad(xz, ((pad, pad), (0, 0)), mode="reflect", reflect_type="odd") if len(xz) > 1 \
        else np.repeat(xz, 2 * pad + 1, 0)
    kernel = np.ones(n) / n
    smooth = np.stack([np.convolve(padded[:, k], kernel, mode="valid") for k in range(2)], -1)
    return smooth - np.asarray(start_xz, np.float64).reshape(1, 2)
