"""The renderer's speed-ups on software rasterisers keep the picture: conservative FXAA rectangles, the
two-pass FXAA, the cached backdrop and the vertex-local triangle order."""
from __future__ import annotations

import numpy as np
import pytest

from render_helpers import RELAXED, posed
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_NAMES
from studyapp.render.context import OffscreenTarget
from studyapp.render.gpu import morph_texture_data, skin_groups, vertex_local_order
from studyapp.render.pose import prepare_slot
from studyapp.render.renderer import Renderer
from studyapp.render.scene import make_scene

pytestmark = pytest.mark.gl

WIDE = {"LeftUpperArm": (20, 30, -10), "RightUpperArm": (-20, -40, 15), "LeftLowerArm": (0, -90, 0),
        "RightLowerArm": (0, 70, 0), "Head": (15, 25, 0), "Spine": (10, 0, 8)}


def _scene(avatar):
    w = np.zeros((2, 52), np.float32)
    w[:, ARKIT_NAMES.index("jawOpen")] = 1.0
    w[:, ARKIT_NAMES.index("mouthSmileLeft")] = 1.0
    face = FaceAnimation(w, 30.0)
    slots = [prepare_slot(avatar, posed(avatar, pose, 2), face) for pose in (RELAXED, WIDE, {})]
    return make_scene(slots, avatar, labels=("A", "B", "C"))


def _frame(renderer, scene, size, figures=True):
    target = OffscreenTarget(renderer.ctx, size)
    try:
        renderer.draw_trial(scene, 0.0, target.fbo, figures=figures)
        return target.read_rgb()
    finally:
        target.release()


def test_triangle_order_is_a_permutation(avatar):
    tris = vertex_local_order(avatar.indices)
    assert sorted(map(tuple, tris)) == sorted(map(tuple, np.asarray(avatar.indices).reshape(-1, 3)))


@pytest.mark.parametrize("size", [(1280, 720), (640, 300)])
def test_fxaa_rectangles_hold_every_figure_pixel(gl_ctx, avatar, size):
    scene = _scene(avatar)
    plain = Renderer(gl_ctx, samples=0)
    fig = np.abs(_frame(plain, scene, size).astype(int) - _frame(plain, scene, size, figures=False)).max(-1) > 0
    aa = Renderer(gl_ctx, software_aa="fxaa")
    _frame(aa, scene, size)
    w, h = size
    inside = np.zeros((h, w), bool)
    for rects in aa._aa_rects:
        for x, y, rw, rh in rects:
            inside[h - (y + rh):h - y, x:x + rw] = True
    assert fig.any()
    assert not (fig & ~inside).any()
    assert inside.mean() < 0.9  # and they are not just the whole frame


def test_fxaa_is_deterministic_and_stays_in_its_rectangles(gl_ctx, avatar):
    scene = _scene(avatar)
    aa = Renderer(gl_ctx, software_aa="fxaa")
    if aa.antialiasing != "fxaa":
        pytest.skip("FXAA is used on software rasterisers only")
    a = _frame(aa, scene, (960, 540))
    assert (a == _frame(aa, scene, (960, 540))).all()
    plain = _frame(Renderer(gl_ctx, samples=0), scene, (960, 540))
    diff = np.abs(a.astype(int) - plain).max(-1)
    assert diff.max() > 40  # edges were smoothed
    inside = np.zeros(diff.shape, bool)
    for rects in aa._aa_rects:
        for x, y, rw, rh in rects:
            inside[540 - (y + rh):540 - y, x:x + rw] = True
    assert not (diff > 0)[~inside].any()


def test_cached_backdrop_matches_after_resize_and_slot_count(gl_ctx, avatar):
    scene = _scene(avatar)
    one = make_scene(scene.slots[:1], avatar, labels=None)
    r = Renderer(gl_ctx, samples=0)
    for s, size in ((scene, (640, 360)), (one, (640, 360)), (scene, (500, 400)), (scene, (640, 360))):
        fresh = _frame(Renderer(gl_ctx, samples=0), s, size)
        assert (_frame(r, s, size) == fresh).all()


def _texture_rgb(tex):
    w, h = tex.size
    return np.frombuffer(tex.read(), np.uint8).reshape(h, w, 4)[::-1, :, :3]


