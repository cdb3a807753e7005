"""Draw a trial: up to three skinned, morphing avatars side by side, identically framed and lit.

Per frame the CPU only blends two precomputed palettes per slot, writes them to three small uniform
buffers and sets the handful of non-zero morph weights; skinning and morphing run in the vertex
shader. Drawing goes to a multisample framebuffer owned by the renderer, which is then resolved into the
caller's framebuffer (an :class:`~studyapp.render.context.OffscreenTarget` or a window's). On software
rasterisers (llvmpipe) an FXAA pass replaces MSAA by default (see :class:`Renderer`).

Example (headless)::

    >>> from studyapp.render.context import create_offscreen_context, OffscreenTarget
    >>> from studyapp.render.avatar import build_default_avatar
    >>> from studyapp.render.pose import prepare_slot
    >>> from studyapp.render.scene import make_scene
    >>> from studyapp.motion.skeleton import Motion
    >>> ctx = create_offscreen_context()
    >>> av = build_default_avatar()
    >>> slot = prepare_slot(av, Motion.rest(av.skeleton, 2, 30.0), None)
    >>> scene = make_scene([slot] * 3, av, labels=("A", "B", "C"))
    >>> target = OffscreenTarget(ctx, (384, 216))
    >>> Renderer(ctx).draw_trial(scene, 0.0, target.fbo)
    >>> target.read_rgb().shape
    (216, 384, 3)
"""
from __future__ import annotations

import moderngl
import numpy as np

from studyapp.render.avatar import Avatar
from studyapp.render.gpu import MAX_ACTIVE_MORPHS, AvatarMesh, rasterize_label
from studyapp.resources import read_shader

BACKGROUND_TOP = (0.86, 0.87, 0.89)
BACKGROUND_BOTTOM = (0.66, 0.67, 0.69)
FLOOR_COLOR = (0.60, 0.61, 0.63)
LABEL_COLOR = (0.22, 0.23, 0.26, 0.9)
MAX_CACHED_AVATARS = 4  # GPU meshes kept for avatars not drawn lately (a study normally uses one)
MORPH_EPS = 1e-4  # weights below this are skipped (invisible, and it keeps the vertex loop short)


def slot_viewports(viewport: tuple[int, int, int, int], n: int) -> list[tuple[int, int, int, int]]:
    """Split ``(x, y, w, h)`` into ``n`` equal columns, left to right (integer pixels, no gaps).

    >>> slot_viewports((0, 0, 1280, 720), 3)
    [(0, 0, 427, 720), (427, 0, 426, 720), (853, 0, 427, 720)]
    """
    x, y, w, h = viewport
    edges = [x + round(w * i / n) for i in range(n + 1)]
    return [(edges[i], y, edges[i + 1] - edges[i], h) for i in range(n)]


SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "swiftshader", "software rasterizer")


def is_software_renderer(ctx: moderngl.Context) -> bool:
    """True for CPU rasterisers (Mesa llvmpipe/softpipe, SwiftShader), where MSAA is very expensive."""
    name = str(ctx.info.get("GL_RENDERER", "")).lower()
    return any(s in name for s in SOFTWARE_RENDERERS)


