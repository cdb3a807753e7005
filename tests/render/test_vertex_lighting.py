"""Per-vertex lighting (the default on software rasterisers) against per-pixel lighting: same figures,
same silhouette, colours within the documented tolerance (Renderer's ``lighting`` parameter).

Measured on the built-in avatar at 1280x720 (llvmpipe): mean difference 1.0 level over the figures'
pixels, 95 % within 4 levels, 99 % within 9; the rest lie on the seams between materials (hair and
skin, the belt), where the pixel path takes one vertex's material for a whole triangle and the vertex
path blends the two, up to about 100 levels on single pixels."""
from __future__ import annotations

import numpy as np
import pytest

from render_helpers import RELAXED, posed
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_NAMES
from studyapp.render.context import OffscreenTarget
from studyapp.render.pose import prepare_slot
from studyapp.render.renderer import Renderer, is_software_renderer
from studyapp.render.scene import make_scene

pytestmark = pytest.mark.gl

SIZE = (1280, 720)  # the participant's frame: triangles of about three pixels each
MEAN_TOL = 1.5      # mean |difference| over the figures' pixels, in 8-bit levels (max over R, G, B)
LEVEL_TOL = 12      # ... and at least SHARE_TOL of those pixels within this many levels
SHARE_TOL = 0.99


def render(renderer, scene, t=0.0, figures=True):
    target = OffscreenTarget(renderer.ctx, SIZE)
    try:
        renderer.draw_trial(scene, t, target.fbo, figures=figures)
        return target.read_rgb().astype(int)
    finally:
        target.release()


@pytest.fixture(scope="module")
def scene(avatar):
    w = np.zeros((2, 52), np.float32)
    w[:, ARKIT_NAMES.index("jawOpen")] = 0.5
    w[:, ARKIT_NAMES.index("mouthSmileLeft")] = 0.6
    slots = [prepare_slot(avatar, posed(avatar, RELAXED, 2), FaceAnimation(w, 30.0)),
             prepare_slot(avatar, posed(avatar, {"LeftUpperArm": (0, 0, -40), "Head": (10, 25, 0)}, 2), None),
             prepare_slot(avatar, posed(avatar, {"RightLowerArm": (0, 70, 0), "Spine": (0, 0, 12)}, 2), None)]
    return make_scene(slots, avatar, labels=("A", "B", "C"))


def test_software_renderers_light_per_vertex(gl_ctx, renderer):
    assert renderer.lighting == ("vertex" if is_software_renderer(gl_ctx) else "pixel")
    with pytest.raises(ValueError, match="lighting"):
        Renderer(gl_ctx, lighting="flat")


def test_vertex_lighting_matches_pixel_lighting_within_tolerance(gl_ctx, scene):
    pixel, vertex = Renderer(gl_ctx, lighting="pixel"), Renderer(gl_ctx, lighting="vertex")
    empty = render(pixel, scene, figures=False)
    a, b = render(pixel, scene), render(vertex, scene)
    fig_a = (a != empty).any(axis=2)
    fig_b = (b != empty).any(axis=2)
    assert fig_a.sum() > 0.05 * fig_a.size  # three figures are there
    # the same triangles cover the same pixels: the silhouette is exactly the same
    # (a pixel whose lit colour happens to equal the backdrop's is the only way for the masks to differ)
    assert (fig_a != fig_b).sum() <= 0.0005 * fig_a.sum()
    assert np.array_equal(a[~fig_a & ~fig_b], b[~fig_a & ~fig_b])  # backdrop, floor, labels untouched
    d = np.abs(a - b).max(axis=2)[fig_a]
    assert d.mean() <= MEAN_TOL, d.mean()
    assert np.mean(d <= LEVEL_TOL) >= SHARE_TOL, np.mean(d <= LEVEL_TOL)
    assert d.max() > 0  # really a different program (per-vertex colours are interpolated)
    # the shading is still there: the lit figure is far from flat in either mode
    assert b[fig_b].std() > 20