@pytest.mark.parametrize("kind", ["default", "none", "fxaa", "msaa"])
def test_render_texture_and_the_scene_cache_show_the_draw_trial_picture(gl_ctx, avatar, kind):
    """The participant UI shows the renderer's own texture (no copy) through the scene cache: pixel for
    pixel what ``draw_trial`` writes into a framebuffer (what stills, videos and ``view`` show)."""
    from studyapp.ui.scene_cache import SceneCache

    make = {"default": lambda: Renderer(gl_ctx), "none": lambda: Renderer(gl_ctx, samples=0),
            "fxaa": lambda: Renderer(gl_ctx, software_aa="fxaa"), "msaa": lambda: Renderer(gl_ctx, software_aa="msaa")}
    scene = _scene(avatar)
    size = (480, 270)
    renderer = make[kind]()
    want = _frame(renderer, scene, size)
    assert np.abs(want.astype(int) - _frame(renderer, scene, size, figures=False)).max() > 40  # figures drawn
    got = _texture_rgb(renderer.render_texture(scene, 0.0, size))
    assert (got == want).all()
    cache = SceneCache(gl_ctx)
    target = OffscreenTarget(gl_ctx, size)
    try:
        cache.draw(renderer, scene, 0.0, target.fbo, (0, 0, *size), size)
        assert (target.read_rgb() == want).all()
        renderer.draw_trial(scene, 0.0, target.fbo, figures=False)  # the renderer draws something else ...
        cache.draw(renderer, scene, 0.0, target.fbo, (0, 0, *size), size)
        assert (target.read_rgb() == want).all() and cache.renders == 2  # ... so the cache draws anew
        cache.draw(renderer, scene, 0.0, target.fbo, (0, 0, *size), size)
        assert cache.renders == 2  # nothing changed: the same picture, not drawn again
    finally:
        target.release()
        cache.release()


def test_software_renderers_draw_without_an_extra_pass_by_default(gl_ctx):
    from studyapp.render.renderer import is_software_renderer

    r = Renderer(gl_ctx)
    if is_software_renderer(gl_ctx):
        assert (r.antialiasing, r.samples, r.fxaa) == ("none", 0, False)
        assert Renderer(gl_ctx, software_aa="fxaa").antialiasing == "fxaa"
        assert Renderer(gl_ctx, software_aa="msaa").antialiasing == "msaa"
    else:  # GPUs keep the MSAA they asked for, whatever the software setting
        assert r.antialiasing == "msaa" and r.samples > 0
    with pytest.raises(ValueError):
        Renderer(gl_ctx, software_aa="smaa")


@pytest.mark.parametrize("kind", ["default", "msaa", "fxaa"])
def test_scene_cache_with_a_background_fills_the_frame_like_clear_and_quad(gl_ctx, avatar, kind):
    """Given the colour around the scene, the cache fills the whole target in one copy of the renderer's
    canvas (no clear, no quad): pixel for pixel the cleared frame with the scene's picture in its
    viewport, at an offset as in the participant window (panel below, margins)."""
    from studyapp.ui.scene_cache import SceneCache

    make = {"default": lambda: Renderer(gl_ctx), "fxaa": lambda: Renderer(gl_ctx, software_aa="fxaa"),
            "msaa": lambda: Renderer(gl_ctx, software_aa="msaa")}
    renderer = make[kind]()
    scene = _scene(avatar)
    size, viewport, bg = (520, 330), (23, 51, 480, 270), (0.11, 0.12, 0.14)
    want = np.empty((size[1], size[0], 3), np.uint8)
    want[:] = np.round(np.array(bg) * 255).astype(np.uint8)
    x, y, w, h = viewport
    rows = slice(size[1] - y - h, size[1] - y)  # read_rgb is top row first, GL's y from the bottom
    want[rows, x:x + w] = _frame(renderer, scene, (w, h))
    cache = SceneCache(gl_ctx)
    target = OffscreenTarget(gl_ctx, size)
    try:
        target.fbo.use()
        target.fbo.clear(1.0, 0.0, 1.0, 1.0)  # whatever was there before: all of it is replaced
        cache.draw(renderer, scene, 0.0, target.fbo, viewport, size, bg)
        got = target.read_rgb()
        assert np.abs(got.astype(int) - want).max() <= 1, np.abs(got.astype(int) - want).max()
        cache.draw(renderer, scene, 0.0, target.fbo, viewport, size, bg)
        assert cache.renders == 1 and (target.read_rgb() == got).all()  # unchanged: copied, not drawn again
    finally:
        target.release()
        cache.release()