class Renderer:
    """Draws :class:`~studyapp.render.scene.TrialScene` frames into any framebuffer of ``ctx``.

    Parameters
    ----------
    samples:
        MSAA sample count (0: no multisampling).
    software_aa:
        What to do on a software rasteriser (llvmpipe), where multisampling costs about three times the
        frame time: ``"fxaa"`` (default) replaces MSAA by one FXAA pass, ``"msaa"`` keeps MSAA anyway.
        On GPUs MSAA is always used as asked.

    ``antialiasing`` tells which method is in use: ``"msaa"``, ``"fxaa"`` or ``"none"``.
    """

    def __init__(self, ctx: moderngl.Context, samples: int = 4, software_aa: str = "fxaa") -> None:
        self.ctx = ctx
        if software_aa not in ("fxaa", "msaa"):
            raise ValueError(f"software_aa must be 'fxaa' or 'msaa', got {software_aa!r}")
        samples = min(int(samples), ctx.max_samples) if samples else 0
        self.fxaa = bool(samples) and software_aa == "fxaa" and is_software_renderer(ctx)
        self.samples = 0 if self.fxaa else samples
        self.antialiasing = "fxaa" if self.fxaa else ("msaa" if self.samples else "none")
        vert = read_shader("fullscreen.vert")
        self.prog = ctx.program(vertex_shader=read_shader("skinned.vert"), fragment_shader=read_shader("skinned.frag"))
        self.bg_prog = ctx.program(vertex_shader=vert, fragment_shader=read_shader("background.frag"))
        self.blit_prog = ctx.program(vertex_shader=vert, fragment_shader=read_shader("blit.frag"))
        self.fxaa_prog = ctx.program(vertex_shader=vert, fragment_shader=read_shader("fxaa.frag"))
        self._fxaa_vao = ctx.vertex_array(self.fxaa_prog, [])
        self.floor_prog = ctx.program(vertex_shader=read_shader("floor.vert"), fragment_shader=read_shader("floor.frag"))
        self.label_prog = ctx.program(vertex_shader=read_shader("label.vert"), fragment_shader=read_shader("label.frag"))
        self._empty_vao = ctx.vertex_array(self.bg_prog, [])
        self._blit_vao = ctx.vertex_array(self.blit_prog, [])
        self._label_vao = ctx.vertex_array(self.label_prog, [])
        quad = np.array([[-2.5, -2.5], [2.5, -2.5], [-2.5, 2.5], [2.5, 2.5]], np.float32)
        self._floor_vbo = ctx.buffer(quad.tobytes())
        self._floor_vao = ctx.vertex_array(self.floor_prog, [(self._floor_vbo, "2f", "in_xz")])
        self.bg_prog["u_top"].value = BACKGROUND_TOP
        self.bg_prog["u_bottom"].value = BACKGROUND_BOTTOM
        self.floor_prog["u_floor"].value = FLOOR_COLOR
        self.prog["Bones"].binding = 0
        self.prog["u_morph_pos"].value = 1
        self.prog["u_morph_nrm"].value = 2
        self.prog["u_base_color"].value = 3
        self.prog["u_model"].write(np.eye(4, dtype="f4").tobytes())
        self._meshes: dict[int, AvatarMesh] = {}
        self._labels: dict[tuple[str, int], moderngl.Texture] = {}
        self._msaa: moderngl.Framebuffer | None = None
        self._resolve: moderngl.Framebuffer | None = None
        self._size: tuple[int, int] | None = None
        self._aa_rects: list[tuple[int, int, int, int]] = []
        self._ids = np.zeros(MAX_ACTIVE_MORPHS, np.int32)
        self._w = np.zeros(MAX_ACTIVE_MORPHS, np.float32)

    # -- resources ------------------------------------------------------------------------------
    def upload_avatar(self, avatar: Avatar) -> AvatarMesh:
        """GPU buffers of ``avatar`` (created once per avatar object and reused by every slot)."""
        key = id(avatar)
        mesh = self._meshes.pop(key, None)
        if mesh is None or mesh.avatar is not avatar:
            mesh = AvatarMesh(self.ctx, avatar, self.prog)
        self._meshes[key] = mesh  # most recently used last
        while len(self._meshes) > MAX_CACHED_AVATARS:
            self._meshes.pop(next(iter(self._meshes))).release()
        return mesh

    def _label_texture(self, text: str, height: int) -> moderngl.Texture:
        key = (text, height)
        tex = self._labels.get(key)
        if tex is None:
            img = rasterize_label(text, height)  # top row first; label.vert flips v
            tex = self.ctx.texture((img.shape[1], img.shape[0]), 1, np.ascontiguousarray(img).tobytes())
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self._labels[key] = tex
        return tex

    def _ensure_buffers(self, size: tuple[int, int]) -> None:
        if self._size == size:
            return
        for fb in {id(f): f for f in (self._msaa, self._resolve) if f is not None}.values():
            if fb is not None:
                for att in list(fb.color_attachments) + [fb.depth_attachment]:
                    if att is not None:
                        att.release()
                fb.release()
        ctx = self.ctx
        if self.samples:
            self._msaa = ctx.framebuffer([ctx.renderbuffer(size, 4, samples=self.samples)],
                                         ctx.depth_renderbuffer(size, samples=self.samples))
            self._resolve = ctx.framebuffer([ctx.texture(size, 4)])
        else:
            # single-sampled: draw straight into a texture that FXAA or the blit reads
            color = ctx.texture(size, 4)
            color.filter = (moderngl.LINEAR, moderngl.LINEAR)
            color.repeat_x = color.repeat_y = False
            self._msaa = ctx.framebuffer([color], ctx.depth_renderbuffer(size))
            self._resolve = self._msaa
        self._size = size

    # -- drawing --------------------------------------------------------------------------------
    def draw_trial(self, scene, t: float, target_fbo: moderngl.Framebuffer,
                   viewport: tuple[int, int, int, int] | None = None, *, figures: bool = True) -> None:
        """Draw ``scene`` at ``t`` seconds into ``viewport`` (x, y, w, h; default: all) of ``target_fbo``.

        ``figures=False`` draws only the backdrop, floor and labels (what a frame looks like without avatars).
        """
        if viewport is None:
            viewport = (0, 0, *target_fbo.size)
        x, y, w, h = (int(v) for v in viewport)
        self._ensure_buffers((w, h))
        fbo = self._msaa
        fbo.use()
        fbo.clear(*BACKGROUND_BOTTOM, 1.0, depth=1.0)
        self._draw_slots(scene, t, (0, 0, w, h), figures)
        self._present(target_fbo, (x, y, w, h), scene.n_slots)

    def _present(self, target: moderngl.Framebuffer, viewport: tuple[int, int, int, int], n_slots: int = 1) -> None:
        x, y, w, h = viewport
        ctx = self.ctx
        if not self.fxaa and (x, y) == (0, 0) and tuple(target.size) == (w, h):
            ctx.copy_framebuffer(target, self._msaa)  # resolves MSAA in one blit
            return
        if self.samples:
            ctx.copy_framebuffer(self._resolve, self._msaa)
        target.use()
        target.viewport = (x, y, w, h)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        self._resolve.color_attachments[0].use(0)
        if self.fxaa:
            # copy everything, then anti-alias only around the figures (the backdrop is smooth already);
            # one pass per slot, clamped to it, so one slot's edges never bleed into the next
            if (x, y) == (0, 0) and tuple(target.size) == (w, h):
                ctx.copy_framebuffer(target, self._resolve)
            else:
                self.blit_prog["u_image"].value = 0
                self._blit_vao.render(moderngl.TRIANGLES, vertices=3)
            target.use()
            self.fxaa_prog["u_image"].value = 0
            self.fxaa_prog["u_texel"].value = (1.0 / w, 1.0 / h)
            for (sx, _, sw, _), (rx, ry, rw, rh) in zip(slot_viewports((0, 0, w, h), n_slots), self._aa_rects):
                if rw <= 0 or rh <= 0:
                    continue
                target.viewport = (x + rx, y + ry, rw, rh)
                self.fxaa_prog["u_rect"].value = (rx / w, ry / h, rw / w, rh / h)
                self.fxaa_prog["u_bounds"].value = ((sx + 0.5) / w, 0.5 / h, (sx + sw - 0.5) / w, 1 - 0.5 / h)
                self._fxaa_vao.render(moderngl.TRIANGLES, vertices=3)
        else:
            self.blit_prog["u_image"].value = 0
            self._blit_vao.render(moderngl.TRIANGLES, vertices=3)
        target.viewport = (0, 0, *target.size)

    def _draw_slots(self, scene, t: float, viewport: tuple[int, int, int, int], figures: bool = True) -> None:
        ctx = self.ctx
        fbo = self._msaa
        vps = slot_viewports(viewport, scene.n_slots)
        aspect = vps[0][2] / max(vps[0][3], 1)
        view_proj = scene.camera.view_proj(aspect)
        vp_bytes = np.ascontiguousarray(view_proj.T, np.float32).tobytes()
        # one palette upload per avatar per frame, all slots at once
        frames = []
        meshes = []
        for i, (slot, avatar) in enumerate(zip(scene.slots, scene.avatars)):
            mesh = self.upload_avatar(avatar)
            pal, wts = slot.frame_at(t)
            mesh.palette.set_row(i, pal)
            frames.append(wts)
            meshes.append(mesh)
        for mesh in {id(m): m for m in meshes}.values():
            mesh.palette.upload()
        self.prog["u_view_proj"].write(vp_bytes)
        self.prog["u_camera_pos"].value = tuple(float(v) for v in scene.camera.eye)
        self.floor_prog["u_view_proj"].write(vp_bytes)
        self._aa_rects = []
        for i, vp in enumerate(vps):
            fbo.viewport = vp
            self._aa_rects.append(self._figure_rect(scene.slots[i].joints_at(t), view_proj, vp) if figures else (0, 0, 0, 0))
            # backdrop
            ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
            self._empty_vao.render(moderngl.TRIANGLES, vertices=3)
            # floor with contact shadow
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
            joints = scene.slots[i].joints_at(t)
            sk = scene.avatars[i].skeleton
            hips = joints[0]
            self.floor_prog["u_shadow_centre"].value = (float(hips[0]), float(hips[2]))
            feet = [joints[sk.index(n)] if n in sk.names else hips for n in ("LeftFoot", "RightFoot")]
            self.floor_prog["u_feet"].write(np.array([[f[0], f[2]] for f in feet], np.float32).tobytes())
            self._floor_vao.render(moderngl.TRIANGLE_STRIP)
            ctx.disable(moderngl.BLEND)
            # avatar
            ctx.enable(moderngl.DEPTH_TEST)
            mesh = meshes[i]
            self._set_morphs(frames[i])
            self.prog["u_morph_rows"].value = mesh.morph_rows
            self.prog["u_has_texture"].value = mesh.has_texture
            self.prog["u_base_factor"].value = tuple(float(v) for v in scene.avatars[i].base_color_factor)
            mesh.palette.bind(i, 0)
            mesh.morph_pos.use(1)
            mesh.morph_nrm.use(2)
            mesh.texture.use(3)
            if figures:
                if not scene.avatars[i].double_sided:
                    ctx.enable(moderngl.CULL_FACE)
                    ctx.front_face = "ccw"
                mesh.vao.render(moderngl.TRIANGLES)
                ctx.disable(moderngl.CULL_FACE)
            ctx.disable(moderngl.DEPTH_TEST)
            if scene.labels:
                self._draw_label(scene.labels[i], vp)
        fbo.viewport = viewport

    @staticmethod
    def _figure_rect(joints: np.ndarray, view_proj: np.ndarray, vp: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
        """Pixel rectangle (in the draw buffer) that surely holds the figure: its joints projected, padded
        by a tenth of the slot height for the head top, hair and fingertips beyond the joints."""
        x, y, w, h = vp
        clip = np.c_[joints, np.ones(len(joints))] @ view_proj.T
        ndc = clip[:, :2] / np.maximum(clip[:, 3:4], 1e-6)
        px = x + (ndc[:, 0] + 1) * 0.5 * w
        py = y + (ndc[:, 1] + 1) * 0.5 * h
        pad = 0.1 * h
        x0 = int(max(x, np.floor(px.min() - pad)))
        x1 = int(min(x + w, np.ceil(px.max() + pad)))
        y0 = int(max(y, np.floor(py.min() - pad)))
        y1 = int(min(y + h, np.ceil(py.max() + pad)))
        return x0, y0, max(0, x1 - x0), max(0, y1 - y0)

    def _set_morphs(self, weights: np.ndarray) -> None:
        active = np.flatnonzero(np.abs(weights) > MORPH_EPS)[:MAX_ACTIVE_MORPHS]
        n = len(active)
        self._ids[:] = 0
        self._w[:] = 0
        self._ids[:n] = active
        self._w[:n] = weights[active]
        self.prog["u_morph_count"].value = n
        self.prog["u_morph_ids"].write(self._ids.tobytes())
        self.prog["u_morph_w"].write(self._w.tobytes())

    def _draw_label(self, text: str, vp: tuple[int, int, int, int]) -> None:
        _, _, w, h = vp
        px = max(12, int(round(h * 0.05)))
        tex = self._label_texture(text, px)
        tw, th = tex.size
        # NDC rectangle centred near the top of the slot
        x0 = -tw / w
        x1 = tw / w
        y1 = 1.0 - 2 * (0.025 * h) / h
        y0 = y1 - 2 * th / h
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        tex.use(0)
        self.label_prog["u_text"].value = 0
        self.label_prog["u_rect"].value = (x0, y0, x1, y1)
        self.label_prog["u_color"].value = LABEL_COLOR
        self._label_vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        self.ctx.disable(moderngl.BLEND)

    def draw_bare(self, avatar: Avatar, scene, target_fbo: moderngl.Framebuffer, program: moderngl.Program) -> None:
        """Benchmark baseline: the same triangles in the same slots with a trivial shader."""
        w, h = target_fbo.size
        self._ensure_buffers((w, h))
        fbo = self._msaa
        fbo.use()
        fbo.clear(*BACKGROUND_BOTTOM, 1.0, depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        mesh = self.upload_avatar(avatar)
        vao = mesh.bare_vao(program)
        vps = slot_viewports((0, 0, w, h), scene.n_slots)
        program["u_view_proj"].write(np.ascontiguousarray(scene.camera.view_proj(vps[0][2] / vps[0][3]).T, np.float32).tobytes())
        for vp in vps:
            fbo.viewport = vp
            vao.render(moderngl.TRIANGLES)
        self.ctx.disable(moderngl.DEPTH_TEST)
        self._present(target_fbo, (0, 0, w, h), scene.n_slots)

    def release(self) -> None:
        for mesh in self._meshes.values():
            mesh.release()
        self._meshes.clear()
        for tex in self._labels.values():
            tex.release()
        self._labels.clear()
        self._size = None
