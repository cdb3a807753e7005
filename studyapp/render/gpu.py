"""Thin wrappers around the GPU resources of one avatar, the bone palettes and the slot labels."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import moderngl

from studyapp.render.avatar import Avatar

MORPH_TEX_W = 2048  # must match MORPH_TEX_W in shaders/skinned.vert
MAX_ACTIVE_MORPHS = 52  # size of the u_morph_ids / u_morph_w arrays in shaders/skinned.vert
MAX_BONES = 256  # size of the Bones uniform block in shaders/skinned.vert (16 KiB: every GL 3.3 driver)


def morph_texture_data(deltas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pack ``(M, V, 3)`` deltas for the vertex shader.

    Returns ``(rows, texels)``: ``rows`` is ``(V,) int32``, the vertex's row among the R vertices that
    any morph moves (-1 for the rest), and ``texels`` is ``(H, MORPH_TEX_W, 4) float32`` holding the delta
    of morph ``m`` for row ``r`` at linear index ``m * R + r``.

    >>> d = np.zeros((2, 3, 3), np.float32); d[1, 2] = [1, 2, 3]
    >>> rows, tex = morph_texture_data(d)
    >>> rows.tolist(), tex.reshape(-1, 4)[1 * 1 + 0].tolist()
    ([-1, -1, 0], [1.0, 2.0, 3.0, 0.0])
    """
    m, v, _ = deltas.shape
    # a contiguous pass over (M, V*3) then a (V, 3) fold: reducing over axes (0, 2) of the (M, V, 3) array
    # (strided) took 70 ms for the built-in avatar, all of it before a participant's first frame
    moved = np.any(deltas.reshape(m, v * 3) != 0, axis=0).reshape(v, 3).any(axis=1) if m else np.zeros(v, bool)
    rows = np.full(v, -1, np.int32)
    idx = np.flatnonzero(moved)
    rows[idx] = np.arange(len(idx), dtype=np.int32)
    packed = np.zeros((m * len(idx), 4), np.float32)
    if len(idx):
        packed[:, :3] = deltas[:, idx, :].reshape(-1, 3)
    n = max(len(packed), 1)
    h = -(-n // MORPH_TEX_W)
    tex = np.zeros((h * MORPH_TEX_W, 4), np.float32)
    tex[: len(packed)] = packed
    return rows, tex.reshape(h, MORPH_TEX_W, 4)


#: Per material id (``MAT_*`` in avatar.py): light wrap (soft terminator), shininess, specular strength.
MATERIAL_SHADING = np.array([
    [0.35, 28.0, 0.10],   # skin
    [0.20, 8.0, 0.025],   # cloth
    [0.10, 160.0, 0.90],  # eye
    [0.25, 12.0, 0.06],   # hair
    [0.30, 40.0, 0.25],   # teeth
    [0.00, 16.0, 0.05],   # anything else
], np.float32)


def vertex_local_order(indices: np.ndarray) -> np.ndarray:
    """The triangles sorted by the sum of their vertex indices (stable, so deterministic).

    Neighbouring triangles then share vertices that are close in the index buffer, which Mesa's vertex
    cache (llvmpipe splits indexed draws into short runs and shades each vertex once per run) turns into
    fewer vertex-shader runs: about a seventh less frame time for the built-in avatar on llvmpipe. The
    picture is the same (depth-tested opaque triangles; only exact depth ties could resolve differently).
    """
    idx = np.asarray(indices).reshape(-1, 3)
    return idx[np.argsort(idx.astype(np.int64).sum(axis=1), kind="stable")]


SKIN_BONES = (1, 2, 4)  # the shader variants' joint counts per vertex (SKIN_BONES in skinned.vert)


def skin_groups(indices: np.ndarray, weights: np.ndarray, morph_rows: np.ndarray
                ) -> tuple[np.ndarray, list[tuple[bool, int, int, int]]]:
    """The triangles grouped by what their vertices need of the vertex shader, for its specialised variants.

    Returns ``(triangles, groups)``: the triangles reordered, group after group, each group in
    :func:`vertex_local_order`; and per group ``(morphs, bones, first, count)`` -- whether its vertices have
    morph rows (one group without, one with), how many leading joint slots its vertices' weights use (the
    smallest of :data:`SKIN_BONES` holding the last non-zero weight of every vertex of the group), and its
    range in the index buffer (first index, number of indices). Weights past ``bones`` are zero, so a variant
    that leaves them out sums the same skinning matrix.

    Two groups, not one per joint count: on llvmpipe each variant is compiled at its first draw, about
    0.2 s with an empty shader cache (a participant's first run), and splitting by joint count as well (five
    variants for the built-in avatar) made the first trial frame 2.6 s instead of 1.6 s on a fresh machine
    for no frame time measurable in ``bench_render.py`` (1.25x either way, interleaved, load 1.6).

    >>> tris = np.array([[0, 1, 2], [1, 2, 3]])
    >>> w = np.array([[1, 0, 0, 0], [1, 0, 0, 0], [0.5, 0.5, 0, 0], [0.4, 0.3, 0.2, 0.1]], np.float32)
    >>> order, groups = skin_groups(tris, w, np.array([-1, -1, -1, -1]))
    >>> order.tolist(), groups
    ([[0, 1, 2], [1, 2, 3]], [(False, 4, 0, 6)])
    >>> skin_groups(tris, w, np.array([-1, -1, -1, 0]))[1]
    [(False, 2, 0, 3), (True, 4, 3, 3)]
    """
    tri = np.asarray(indices).reshape(-1, 3)
    w = np.asarray(weights)
    used = np.where(w.any(axis=1), w.shape[1] - np.argmax(w[:, ::-1] != 0, axis=1), 1)
    bones = np.asarray(SKIN_BONES)[np.searchsorted(SKIN_BONES, np.minimum(used, SKIN_BONES[-1]))]
    tri_bones = bones[tri].max(axis=1)
    tri_morph = (np.asarray(morph_rows)[tri] >= 0).any(axis=1)
    parts, groups, first = [], [], 0
    for morphs in (False, True):
        sel = tri[tri_morph == morphs]
        if len(sel):
            b = int(tri_bones[tri_morph == morphs].max())
            parts.append(vertex_local_order(sel))
            groups.append((morphs, b, first, 3 * len(sel)))
            first += 3 * len(sel)
    order = np.concatenate(parts) if parts else tri[:0]
    return order, groups


class AvatarMesh:
    """Vertex buffers, morph textures and base-colour texture of one avatar, shared by every slot."""

    def __init__(self, ctx: moderngl.Context, avatar: Avatar,
                 palette_rows: int = 4) -> None:  # one per slot: render.scene.MAX_SLOTS
        self.ctx = ctx
        self.avatar = avatar
        self.n_joints = avatar.skeleton.n_joints
        v = avatar.n_vertices
        rows, tex = morph_texture_data(avatar.morph_deltas)
        self.morph_rows = int(rows.max() + 1) if rows.size and rows.max() >= 0 else 0
        ndeltas = avatar.morph_normal_deltas if avatar.morph_normal_deltas is not None else np.zeros_like(avatar.morph_deltas)
        # normal texels must line up with position texels: pack them with the same row selection
        ntex = self._pack_like(rows, ndeltas, tex.shape)
        self.morph_pos = ctx.texture((MORPH_TEX_W, tex.shape[0]), 4, tex.tobytes(), dtype="f4")
        self.morph_nrm = ctx.texture((MORPH_TEX_W, ntex.shape[0]), 4, ntex.tobytes(), dtype="f4")
        for t in (self.morph_pos, self.morph_nrm):
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
        # sRGB -> linear and the material table are resolved here, once, not per vertex per frame
        linear = np.power(np.clip(avatar.colors, 0, None), 2.2)
        color = np.concatenate([linear, avatar.material[:, None].astype(np.float32)], axis=1)
        shading = MATERIAL_SHADING[np.minimum(avatar.material, len(MATERIAL_SHADING) - 1)]
        uv = avatar.uv if avatar.uv is not None else np.zeros((v, 2), np.float32)
        self._buffers = {
            "in_position": ctx.buffer(avatar.vertices.tobytes()),
            "in_normal": ctx.buffer(avatar.normals.tobytes()),
            "in_color": ctx.buffer(np.ascontiguousarray(color, np.float32).tobytes()),
            "in_shading": ctx.buffer(np.ascontiguousarray(shading, np.float32).tobytes()),
            "in_joints": ctx.buffer(avatar.joints.astype(np.int32).tobytes()),
            "in_weights": ctx.buffer(avatar.weights.tobytes()),
            "in_morph_row": ctx.buffer(rows.tobytes()),
            "in_uv": ctx.buffer(np.ascontiguousarray(uv, np.float32).tobytes()),
        }
        order, self.groups = skin_groups(avatar.indices, avatar.weights, rows)
        self.index_buffer = ctx.buffer(order.astype(np.uint32).tobytes())
        self._vaos: dict[int, tuple[moderngl.Program, moderngl.VertexArray]] = {}
        if avatar.texture is not None:
            img = np.ascontiguousarray(avatar.texture[::-1], np.uint8)  # GL wants the bottom row first
            self.texture = ctx.texture((img.shape[1], img.shape[0]), img.shape[2], img.tobytes())
            self.texture.build_mipmaps()
            self.texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        else:
            self.texture = ctx.texture((1, 1), 4, bytes([255, 255, 255, 255]))
        self.has_texture = avatar.texture is not None and avatar.uv is not None
        self.palette = PaletteBuffers(ctx, self.n_joints, palette_rows)
        self._bare_vao: moderngl.VertexArray | None = None

    @staticmethod
    def _pack_like(rows: np.ndarray, deltas: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
        idx = np.flatnonzero(rows >= 0)
        out = np.zeros((shape[0] * shape[1], 4), np.float32)
        if len(idx) and len(deltas):
            packed = deltas[:, idx, :].reshape(-1, 3)
            out[: len(packed), :3] = packed
        return out.reshape(shape)

    def vao_for(self, program: moderngl.Program) -> moderngl.VertexArray:
        """The vertex array of this mesh for ``program`` (the attributes it uses), made once per program;
        draw a group's range of it (:attr:`groups`)."""
        hit = self._vaos.get(id(program))
        if hit is None or hit[0] is not program:
            fmt = {"in_position": "3f", "in_normal": "3f", "in_color": "4f", "in_shading": "3f", "in_joints": "4i",
                   "in_weights": "4f", "in_morph_row": "i", "in_uv": "2f"}
            content = [(self._buffers[name], fmt[name], name) for name in fmt if name in program]
            hit = (program, self.ctx.vertex_array(program, content, self.index_buffer, index_element_size=4))
            self._vaos[id(program)] = hit
        return hit[1]

    def bare_vao(self, program: moderngl.Program) -> moderngl.VertexArray:
        """Same triangles, positions only (benchmark baseline)."""
        if self._bare_vao is None:
            self._bare_vao = self.ctx.vertex_array(program, [(self._buffers["in_position"], "3f", "in_position")],
                                                   self.index_buffer, index_element_size=4)
        return self._bare_vao

    def release(self) -> None:
        for b in self._buffers.values():
            b.release()
        for _, vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        for obj in (self.index_buffer, self.morph_pos, self.morph_nrm, self.texture, self._bare_vao):
            if obj is not None:
                obj.release()
        self.palette.release()


class PaletteBuffers:
    """Bone palettes of up to ``rows`` slots, one uniform buffer each (bound to the ``Bones`` block).

    A uniform block beats a float texture here: llvmpipe gathers uniforms much faster than it runs
    ``texelFetch`` in the vertex shader, and every GPU handles 256 std140 mat4 (16 KiB).
    """

    def __init__(self, ctx: moderngl.Context, n_joints: int, rows: int = 3) -> None:
        if n_joints > MAX_BONES:
            raise ValueError(f"avatar has {n_joints} joints; the renderer supports at most {MAX_BONES}")
        self.n_joints = n_joints
        self.rows = rows
        self.buffers = [ctx.buffer(reserve=64 * n_joints, dynamic=True) for _ in range(rows)]
        self._data = np.zeros((rows, n_joints, 4, 4), np.float32)
        self._data[:] = np.eye(4, dtype=np.float32)
        self._dirty = [True] * rows

    def set_row(self, row: int, palette: np.ndarray) -> None:
        # numpy matrices are row-major; std140 mat4 arrays store columns
        self._data[row] = np.swapaxes(palette, -1, -2)
        self._dirty[row] = True

    def upload(self) -> None:
        for row, buf in enumerate(self.buffers):
            if self._dirty[row]:
                buf.write(self._data[row].tobytes())
                self._dirty[row] = False

    def bind(self, row: int, binding: int = 0) -> None:
        self.buffers[row].bind_to_uniform_block(binding)

    def release(self) -> None:
        for b in self.buffers:
            b.release()


def rasterize_label(text: str, height_px: int) -> np.ndarray:
    """White-on-black coverage image ``(H, W) uint8`` of ``text`` in DejaVu Sans Bold, its ink centred.

    FreeType through Pillow with the font file studyapp ships (``studyapp/render/fonts``, the one matplotlib
    ships too: the labels look as they did when matplotlib drew them, and the participant's install needs no
    matplotlib).

    >>> img = rasterize_label("A", 32); img.shape[0] == 32 and bool(img.max() > 200)
    True
    """
    from PIL import Image, ImageDraw, ImageFont

    height_px = max(8, int(height_px))
    width_px = max(height_px, int(height_px * (0.75 * len(text) + 0.6)))
    # the em is ~1.4x the capital height: capitals fill about two thirds of the label height
    font = ImageFont.truetype(str(_label_font()), size=max(1, round(height_px * 0.95)))
    canvas = Image.new("L", (2 * width_px + 2 * height_px, 3 * height_px), 0)
    ImageDraw.Draw(canvas).text((height_px, height_px), text, fill=255, font=font)
    glyphs = np.asarray(canvas)
    out = np.zeros((height_px, width_px), np.uint8)
    rows, cols = np.nonzero(glyphs)
    if rows.size:
        ink = glyphs[rows.min():rows.max() + 1, cols.min():cols.max() + 1][:height_px, :width_px]
        y, x = (height_px - ink.shape[0]) // 2, (width_px - ink.shape[1]) // 2
        out[y:y + ink.shape[0], x:x + ink.shape[1]] = ink
    return out


def _label_font() -> Path:
    """DejaVu Sans Bold, shipped in studyapp's package data (``studyapp/render/fonts``, with its license)."""
    return Path(__file__).resolve().parent / "fonts" / "DejaVuSans-Bold.ttf"