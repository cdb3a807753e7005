"""Camera matrices and the framing rule shared by every slot of a trial.

All slots use one camera (same position, lens and aspect), so no model looks bigger, closer or better lit
than another. The framing is fitted once per trial to the union of all slots' joint positions over the
whole clip (robust percentiles), so hands stay inside the frame during normal gestures.

>>> cam = Camera(eye=np.array([0, 1.2, 4.0]), target=np.array([0, 1.2, 0.0]), fov_y=30.0)
>>> m = cam.view_proj(aspect=0.6)
>>> p = m @ np.array([0, 1.2, 0, 1.0]); np.round(p[:2] / p[3], 6).tolist()
[0.0, 0.0]
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pyrr import matrix44


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL projection matrix for column vectors (pyrr builds it for row vectors: transpose)."""
    return matrix44.create_perspective_projection(fov_y_deg, aspect, near, far, dtype=np.float64).T


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """World-to-camera matrix for column vectors (pyrr builds it for row vectors: transpose)."""
    return matrix44.create_look_at(np.asarray(eye, np.float64), np.asarray(target, np.float64),
                                   np.asarray(up, np.float64), dtype=np.float64).T


@dataclass(frozen=True)
class Camera:
    """A perspective camera looking at ``target`` from ``eye`` (metres), vertical field of view in degrees."""

    eye: np.ndarray
    target: np.ndarray
    fov_y: float = 24.0
    near: float = 0.1
    far: float = 30.0

    def view(self) -> np.ndarray:
        return look_at(self.eye, self.target)

    def view_proj(self, aspect: float) -> np.ndarray:
        return perspective(self.fov_y, aspect, self.near, self.far) @ self.view()


#: Smallest box always shown (metres, around an avatar standing at the origin): head to upper thighs,
#: hands at a relaxed width. Gestures wider or higher than this enlarge the frame for all slots alike.
MIN_BOX = (np.array([-0.34, 0.70, -0.2]), np.array([0.34, 1.80, 0.2]))


def fit_camera(points: np.ndarray, aspect: float, fov_y: float = 24.0, margin: float = 0.06,
               min_box: tuple[np.ndarray, np.ndarray] = MIN_BOX, percentile: float = 99.5,
               top_reserve: float = 0.0) -> Camera:
    """A front camera (slightly above chest height) that shows every point, with ``margin`` metres to spare.

    ``points`` is ``(N, 3)`` world positions (all slots, all frames). Extremes beyond the ``percentile``
    are ignored so one glitching frame cannot shrink every avatar. ``top_reserve`` keeps that fraction of
    the frame height free at the top (for slot labels).
    """
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    if len(pts):
        lo = np.percentile(pts, 100 - percentile, axis=0)
        hi = np.percentile(pts, percentile, axis=0)
        # keep the avatar centred horizontally: the frame is symmetric around x = 0
        half_x = max(abs(lo[0]), abs(hi[0]))
        lo = np.minimum(min_box[0], [-half_x, lo[1], lo[2]])
        hi = np.maximum(min_box[1], [half_x, hi[1], hi[2]])
    else:
        lo, hi = min_box
    lo = lo - margin
    hi = hi + margin
    hi = hi.copy()
    hi[1] += (hi[1] - lo[1]) * top_reserve / max(1e-6, 1 - top_reserve)
    half_w = max(abs(lo[0]), abs(hi[0]))
    half_h = (hi[1] - lo[1]) / 2
    tan_y = np.tan(np.radians(fov_y) / 2)
    # distance so that both the height and the width fit (measured at the front of the box)
    dist = max(half_h / tan_y, half_w / (tan_y * aspect)) + hi[2]
    # when the width decides the distance there is spare height: keep the head near the top of the frame
    # and let the spare room show more of the legs
    visible_half_h = (dist - hi[2]) * tan_y
    centre_y = max(hi[1] - visible_half_h, visible_half_h - 0.08)  # never show much below the floor
    # a camera slightly above the centre looking a little down reads as eye level for a seated viewer
    eye = np.array([0.0, centre_y + 0.05 * dist * tan_y, dist])
    target = np.array([0.0, centre_y, 0.0])
    return Camera(eye=eye, target=target, fov_y=fov_y, near=max(0.05, dist - 3.0), far=dist + 6.0)
