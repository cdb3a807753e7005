"""Draw a trial: up to three skinned, morphing avatars side by side, identically framed and lit.

Per frame the CPU only blends two precomputed palettes per slot, writes them to three small uniform
buffers and sets the handful of non-zero morph weights; skinning and morphing run in the vertex
shader, specialised per group of triangles (:func:`~studyapp.render.gpu.skin_groups`: the morph loop only
where a morph moves a vertex, only as many joints as the group's weights use). Drawing goes to a multisample framebuffer owned by the renderer, which is then resolved into the
caller's framebuffer (an :class:`~studyapp.render.context.OffscreenTarget` or a window's), or handed
over as a texture (:meth:`Renderer.render_texture`, so the picture is not copied once more), or as a
whole canvas of the window's size with the scene in its viewport (:meth:`Renderer.draw_canvas`, what the
participant UI's scene cache copies in: one copy, no clear, no quad). On software rasterisers (llvmpipe) MSAA is replaced by default (see
:class:`Renderer`): every full-frame pass there waits for the CPU raster threads while holding the
Python interpreter (and with it the audio callback), so the software path draws with no extra pass;
and there it flushes after each slot (:func:`~studyapp.render.context.gl_flush`), so llvmpipe's raster
threads fill one slot while the calling thread shades the next one's vertices.

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

import logging

import moderngl
import numpy as np

from studyapp.render.avatar import Avatar
from studyapp.render.context import gl_flush
from studyapp.render.gpu import MAX_ACTIVE_MORPHS, AvatarMesh, rasterize_label
from studyapp.resources import read_shader

BACKGROUND_TOP = (0.86, 0.87, 0.89)
BACKGROUND_BOTTOM = (0.66, 0.67, 0.69)
FLOOR_COLOR = (0.60, 0.61, 0.63)
LABEL_COLOR = (0.22, 0.23, 0.26, 0.9)
MAX_CACHED_AVATARS = 4  # GPU meshes kept for avatars not drawn lately (a study normally uses one)
MORPH_EPS = 1e-4  # weights below this are skipped (invisible, and it keeps the vertex loop short)
FXAA_BANDS = 8  # anti-aliasing rectangles per figure (horizontal bands fitted to the figure's joints)
SOFTWARE_AA = ("none", "fxaa", "msaa")

log = logging.getLogger(__name__)
_logged_aa: set[tuple[str, str]] = set()  # (GL renderer, decision): said once per process


def slot_viewports(viewport: tuple[int, int, int, int], n: int) -> list[tuple[int, int, int, int]]:
    """Split ``(x, y, w, h)`` into ``n`` equal columns, left to right (integer pixels, no gaps).

    >>> slot_viewports((0, 0, 1280, 720), 3)
    [(0, 0, 427, 720), (427, 0, 426, 720), (853, 0, 427, 720)]
    """
    x, y, w, h = viewport
    edges = [x + round(w * i / n) for i in range(n + 1)]
    return [(edges[i], y, edges[i + 1] - edges[i], h) for i in range(n)]


FLOOR_EXTENT = 2.5  # half the side of the floor square (m) around the origin
FLOOR_FADE = (1.6, 1.1)  # floor.frag: the floor's own alpha is 0 outside this ellipse (half axes, m)
SHADOW_REACH = ((0.34, 0.24), (0.08, 0.14))  # floor.frag: hips' and feet's shadow scales (m)
SHADOW_CUT = 2.0  # shadow scales beyond which a shadow's alpha is below 1e-4 (under half an 8-bit level)


def floor_bounds(hips, feet) -> tuple[float, float, float, float]:
    """``(x0, z0, x1, z1)``: the part of the floor square where ``floor.frag`` draws anything visible --
    the fading ellipse and every contact shadow -- so the floor quad covers no pixel it leaves unchanged
    (on llvmpipe the floor's per-pixel exponentials are a tenth of the figure-free frame).

    >>> floor_bounds((0, 0.9, 0), [(-0.1, 0, 0.05), (0.1, 0, 0.05)])
    (-1.6, -1.1, 1.6, 1.1)
    >>> floor_bounds((2.3, 0.9, 0), [(2.2, 0, 0), (2.4, 0, 0)])  # a figure far to the side: its shadow
    (-1.6, -1.1, 2.5, 1.1)
    """
    lo = [-FLOOR_FADE[0], -FLOOR_FADE[1]]
    hi = [FLOOR_FADE[0], FLOOR_FADE[1]]
    for (sx, sz), points in zip(SHADOW_REACH, ([hips], list(feet))):
        for p in points:
            x, z = float(p[0]), float(p[2])
            lo = [min(lo[0], x - SHADOW_CUT * sx), min(lo[1], z - SHADOW_CUT * sz)]
            hi = [max(hi[0], x + SHADOW_CUT * sx), max(hi[1], z + SHADOW_CUT * sz)]
    e = FLOOR_EXTENT
    return (max(lo[0], -e), max(lo[1], -e), min(hi[0], e), min(hi[1], e))


SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "swiftshader", "software rasterizer")


def skinned_program(ctx: moderngl.Context, vertex_lighting: bool, textured: bool = True, *,
                    morphs: bool = True, bones: int = 4) -> moderngl.Program:
    """The avatar program: ``skinned.vert`` + ``skinned.frag`` with ``lighting.glsl`` pasted in after their
    ``#version`` line (one definition of the lighting for both stages), lit per pixel, or per vertex when
    ``vertex_lighting`` (``#define VERTEX_LIGHTING``); ``textured=False`` there leaves out the texture
    path and its varyings (``#define UNTEXTURED``). ``morphs=False`` and ``bones`` (1, 2 or 4) specialise
    it for a group of triangles (:func:`~studyapp.render.gpu.skin_groups`): no morph loop, only the first
    ``bones`` joint weights."""
    defines = ("#define VERTEX_LIGHTING\n" if vertex_lighting else "") + \
              ("#define UNTEXTURED\n" if vertex_lighting and not textured else "") + \
              ("" if morphs else "#define NO_MORPHS\n") + f"#define SKIN_BONES {int(bones)}\n"
    head = defines + read_shader("lighting.glsl")

    def source(name: str) -> str:
        version, rest = read_shader(name).split("\n", 1)
        return f"{version}\n{head}\n#line 2\n{rest}"

    return ctx.program(vertex_shader=source("skinned.vert"), fragment_shader=source("skinned.frag"))


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
        frame time: ``"none"`` (default) draws single-sampled with no extra pass (each full-frame pass
        there is a stall while the raster threads finish: FXAA's two cost a fifth of the frame), ``"fxaa"``
        replaces MSAA by an FXAA pass around the figures, ``"msaa"`` keeps MSAA anyway. On GPUs MSAA is
        always used as asked. The choice is made once per renderer and logged once per process.

    lighting:
        ``"pixel"`` lights every pixel; ``"vertex"`` lights every vertex and interpolates the colour
        (a texture's albedo is still applied per pixel). ``None`` (default): per vertex on a software
        rasteriser, per pixel on a GPU. The built-in avatar's triangles cover about three pixels each at
        720p; llvmpipe shades whole 4x4 blocks and sets up every varying per triangle, so per-pixel
        lighting and its six varyings made the renderer 1.7x a bare draw of the same triangles (CPU time),
        per-vertex lighting with one varying (an untextured avatar) 1.15x. It differs from per-pixel
        lighting by a level on average, most at the seams between materials (tolerance in
        ``tests/render/test_vertex_lighting.py``). Double-sided avatars are
        always lit per pixel (which side a pixel shows is known only there).

    ``antialiasing`` tells which method is in use: ``"msaa"``, ``"fxaa"`` or ``"none"``; ``lighting``
    which lighting: ``"pixel"`` or ``"vertex"``.
    """

    def __init__(self, ctx: moderngl.Context, samples: int = 4, software_aa: str = "none",
                 lighting: str | None = None) -> None:
        self.ctx = ctx
        if software_aa not in SOFTWARE_AA:
            raise ValueError(f"software_aa must be one of {', '.join(SOFTWARE_AA)}, got {software_aa!r}")
        samples = min(int(samples), ctx.max_samples) if samples else 0
        software = is_software_renderer(ctx)
        self.fxaa = bool(samples) and software_aa == "fxaa" and software
        self.samples = 0 if (software and software_aa != "msaa") else samples
        self.antialiasing = "fxaa" if self.fxaa else ("msaa" if self.samples else "none")
        if software and samples:
            key = (str(ctx.info.get("GL_RENDERER", "")), self.antialiasing)
            if key not in _logged_aa:
                _logged_aa.add(key)
                log.info("software renderer %s: anti-aliasing %s instead of %dx MSAA", key[0], key[1], samples)
        self.frames_drawn = 0  # pictures drawn so far: a texture from render_texture is valid until the next
        vert = read_shader("fullscreen.vert")
        if lighting not in (None, "pixel", "vertex"):
            raise ValueError(f"lighting must be 'pixel', 'vertex' or None, got {lighting!r}")
        self.lighting = lighting or ("vertex" if software else "pixel")
        # llvmpipe shades vertices on the calling thread and rasterises only when flushed: a flush after
        # each slot lets its raster threads fill one slot while this thread shades the next one's vertices
        # (without it the frame is all vertex work, then all raster work)
        self.flush_slots = software
        # per (lighting, morphs, joints), compiled when a group of triangles first needs it; the passes this
        # renderer never runs (FXAA without it, the blit when every picture is copied whole) are not compiled
        # either: each program costs a compile on a participant's first start (see studyapp.render.warmup)
        self._progs: dict[tuple[str, bool, int], moderngl.Program] = {}
        self.bg_prog = ctx.program(vertex_shader=vert, fragment_shader=read_shader("background.frag"))
        self._blit: tuple[moderngl.Program, moderngl.VertexArray] | None = None
        if self.fxaa:
            self.fxaa_prog = ctx.program(vertex_shader=vert, fragment_shader=read_shader("fxaa.frag"))
            self._fxaa_vao = ctx.vertex_array(self.fxaa_prog, [])
            self.fxaa_edges_prog = ctx.program(vertex_shader=vert, fragment_shader=read_shader("fxaa_edges.frag"))
            self._fxaa_edges_vao = ctx.vertex_array(self.fxaa_edges_prog, [])
        self.floor_prog = ctx.program(vertex_shader=read_shader("floor.vert"), fragment_shader=read_shader("floor.frag"))
        self.label_prog = ctx.program(vertex_shader=read_shader("label.vert"), fragment_shader=read_shader("label.frag"))
        self._empty_vao = ctx.vertex_array(self.bg_prog, [])
        self._label_vao = ctx.vertex_array(self.label_prog, [])
        quad = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float32)  # mapped onto floor_bounds()
        self._floor_vbo = ctx.buffer(quad.tobytes())
        self._floor_vao = ctx.vertex_array(self.floor_prog, [(self._floor_vbo, "2f", "in_xz")])
        self.bg_prog["u_top"].value = BACKGROUND_TOP
        self.bg_prog["u_bottom"].value = BACKGROUND_BOTTOM
        self.floor_prog["u_floor"].value = FLOOR_COLOR
        self._meshes: dict[int, AvatarMesh] = {}
        self._labels: dict[tuple[str, int], moderngl.Texture] = {}
        self._msaa: moderngl.Framebuffer | None = None
        self._resolve: moderngl.Framebuffer | None = None
        self._aa: moderngl.Framebuffer | None = None
        self._size: tuple[int, int] | None = None
        self._backdrop_fbo: moderngl.Framebuffer | None = None
        self._backdrop_key: tuple | None = None
        self._aa_rects: list[list[tuple[int, int, int, int]]] = []
        self._boxes: dict[int, tuple[Avatar, tuple]] = {}
        self._ids = np.zeros(MAX_ACTIVE_MORPHS, np.int32)
        self._w = np.zeros(MAX_ACTIVE_MORPHS, np.float32)
        self._n_morphs = 0
        # per-frame Python on the thread that shades the vertices (llvmpipe), computed once instead:
        self._view: tuple | None = None  # (camera, aspect, view_proj, its bytes, eye) of the last frame
        self._uniforms: dict[int, tuple[moderngl.Program, frozenset[str]]] = {}  # a program's uniform names
        self._feet: dict[int, tuple[object, tuple[int, int, int]]] = {}  # skeleton: hips, left, right foot

    # -- resources ------------------------------------------------------------------------------
    def _program(self, kind: str, morphs: bool = True, bones: int = 4) -> moderngl.Program:
        key = (kind, morphs, bones)
        prog = self._progs.get(key)
        if prog is None:
            prog = skinned_program(self.ctx, kind != "pixel", textured=kind != "vertex-untextured",
                                   morphs=morphs, bones=bones)
            prog["Bones"].binding = 0
            for name, unit in (("u_morph_pos", 1), ("u_morph_nrm", 2), ("u_base_color", 3)):
                if name in prog:
                    prog[name].value = unit
            prog["u_model"].write(np.eye(4, dtype="f4").tobytes())
            self._progs[key] = prog
        return prog

    @property
    def prog(self) -> moderngl.Program:
        """The avatar program of :attr:`lighting` for triangles with morphs and four joints (the general one)."""
        return self._program(self.lighting)

    def _blit_program(self) -> tuple[moderngl.Program, moderngl.VertexArray]:
        if self._blit is None:
            prog = self.ctx.program(vertex_shader=read_shader("fullscreen.vert"), fragment_shader=read_shader("blit.frag"))
            self._blit = (prog, self.ctx.vertex_array(prog, []))
        return self._blit

    def _kind_for(self, avatar: Avatar) -> str:
        if self.lighting != "vertex":
            return self.lighting
        if avatar.double_sided:
            return "pixel"
        if avatar.texture is None or avatar.uv is None:
            return "vertex-untextured"
        return self.lighting

    def program_for(self, avatar: Avatar) -> moderngl.Program:
        """The avatar program that draws ``avatar``: per-pixel lighting for a double-sided avatar even
        when lighting per vertex (only a pixel knows which side of its surface it shows); per vertex,
        without the texture path for an avatar with no texture; else :attr:`prog`."""
        return self._program(self._kind_for(avatar))

    def group_programs(self, avatar: Avatar, mesh: AvatarMesh) -> list[tuple[moderngl.Program, int, int]]:
        """``(program, first, count)`` per group of ``mesh``'s triangles: :meth:`program_for`'s lighting,
        specialised for the group (:func:`~studyapp.render.gpu.skin_groups`)."""
        kind = self._kind_for(avatar)
        return [(self._program(kind, morphs, bones), first, count) for morphs, bones, first, count in mesh.groups]

    def upload_avatar(self, avatar: Avatar) -> AvatarMesh:
        """GPU buffers of ``avatar`` (created once per avatar object and reused by every slot)."""
        key = id(avatar)
        mesh = self._meshes.pop(key, None)
        if mesh is None or mesh.avatar is not avatar:
            mesh = AvatarMesh(self.ctx, avatar)
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
        if self._aa is not None:  # its depth buffer is the draw buffer's, released below
            self._aa.color_attachments[0].release()
            self._aa.release()
            self._aa = None
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
            if self.fxaa:  # FXAA's output; shares the depth buffer, where its first pass marks edges
                self._aa = ctx.framebuffer([ctx.texture(size, 4)], self._msaa.depth_attachment)
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
        self._draw_picture(scene, t, (w, h), figures)
        self._present(target_fbo, (x, y, w, h), scene.n_slots)

    def render_texture(self, scene, t: float, size: tuple[int, int], *, figures: bool = True) -> moderngl.Texture:
        """Draw ``scene`` at ``t`` and return the finished picture as a texture of ``size`` (bottom row first),
        without copying it anywhere: the renderer's own buffer, valid until it draws again (see
        :attr:`frames_drawn`). What :meth:`draw_trial` would copy into a framebuffer, pixel for pixel."""
        w, h = (int(v) for v in size)
        self._draw_picture(scene, t, (w, h), figures)
        if self.fxaa:
            self._fxaa(scene.n_slots)
            return self._aa.color_attachments[0]
        if self.samples:
            self.ctx.copy_framebuffer(self._resolve, self._msaa)
        return self._resolve.color_attachments[0]

    @property
    def draws_canvas(self) -> bool:
        """Whether :meth:`draw_canvas` is available (not with FXAA, whose pass covers the whole buffer)."""
        return not self.fxaa

    def draw_canvas(self, scene, t: float, size: tuple[int, int], viewport: tuple[int, int, int, int],
                    background: tuple[float, float, float], *, figures: bool = True) -> moderngl.Framebuffer:
        """Draw ``scene`` at ``t`` into ``viewport`` (x, y, w, h) of the renderer's own buffer of ``size``,
        the rest of it ``background`` (rgb), and return that framebuffer: ``ctx.copy_framebuffer`` puts
        it into a target of the same size in one copy, with no clear and no textured quad -- on llvmpipe
        a quad over the picture is a full shading pass, several times the cost of the copy. The picture
        is :meth:`render_texture`'s, pixel for pixel, moved to ``viewport``. Valid until the renderer
        draws again (:attr:`frames_drawn`). Not with FXAA (:attr:`draws_canvas`)."""
        if not self.draws_canvas:
            raise RuntimeError("draw_canvas is not available with FXAA")
        w, h = (int(v) for v in size)
        self._draw_picture(scene, t, (w, h), figures, tuple(int(v) for v in viewport), tuple(background))
        return self._msaa

    def _draw_picture(self, scene, t: float, size: tuple[int, int], figures: bool,
                      viewport: tuple[int, int, int, int] | None = None,
                      background: tuple[float, float, float] | None = None) -> None:
        """Draw the frame into ``viewport`` (default: all) of the renderer's own buffer (``self._msaa``) of
        ``size``; ``background`` fills the rest."""
        w, h = size
        viewport = viewport or (0, 0, w, h)
        self.frames_drawn += 1
        self._ensure_buffers((w, h))
        fbo = self._msaa
        fbo.use()
        backdrop = self._backdrop(scene.n_slots, viewport, background)
        if backdrop is None:
            fbo.clear(*(background or BACKGROUND_BOTTOM), 1.0, depth=1.0)
        else:
            # the backdrop never changes: copy the cached one and clear only the depth buffer
            self.ctx.copy_framebuffer(fbo, backdrop)
            fbo.color_mask = (False, False, False, False)
            fbo.clear(depth=1.0)
            fbo.color_mask = (True, True, True, True)
            fbo.use()
        self._draw_slots(scene, t, viewport, figures, backdrop=backdrop is None)

    def _backdrop(self, n_slots: int, viewport: tuple[int, int, int, int],
                  background: tuple[float, float, float] | None) -> moderngl.Framebuffer | None:
        """The backdrop of every slot in ``viewport`` (``background`` around it), drawn once per size,
        viewport, background and slot count into a texture (single-sampled drawing only: a blit cannot
        fill a multisample buffer). None when it must be drawn per frame."""
        if self.samples:
            return None
        if tuple(viewport) == (0, 0, *self._size):
            background = None  # the slots' backdrops cover it all: the same picture for any background
        key = (self._size, n_slots, viewport, background)
        if self._backdrop_key != key:
            if self._backdrop_fbo is None or self._backdrop_fbo.size != self._size:
                if self._backdrop_fbo is not None:
                    self._backdrop_fbo.color_attachments[0].release()
                    self._backdrop_fbo.release()
                self._backdrop_fbo = self.ctx.framebuffer([self.ctx.texture(self._size, 4)])
            fbo = self._backdrop_fbo
            fbo.use()
            fbo.clear(*(background or BACKGROUND_BOTTOM), 1.0)
            self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
            for vp in slot_viewports(viewport, n_slots):
                fbo.viewport = vp
                self._empty_vao.render(moderngl.TRIANGLES, vertices=3)
            fbo.viewport = (0, 0, *self._size)
            self._backdrop_key = key
            self._msaa.use()
        return self._backdrop_fbo

    def _present(self, target: moderngl.Framebuffer, viewport: tuple[int, int, int, int], n_slots: int = 1) -> None:
        x, y, w, h = viewport
        ctx = self.ctx
        if not self.fxaa and (x, y) == (0, 0) and tuple(target.size) == (w, h):
            ctx.copy_framebuffer(target, self._msaa)  # resolves MSAA in one blit
            return
        if self.fxaa:
            self._fxaa(n_slots)
            source = self._aa
        else:
            if self.samples:
                ctx.copy_framebuffer(self._resolve, self._msaa)
            source = self._resolve
        if (x, y) == (0, 0) and tuple(target.size) == (w, h):
            ctx.copy_framebuffer(target, source)
        else:
            target.use()
            target.viewport = (x, y, w, h)
            ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
            source.color_attachments[0].use(0)
            blit_prog, blit_vao = self._blit_program()
            blit_prog["u_image"].value = 0
            blit_vao.render(moderngl.TRIANGLES, vertices=3)
            target.viewport = (0, 0, *target.size)

    def _fxaa(self, n_slots: int) -> None:
        """Anti-alias the drawn image into ``self._aa``, only around the figures (the backdrop is smooth
        already), one slot at a time and clamped to it so one slot's edges never bleed into the next.

        Two passes over each figure's rectangles: ``fxaa_edges.frag`` marks the pixels with contrast in the
        depth buffer (which the scene no longer needs), then ``fxaa.frag`` runs depth-tested against the
        marks, so the costly edge search is skipped for blocks with no edge (about four fifths of them)."""
        ctx = self.ctx
        w, h = self._size
        aa = self._aa
        ctx.copy_framebuffer(aa, self._resolve)  # pixels FXAA leaves alone
        aa.use()
        ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        ctx.enable(moderngl.DEPTH_TEST)
        self._resolve.color_attachments[0].use(0)
        progs = (self.fxaa_edges_prog, self.fxaa_prog)
        for prog in progs:
            prog["u_image"].value = 0
            prog["u_texel"].value = (1.0 / w, 1.0 / h)
        for pass_, (prog, vao) in enumerate(((self.fxaa_edges_prog, self._fxaa_edges_vao), (self.fxaa_prog, self._fxaa_vao))):
            if pass_ == 0:  # write the marks, not the colour
                ctx.depth_func = "1"
                aa.color_mask = (False, False, False, False)
                aa.depth_mask = True
            else:  # the full-screen triangle lies at depth 0.5: passes where the mark is 1
                ctx.depth_func = "<"
                aa.color_mask = (True, True, True, True)
                aa.depth_mask = False
            aa.use()
            for (sx, _, sw, _), rects in zip(slot_viewports((0, 0, w, h), n_slots), self._aa_rects):
                prog["u_bounds"].value = ((sx + 0.5) / w, 0.5 / h, (sx + sw - 0.5) / w, 1 - 0.5 / h)
                for rx, ry, rw, rh in rects:
                    aa.viewport = (rx, ry, rw, rh)
                    prog["u_rect"].value = (rx / w, ry / h, rw / w, rh / h)
                    vao.render(moderngl.TRIANGLES, vertices=3)
        aa.depth_mask = True
        aa.viewport = (0, 0, w, h)
        ctx.depth_func = "<"
        ctx.disable(moderngl.DEPTH_TEST)

    def _draw_slots(self, scene, t: float, viewport: tuple[int, int, int, int], figures: bool = True,
                    backdrop: bool = True) -> None:
        ctx = self.ctx
        fbo = self._msaa
        vps = slot_viewports(viewport, scene.n_slots)
        aspect = vps[0][2] / max(vps[0][3], 1)
        view_proj, vp_bytes, eye = self._view_of(scene.camera, aspect)
        # one palette upload per avatar per frame, all slots at once
        frames = []
        meshes = []
        pals = []
        for i, (slot, avatar) in enumerate(zip(scene.slots, scene.avatars)):
            mesh = self.upload_avatar(avatar)
            pal, wts = slot.frame_at(t)
            mesh.palette.set_row(i, pal)
            frames.append(wts)
            meshes.append(mesh)
            pals.append(pal)
        for mesh in {id(m): m for m in meshes}.values():
            mesh.palette.upload()
        groups = [self.group_programs(a, m) for a, m in zip(scene.avatars, meshes)]
        for prog in {id(p): p for g in groups for p, _, _ in g}.values():
            prog["u_view_proj"].write(vp_bytes)
            if "u_camera_pos" in self._uniform_names(prog):
                prog["u_camera_pos"].value = eye
        self.floor_prog["u_view_proj"].write(vp_bytes)
        self._aa_rects = []
        for i, vp in enumerate(vps):
            fbo.viewport = vp
            if figures and self.fxaa:  # where FXAA works (nothing else needs the figure's rectangles)
                avatar = scene.avatars[i]
                self._aa_rects.append(self._figure_rects(self._joint_boxes(avatar), pals[i], frames[i], view_proj, vp))
            else:
                self._aa_rects.append([])
            # backdrop
            ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
            if backdrop:
                self._empty_vao.render(moderngl.TRIANGLES, vertices=3)
            # floor with contact shadow
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
            joints = scene.slots[i].joints_at(t)
            hips, left, right = self._feet_of(scene.avatars[i].skeleton)
            hips = joints[hips]
            self.floor_prog["u_shadow_centre"].value = (float(hips[0]), float(hips[2]))
            feet = [joints[left], joints[right]]
            self.floor_prog["u_feet"].write(np.array([[f[0], f[2]] for f in feet], np.float32).tobytes())
            self.floor_prog["u_bounds"].value = floor_bounds(hips, feet)
            self._floor_vao.render(moderngl.TRIANGLE_STRIP)
            ctx.disable(moderngl.BLEND)
            # avatar
            ctx.enable(moderngl.DEPTH_TEST)
            mesh = meshes[i]
            base_factor = tuple(float(v) for v in scene.avatars[i].base_color_factor)
            self._active_morphs(frames[i])
            mesh.palette.bind(i, 0)
            mesh.morph_pos.use(1)
            mesh.morph_nrm.use(2)
            mesh.texture.use(3)
            if not scene.avatars[i].double_sided:
                ctx.enable(moderngl.CULL_FACE)
                ctx.front_face = "ccw"
            for prog, first, count in groups[i] if figures else ():
                names = self._uniform_names(prog)
                if "u_morph_count" in names:
                    self._set_morphs(prog)
                    prog["u_morph_rows"].value = mesh.morph_rows
                if "u_has_texture" in names:
                    prog["u_has_texture"].value = mesh.has_texture
                prog["u_base_factor"].value = base_factor
                mesh.vao_for(prog).render(moderngl.TRIANGLES, vertices=count, first=first)
            ctx.disable(moderngl.CULL_FACE)
            ctx.disable(moderngl.DEPTH_TEST)
            if scene.labels:
                self._draw_label(scene.labels[i], vp)
            if self.flush_slots and i + 1 < len(vps):
                gl_flush()
        fbo.viewport = viewport

    def _view_of(self, camera, aspect: float) -> tuple[np.ndarray, bytes, tuple[float, float, float]]:
        """``camera`` refitted to ``aspect``: its view-projection matrix, that matrix as the shaders take it
        (column-major float32 bytes) and its eye (the lighting's camera position). Computed when the camera
        or the aspect changes, not every frame (the fit and the look-at are Python on the thread that shades
        the vertices)."""
        hit = self._view
        if hit is None or hit[0] is not camera or hit[1] != aspect:
            view_proj = camera.view_proj(aspect)
            eye = tuple(float(v) for v in camera.for_aspect(aspect).eye)
            hit = self._view = (camera, aspect, view_proj,
                                np.ascontiguousarray(view_proj.T, np.float32).tobytes(), eye)
        return hit[2], hit[3], hit[4]

    def _uniform_names(self, prog: moderngl.Program) -> frozenset[str]:
        """The names ``prog`` declares (``name in prog`` walks all of them: moderngl has no lookup for it)."""
        hit = self._uniforms.get(id(prog))
        if hit is None or hit[0] is not prog:
            hit = self._uniforms[id(prog)] = (prog, frozenset(prog))
        return hit[1]

    def _feet_of(self, skeleton) -> tuple[int, int, int]:
        """Indices of the hips (the root) and of the feet the contact shadow follows (the hips for a foot
        the skeleton lacks)."""
        hit = self._feet.get(id(skeleton))
        if hit is None or hit[0] is not skeleton:
            feet = tuple(skeleton.names.index(n) if n in skeleton.names else 0 for n in ("LeftFoot", "RightFoot"))
            if len(self._feet) >= MAX_CACHED_AVATARS:
                self._feet.pop(next(iter(self._feet)))
            hit = self._feet[id(skeleton)] = (skeleton, (0, *feet))
        return hit[1]

    def _joint_boxes(self, avatar: Avatar) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bind-pose bounds of the vertices each joint dominates: ``(J, 8, 4)`` box corners (homogeneous,
        already grown by how far the other joints' weights can pull a vertex), ``(J,)`` extra growth per
        unit of morph weight, and the joints that dominate any vertex. Cached per avatar.

        A vertex ``p`` with dominant joint ``d`` is skinned to ``P_d p + sum_k w_k (P_k p - P_d p)``; the first
        term lies in the box moved by ``P_d`` (a rotation and translation), and ``|P_k p - P_d p|`` is at most
        ``2 |p - J_child|`` when ``k`` and ``d`` are parent and child (the child joint is fixed in the parent's
        frame), else ``|p - J_k| + path(k, d) + |p - J_d|`` (bones are rigid)."""
        hit = self._boxes.get(id(avatar))
        if hit is not None and hit[0] is avatar:
            return hit[1]
        v = np.asarray(avatar.vertices, np.float64)
        bind_pos = np.linalg.inv(np.asarray(avatar.inverse_bind, np.float64))[:, :3, 3]
        parents = np.asarray(avatar.skeleton.parents, np.int64)
        n = len(bind_pos)
        depth = np.zeros(n)  # path length from the root
        anc = [[j] for j in range(n)]  # ancestors, self first
        for j in range(n):
            pj = parents[j]
            if pj >= 0:
                depth[j] = depth[pj] + np.linalg.norm(bind_pos[j] - bind_pos[pj])
                anc[j] = [j] + anc[pj]
        path = np.full((n, n), 1e3)  # joints of separate trees: effectively unbounded
        for i in range(n):
            si = set(anc[i])
            for j in range(n):
                lca = next((x for x in anc[j] if x in si), None)
                if lca is not None:
                    path[i, j] = depth[i] + depth[j] - 2 * depth[lca]
        joints = np.asarray(avatar.joints, np.int64)
        wts = np.asarray(avatar.weights, np.float64)
        wts = wts / np.maximum(wts.sum(axis=1, keepdims=True), 1e-12)
        dom = joints[np.arange(len(v)), wts.argmax(axis=1)]
        dist = np.linalg.norm(v[:, None, :] - bind_pos[joints], axis=2)  # (V, 4) |p - J_k|
        dist_d = np.linalg.norm(v - bind_pos[dom], axis=1)[:, None]  # |p - J_d|
        pull = dist + path[joints, dom[:, None]] + dist_d
        pull = np.where(parents[joints] == dom[:, None], 2 * dist, pull)  # k child of d
        pull = np.where(parents[dom][:, None] == joints, 2 * dist_d, pull)  # k parent of d
        pull = np.where(joints == dom[:, None], 0.0, pull)
        grow = (wts * pull).sum(axis=1)
        morph = np.zeros(len(v))
        if avatar.morph_deltas is not None and len(avatar.morph_deltas):
            morph = np.linalg.norm(np.asarray(avatar.morph_deltas, np.float64), axis=2).sum(axis=0)
        used = np.unique(dom)
        corners = np.zeros((n, 8, 4))
        morph_grow = np.zeros(n)
        for d in used:
            sel = dom == d
            g = grow[sel].max()
            lo = v[sel].min(axis=0) - g
            hi = v[sel].max(axis=0) + g
            corners[d] = [[x[0], y[1], z[2], 1.0] for x in (lo, hi) for y in (lo, hi) for z in (lo, hi)]
            morph_grow[d] = morph[sel].max()
        result = (corners, morph_grow, used)
        if len(self._boxes) >= MAX_CACHED_AVATARS:
            self._boxes.pop(next(iter(self._boxes)))
        self._boxes[id(avatar)] = (avatar, result)
        return result

    @staticmethod
    def _figure_rects(boxes: tuple, palette: np.ndarray, morph_weights: np.ndarray, view_proj: np.ndarray,
                      vp: tuple[int, int, int, int]) -> list[tuple[int, int, int, int]]:
        """Pixel rectangles (in the draw buffer, one per body part) that surely hold the figure: each joint's bind-pose box
        (:meth:`_joint_boxes`, grown by the largest morph offset at this frame's weights) moved by its
        skinning matrix, projected, and padded by two pixels for the anti-aliased edge. The whole slot
        when a box reaches behind the camera."""
        x, y, w, h = vp
        corners, morph_grow, used = boxes
        pal = np.asarray(palette, np.float64)[used]
        wsum = float(np.abs(morph_weights).max()) if len(morph_weights) else 0.0  # |sum w d| <= max|w| sum|d|
        c = corners[used].copy()
        if wsum > 0:
            g = (morph_grow[used] * wsum)[:, None]
            centre = c[:, :, :3].mean(axis=1, keepdims=True)
            c[:, :, :3] += np.sign(c[:, :, :3] - centre) * g[:, :, None]
        world = np.einsum("jab,jkb->jka", pal, c)
        clip = world @ np.asarray(view_proj, np.float64).T  # (used joints, 8, 4)
        if (clip[..., 3] <= 1e-6).any():
            return [(x, y, w, h)]
        px = x + (clip[..., 0] / clip[..., 3] + 1) * 0.5 * w
        py = y + (clip[..., 1] / clip[..., 3] + 1) * 0.5 * h
        pad = 2
        jx0 = np.floor(px.min(axis=1)) - pad
        jx1 = np.ceil(px.max(axis=1)) + pad
        jy0 = np.floor(py.min(axis=1)) - pad
        jy1 = np.ceil(py.max(axis=1)) + pad
        y_lo = int(max(y, jy0.min()))
        y_hi = int(min(y + h, jy1.max()))
        if y_hi <= y_lo:
            return []
        # horizontal bands, each as wide as the joints' boxes that reach into it: arms stretch only a few
        rects = []
        edges = np.linspace(y_lo, y_hi, FXAA_BANDS + 1).round().astype(int)
        for b0, b1 in zip(edges[:-1], edges[1:]):
            hit = (jy1 > b0) & (jy0 < b1)
            if b1 <= b0 or not hit.any():
                continue
            x0 = int(max(x, jx0[hit].min()))
            x1 = int(min(x + w, jx1[hit].max()))
            if x1 > x0:
                rects.append((x0, int(b0), x1 - x0, int(b1 - b0)))
        return rects

    def _active_morphs(self, weights: np.ndarray) -> None:
        """This slot's non-zero morph weights, for :meth:`_set_morphs` (the same for each of its groups)."""
        active = np.flatnonzero(np.abs(weights) > MORPH_EPS)[:MAX_ACTIVE_MORPHS]
        n = len(active)
        self._ids[:] = 0
        self._w[:] = 0
        self._ids[:n] = active
        self._w[:n] = weights[active]
        self._n_morphs = n

    def _set_morphs(self, prog: moderngl.Program) -> None:
        prog["u_morph_count"].value = self._n_morphs
        prog["u_morph_ids"].write(self._ids.tobytes())
        prog["u_morph_w"].write(self._w.tobytes())

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

    def draw_bare(self, avatar: Avatar, scene, target_fbo: moderngl.Framebuffer, program: moderngl.Program,
                  *, flush_slots: bool = False) -> None:
        """Benchmark baseline: the same triangles in the same slots with a trivial shader, one draw per slot
        (``flush_slots``: flushed after each but the last, as the renderer does on a software rasteriser)."""
        w, h = target_fbo.size
        self.frames_drawn += 1
        self._ensure_buffers((w, h))
        fbo = self._msaa
        fbo.use()
        fbo.clear(*BACKGROUND_BOTTOM, 1.0, depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        mesh = self.upload_avatar(avatar)
        vao = mesh.bare_vao(program)
        vps = slot_viewports((0, 0, w, h), scene.n_slots)
        program["u_view_proj"].write(np.ascontiguousarray(scene.camera.view_proj(vps[0][2] / vps[0][3]).T, np.float32).tobytes())
        for i, vp in enumerate(vps):
            fbo.viewport = vp
            vao.render(moderngl.TRIANGLES)
            if flush_slots and i + 1 < len(vps):
                gl_flush()
        self.ctx.disable(moderngl.DEPTH_TEST)
        self._present(target_fbo, (0, 0, w, h), scene.n_slots)

    def release(self) -> None:
        for mesh in self._meshes.values():
            mesh.release()
        self._meshes.clear()
        for tex in self._labels.values():
            tex.release()
        self._labels.clear()
        if self._backdrop_fbo is not None:
            self._backdrop_fbo.color_attachments[0].release()
            self._backdrop_fbo.release()
            self._backdrop_fbo = None
        self._backdrop_key = None
        self._size = None
