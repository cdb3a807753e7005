"""Keeps the last 3D view in a texture so unchanged frames cost one textured quad, not a re-render.

While the participant ranks (or the clip is paused) the avatars do not move, yet the UI still redraws
every frame; re-rendering three skinned, multisampled avatars each time would keep a laptop's CPU or
GPU busy for nothing (and slow the offscreen bot tenfold on a software renderer).

The texture is the renderer's own finished picture (:meth:`~studyapp.render.renderer.Renderer.render_texture`),
not a copy of it: a new picture costs the renderer's drawing and one quad. It is redrawn when (scene,
time, size) change or the renderer drew something else since.

Given the colour around the scene (``background``), the whole frame comes from the renderer instead
(:meth:`~studyapp.render.renderer.Renderer.draw_canvas`: the scene in its viewport of a buffer the size of
the target, the background around it) and reaches the target in one framebuffer copy: no clear and no
quad, which on a software rasteriser (llvmpipe) is a full shading pass costing several copies.

Given the UI drawn over the scene (``overlay``, a callable drawing into the bound framebuffer), a new
picture gets it in the renderer's canvas before that copy: llvmpipe then rasterises the UI with the last
slot and the frame waits for its raster threads once (at the copy), not twice (at the copy, then at the
read-back or swap for the UI). The canvas then holds the UI, so when the same picture is asked for again
(paused, ranking) it is drawn once more, clean, and from then on copied with the UI drawn on the target.
The pixels are the same either way: the UI is blended over the same picture.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable

import moderngl
import numpy as np

if TYPE_CHECKING:
    from studyapp.render.renderer import Renderer
    from studyapp.render.scene import TrialScene

_VERT = """
#version 330
in vec2 in_pos;
out vec2 v_uv;
uniform vec4 u_rect;  // x, y, w, h in normalized device coordinates
void main() {
    v_uv = in_pos;
    gl_Position = vec4(u_rect.xy + in_pos * u_rect.zw, 0.0, 1.0);
}
"""
_FRAG = """
#version 330
in vec2 v_uv;
out vec4 f_color;
uniform sampler2D u_image;
void main() { f_color = vec4(texture(u_image, v_uv).rgb, 1.0); }
"""


class SceneCache:
    """Shows ``renderer.render_texture``, drawn anew when (scene, time, size) change."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.prog = ctx.program(vertex_shader=_VERT, fragment_shader=_FRAG)
        quad = np.array([0, 0, 1, 0, 0, 1, 1, 1], dtype="f4")
        self.vbo = ctx.buffer(quad.tobytes())
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "2f", "in_pos")])
        self.tex: moderngl.Texture | None = None
        self.canvas: moderngl.Framebuffer | None = None  # the renderer's, with the background drawn around
        self.key: tuple | None = None
        self._drawn = -1  # renderer.frames_drawn when self.tex was drawn
        self._overlaid = False  # self.canvas holds the last frame's overlay (not the clean picture)
        self.renders = 0

    def draw(self, renderer: Renderer, scene: TrialScene, t: float, target: moderngl.Framebuffer,
             viewport: tuple[int, int, int, int], target_size: tuple[int, int],
             background: tuple[float, float, float] | None = None,
             overlay: Callable[[], None] | None = None) -> None:
        """Draw the scene at ``t`` into ``viewport`` (GL pixels, origin bottom-left) of ``target``; with
        ``background`` (rgb), fill the rest of the target with it (the caller need not clear). ``overlay``
        draws what goes over the whole frame (the UI) into the bound framebuffer, once, after the scene."""
        x, y, w, h = (int(v) for v in viewport)
        if background is not None:
            if renderer.draws_canvas:
                self._draw_canvas(renderer, scene, t, target, (x, y, w, h), target_size, tuple(background), overlay)
                return
            target.use()
            target.clear(*background, 1.0)
        key = (id(scene), round(float(t), 6), w, h, id(renderer))
        if key != self.key or self.tex is None or self._drawn != renderer.frames_drawn:
            self.tex = renderer.render_texture(scene, t, (w, h))
            self.canvas = None
            self._drawn = renderer.frames_drawn
            self.key = key
            self.renders += 1
        target.use()
        ctx = self.ctx
        ctx.viewport = (0, 0, *target_size)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
        tw, th = target_size
        self.prog["u_rect"].value = (2 * x / tw - 1, 2 * y / th - 1, 2 * w / tw, 2 * h / th)
        filt = self.tex.filter
        self.tex.filter = (moderngl.NEAREST, moderngl.NEAREST)  # pixel for pixel, whatever the renderer needs
        self.tex.use(0)
        self.prog["u_image"].value = 0
        self.vao.render(moderngl.TRIANGLE_STRIP)
        self.tex.filter = filt
        if overlay is not None:
            overlay()

    def _draw_canvas(self, renderer: Renderer, scene: TrialScene, t: float, target: moderngl.Framebuffer,
                     viewport: tuple[int, int, int, int], target_size: tuple[int, int],
                     background: tuple[float, float, float], overlay: Callable[[], None] | None) -> None:
        tw, th = (int(v) for v in target_size)
        key = ("canvas", id(scene), round(float(t), 6), viewport, (tw, th), background, id(renderer))
        again = key == self.key and self.canvas is not None and self._drawn == renderer.frames_drawn
        if not again or self._overlaid:
            self.canvas = renderer.draw_canvas(scene, t, (tw, th), viewport, background)
            self.tex = None
            self._drawn = renderer.frames_drawn
            self.renders += 1
            self._overlaid = False
            if overlay is not None and not again:  # a new picture: the UI goes into it before the one copy
                self.canvas.use()
                overlay()
                self._overlaid = True
                overlay = None
            self.key = key
        self.ctx.copy_framebuffer(target, self.canvas)
        if overlay is not None:  # the same picture again: copied clean, the UI over it on the target
            target.use()
            overlay()

    def release(self) -> None:
        self.tex = self.canvas = None  # the renderer's: it releases them
        for obj in (self.vao, self.vbo, self.prog):
            obj.release()