def test_floor_quad_covers_only_what_the_floor_changes(gl_ctx, avatar, monkeypatch):
    """The floor is drawn over the fading ellipse and the contact shadows only (``floor_bounds``, whose
    doctest covers a shadow reaching out of the ellipse): the same picture as the whole floor square, at
    most a level apart on single pixels where a shadow's tail rounds differently."""
    import studyapp.render.renderer as rr

    scene = _scene(avatar)
    size = (640, 360)
    got = _frame(Renderer(gl_ctx), scene, size).astype(int)
    bounds = []
    real = rr.floor_bounds
    monkeypatch.setattr(rr, "floor_bounds", lambda h, f: bounds.append(real(h, f)) or (-2.5, -2.5, 2.5, 2.5))
    want = _frame(Renderer(gl_ctx), scene, size).astype(int)
    d = np.abs(got - want).max(axis=2)
    assert d.max() <= 1 and (d > 0).sum() <= 50, (d.max(), (d > 0).sum())
    assert all(b[2] - b[0] < 4.0 for b in bounds)  # really less than the square
    # the square's floor is visible: drawing none at all would differ a lot
    monkeypatch.setattr(rr, "floor_bounds", lambda h, f: (0.0, 0.0, 0.0, 0.0))
    assert np.abs(_frame(Renderer(gl_ctx), scene, size).astype(int) - want).max() > 20


def test_morph_rows_are_the_vertices_any_morph_moves():
    """The packing's row selection (computed on a flat view for speed) against a per-vertex loop."""
    rng = np.random.default_rng(3)
    d = np.zeros((5, 40, 3), np.float32)
    for m, v, c in zip(rng.integers(0, 5, 30), rng.integers(0, 40, 30), rng.integers(0, 3, 30)):
        d[m, v, c] = rng.choice([-1e-7, 0.5, -2.0])
    rows, tex = morph_texture_data(d)
    moved = [v for v in range(40) if any(d[m, v, c] != 0 for m in range(5) for c in range(3))]
    assert rows[moved].tolist() == list(range(len(moved)))
    assert (rows[[v for v in range(40) if v not in moved]] == -1).all()
    flat = tex.reshape(-1, 4)
    for m in range(5):
        for r, v in enumerate(moved):
            assert flat[m * len(moved) + r, :3].tolist() == d[m, v].tolist()


def test_software_renderer_flushes_between_slots_and_keeps_the_picture(gl_ctx, avatar, monkeypatch):
    """Each slot but the last is handed to llvmpipe's raster threads (a real glFlush, found through the GL
    dispatch library) while the next one's vertices are shaded; the picture is the unflushed one."""
    import studyapp.render.context as context
    import studyapp.render.renderer as renderer_mod
    from studyapp.render.renderer import is_software_renderer

    if not is_software_renderer(gl_ctx):
        pytest.skip("flushing between slots is for software rasterisers")
    scene = _scene(avatar)
    r = Renderer(gl_ctx)
    assert r.flush_slots
    calls = []

    def counted():
        calls.append(1)
        context.gl_flush()

    monkeypatch.setattr(renderer_mod, "gl_flush", counted)
    flushed = _frame(r, scene, (640, 360))
    assert len(calls) == scene.n_slots - 1
    import ctypes.util

    context.gl_flush()
    if ctypes.util.find_library("OpenGL") or ctypes.util.find_library("GL"):
        assert context._GL_FLUSH[0] is not None  # a real glFlush (EGL through glvnd here), not the do-nothing fallback
    r.flush_slots = False
    assert np.array_equal(_frame(r, scene, (640, 360)), flushed)


def test_skin_groups_leave_out_only_zero_weights_and_unmoved_vertices(avatar):
    rows, _ = morph_texture_data(avatar.morph_deltas)
    order, groups = skin_groups(avatar.indices, avatar.weights, rows)
    tris = np.asarray(avatar.indices).reshape(-1, 3)
    assert sorted(map(tuple, order)) == sorted(map(tuple, tris))
    assert sum(count for *_, count in groups) == order.size and groups[0][2] == 0
    for morphs, bones, first, count in groups:
        verts = np.unique(order.reshape(-1)[first:first + count])
        assert not avatar.weights[verts, bones:].any()
        if not morphs:
            assert (rows[verts] < 0).all()
    # the built-in avatar has both kinds: the body without morphs (up to 4 joints), the head with morphs on
    # at most 2: two variants to compile on a participant's first frame, no more
    assert [(m, b) for m, b, *_ in groups] == [(False, 4), (True, 2)]


def test_specialised_vertex_programs_draw_the_picture_of_the_general_one(gl_ctx, avatar):
    """Each group drawn with its own variant (no morph loop, fewer joints) is, pixel for pixel, the whole
    avatar drawn with the general program (morphs, four joints) -- in every lighting."""
    scene = _scene(avatar)
    for lighting in ("vertex", "pixel"):
        r = Renderer(gl_ctx, samples=0, lighting=lighting)
        specialised = _frame(r, scene, (640, 360))
        mesh = r.upload_avatar(avatar)
        assert len(mesh.groups) > 1
        mesh.groups = [(True, 4, 0, sum(count for *_, count in mesh.groups))]
        assert np.array_equal(_frame(r, scene, (640, 360)), specialised), lighting


def test_scene_cache_blends_the_ui_into_a_new_picture_before_its_one_copy(gl_ctx, avatar):
    """``overlay`` (the UI) goes into the renderer's canvas of a new picture, before the copy to the
    target (one wait for llvmpipe's raster threads, not two); the same picture asked again is drawn clean
    once more and copied, the UI blended on the target: never twice over the picture. Every frame is,
    pixel for pixel, the scene copied and the UI blended over it on the target."""
    import moderngl

    from studyapp.ui.scene_cache import SceneCache

    renderer = Renderer(gl_ctx)
    if not renderer.draws_canvas:
        pytest.skip("no canvas with FXAA")
    scene = _scene(avatar)
    size, viewport, bg = (520, 330), (23, 51, 480, 270), (0.11, 0.12, 0.14)
    prog = gl_ctx.program(vertex_shader="""#version 330
        void main() { gl_Position = vec4(vec2(gl_VertexID & 1, gl_VertexID >> 1) * 3.0 - 1.0, 0.0, 1.0); }""",
                          fragment_shader="""#version 330
        out vec4 c; void main() { c = vec4(1.0, 0.5, 0.0, 0.5); }""")
    vao = gl_ctx.vertex_array(prog, [])
    bound = []

    def overlay():  # half-transparent over the lower left: a second blend would show
        bound.append(gl_ctx.fbo)
        gl_ctx.viewport = (0, 0, size[0] // 2, size[1] // 2)
        gl_ctx.enable(moderngl.BLEND)
        gl_ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        vao.render(moderngl.TRIANGLES, vertices=3)
        gl_ctx.disable(moderngl.BLEND)
        gl_ctx.viewport = (0, 0, *size)

    target = OffscreenTarget(gl_ctx, size)
    old, new = SceneCache(gl_ctx), SceneCache(gl_ctx)
    try:
        want = {}
        for t in (0.0, 1.0):
            old.draw(renderer, scene, t, target.fbo, viewport, size, bg)
            target.fbo.use()
            overlay()
            want[t] = target.read_rgb()
        bound.clear()
        for t in (0.0, 0.0, 0.0, 1.0):
            target.fbo.use()
            target.fbo.clear(1.0, 0.0, 1.0, 1.0)
            new.draw(renderer, scene, t, target.fbo, viewport, size, bg, overlay=overlay)
            got = target.read_rgb()
            assert np.array_equal(got, want[t]), (t, np.abs(got.astype(int) - want[t]).max())
        assert len(bound) == 4
        assert bound[0] is not target.fbo and bound[0] is new.canvas  # new picture: into the canvas
        assert bound[1] is target.fbo and bound[2] is target.fbo  # asked again: over the clean copy
        assert bound[3] is new.canvas
        assert new.renders == 3  # t=0, t=0 once more clean, t=1
    finally:
        target.release()
        old.release()
        new.release()


def test_backdrop_is_drawn_once_for_stills_and_the_participant_canvas(gl_ctx, avatar, monkeypatch):
    """When the slots cover the whole buffer the background colour shows nowhere, so ``draw_trial`` and the
    participant's full-frame canvas share one cached backdrop (alternating, each redrew it on main), with
    the same pixels as a fresh renderer."""
    r = Renderer(gl_ctx, samples=0)
    scene = _scene(avatar)
    size = (480, 270)
    drawn = []
    real = r._empty_vao.render
    monkeypatch.setattr(r, "_empty_vao", type("V", (), {"render": lambda self, *a, **k: (drawn.append(1), real(*a, **k))})())
    target = OffscreenTarget(gl_ctx, size)
    try:
        for _ in range(2):
            canvas = r.draw_canvas(scene, 0.0, size, (0, 0, *size), (0.11, 0.12, 0.14))
            gl_ctx.copy_framebuffer(target.fbo, canvas)
            via_canvas = target.read_rgb()
            assert np.array_equal(_frame(r, scene, size), via_canvas)
        assert len(drawn) == scene.n_slots  # one backdrop per slot, drawn once
        assert np.array_equal(_frame(Renderer(gl_ctx, samples=0), scene, size), via_canvas)
    finally:
        target.release()
