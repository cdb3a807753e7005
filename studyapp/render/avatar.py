"""The avatar data model and the built-in, procedurally modelled avatar.

An :class:`Avatar` is everything the GPU needs to draw a skinned, morphing figure: bind-pose geometry,
per-vertex colours, four joint influences per vertex, inverse bind matrices and the 52 ARKit morph
targets. It comes either from :func:`build_default_avatar` (made here with numpy, no asset files) or
from a glTF/VRM file (:mod:`studyapp.render.gltf`).

The built-in avatar
-------------------
* Bind pose: **T-pose**, arms horizontal along +-X, palms down, facing +Z, +Y up, metres, ~1.76 m tall.
  Joint names are Unity humanoid names (``Hips``, ``Spine``, ``Chest``, ``UpperChest``, ``Neck``,
  ``Head``, ``LeftShoulder`` ... ``LeftLittleDistal``, legs), so retargeting by name works.
* Geometry: lofted tubes (torso, neck, limbs, fingers) with elliptical cross sections and a head built as
  a deformed latitude/longitude surface with sockets, nose, lips and a mouth slit that opens into a dark
  cavity, eyeballs with iris and pupil, eyelids, brows, ears, hair cap, teeth and tongue.
* Skin weights: distance to the bone segments each part may follow (inverse fourth power, top four),
  so joints bend smoothly over about one limb radius.
* Morph targets: all 52 ARKit shapes, as displacement fields in head space (eyelid arcs, eyeball
  rotations, jaw hinge rotation, lip and brow fields). ``jawOpen``, blinks, smiles and brows are large;
  the rest are subtle.
* Palette: neutral grey-blue shirt, charcoal trousers, mid skin tone; identical in every slot.
* Built once per machine: modelling it takes 0.4-0.9 s on a loaded 2-core machine, all of it before a
  participant's first frame (issue 20), so its arrays are kept in ``$STUDYAPP_CACHE_DIR/avatar`` (else the
  platform's user cache) under a key made of the numpy version and the bytes of the modules that model it.
  A missing, stale or damaged file is rebuilt; deleting it is always safe.

>>> av = build_default_avatar()
>>> av.vertices.shape[1], len(av.morph_names), av.skeleton.names[:3]
(3, 52, ('Hips', 'Spine', 'Chest'))
"""
from __future__ import annotations

import functools
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from studyapp.face.arkit import ARKIT_NAMES
from studyapp.motion.fk import rest_global_transforms
from studyapp.motion.skeleton import Skeleton

#: Material ids stored per vertex: they select shininess in the fragment shader.
MAT_SKIN, MAT_CLOTH, MAT_EYE, MAT_HAIR, MAT_TEETH = 0, 1, 2, 3, 4


@dataclass(eq=False)
class Avatar:
    """A skinned mesh with ARKit morph targets, in its bind pose.

    Attributes
    ----------
    skeleton:
        Joint hierarchy (humanoid names where known), metres, bind pose = rest pose.
    vertices, normals:
        ``(V, 3) float32`` bind-pose positions (metres) and unit normals.
    indices:
        ``(T, 3) uint32`` triangles, counter-clockwise seen from outside.
    colors:
        ``(V, 3) float32`` base colour per vertex (sRGB, 0..1); multiplied with the texture if any.
    joints, weights:
        ``(V, 4)`` joint indices (``uint16``) and weights (``float32``, each row sums to 1).
    inverse_bind:
        ``(J, 4, 4) float32`` inverse of each joint's bind-pose global transform.
    morph_names:
        The 52 ARKit names in Apple order; ``morph_deltas[i]`` belongs to ``morph_names[i]``.
    morph_deltas, morph_normal_deltas:
        ``(M, V, 3) float32`` position (and optional normal) offsets at weight 1.
    material:
        ``(V,) uint8`` material id (``MAT_*``) for shading (shininess); zeros when unknown.
    uv, texture:
        Optional ``(V, 2)`` texture coordinates and ``(H, W, 4) uint8`` base-colour image (top row first).
    base_color_factor:
        RGBA multiplier of the base colour (glTF ``baseColorFactor``).
    double_sided:
        Draw back faces too (glTF ``doubleSided``). The built-in avatar is made of closed, outward-facing
        surfaces, so it is drawn with back-face culling (a fifth less work on CPU rasterisers).
    name:
        Free text for logs (never shown to participants).
    notes:
        Messages from loading (ignored morph targets, ...).
    bone_map:
        ``{joint name: Unity humanoid bone}`` for joints whose names the retargeting does not recognise
        (the design's ``[avatar.bone_map]``); empty when every name is recognised (built-in, VRM, Mixamo).
    source:
        The file the avatar was loaded from (for messages), None for the built-in one.
    joint_aliases:
        Other names of joints (a VRM node's own name -> its humanoid joint name), accepted in bone maps.
    """

    skeleton: Skeleton
    vertices: np.ndarray
    normals: np.ndarray
    indices: np.ndarray
    colors: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    inverse_bind: np.ndarray
    morph_names: tuple[str, ...] = ARKIT_NAMES
    morph_deltas: np.ndarray | None = None
    morph_normal_deltas: np.ndarray | None = None
    material: np.ndarray | None = None
    uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    base_color_factor: np.ndarray = field(default_factory=lambda: np.ones(4, np.float32))
    double_sided: bool = False
    name: str = "avatar"
    notes: tuple[str, ...] = ()
    bone_map: dict[str, str] = field(default_factory=dict)
    source: str | None = None
    joint_aliases: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.vertices = np.ascontiguousarray(self.vertices, np.float32).reshape(-1, 3)
        v = len(self.vertices)
        self.normals = np.ascontiguousarray(self.normals, np.float32).reshape(v, 3)
        self.indices = np.ascontiguousarray(self.indices, np.uint32).reshape(-1, 3)
        self.colors = np.ascontiguousarray(self.colors, np.float32).reshape(v, 3)
        self.joints = np.ascontiguousarray(self.joints, np.uint16).reshape(v, 4)
        w = np.asarray(self.weights, np.float32).reshape(v, 4)
        s = w.sum(axis=1, keepdims=True)
        if np.abs(s - 1).max(initial=0) > 1e-5:  # normalise, but leave normalised weights bit-exact
            w = np.where(s > 0, w / np.where(s > 0, s, 1), [[1, 0, 0, 0]])
        self.weights = np.ascontiguousarray(w, np.float32)
        self.inverse_bind = np.ascontiguousarray(self.inverse_bind, np.float32).reshape(-1, 4, 4)
        self.morph_names = tuple(self.morph_names)
        m = len(self.morph_names)
        if self.morph_deltas is None:
            self.morph_deltas = np.zeros((m, v, 3), np.float32)
        self.morph_deltas = np.ascontiguousarray(self.morph_deltas, np.float32).reshape(m, v, 3)
        if self.morph_normal_deltas is not None:
            self.morph_normal_deltas = np.ascontiguousarray(self.morph_normal_deltas, np.float32).reshape(m, v, 3)
        self.material = (np.zeros(v, np.uint8) if self.material is None
                         else np.ascontiguousarray(self.material, np.uint8).reshape(v))
        if self.uv is not None:
            self.uv = np.ascontiguousarray(self.uv, np.float32).reshape(v, 2)
        self.base_color_factor = np.asarray(self.base_color_factor, np.float32).reshape(4)
        if len(self.inverse_bind) != self.skeleton.n_joints:
            raise ValueError(f"{len(self.inverse_bind)} inverse bind matrices for {self.skeleton.n_joints} joints")
        if self.indices.size and int(self.indices.max()) >= v:
            raise ValueError("triangle index out of range")
        if self.joints.size and int(self.joints.max()) >= self.skeleton.n_joints:
            raise ValueError("joint index out of range")

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_triangles(self) -> int:
        return len(self.indices)

    def morph_index(self, name: str) -> int:
        return self.morph_names.index(name)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bind-pose axis-aligned bounding box ``(min, max)``."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)


def vertex_normals(vertices: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Area-weighted smooth vertex normals (unit length; zero-area neighbourhoods give +Y).

    >>> v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float); vertex_normals(v, np.array([[0, 1, 2]]))[0]
    array([0., 0., 1.], dtype=float32)
    """
    v = np.asarray(vertices, np.float64)
    tri = np.asarray(indices, np.int64).reshape(-1, 3)
    fn = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])
    # each face normal added to its three corners: bincount, not np.add.at (10x slower, and the built-in
    # avatar's 73 normal passes are on the way to a participant's first frame)
    corners = tri.T.reshape(-1)
    n = np.stack([np.bincount(corners, np.tile(fn[:, c], 3), minlength=len(v)) for c in range(3)], axis=1)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(ln > 1e-12, n / np.maximum(ln, 1e-12), [[0.0, 1.0, 0.0]])
    return n.astype(np.float32)


# ---------------------------------------------------------------------------------------------
# Skeleton
# ---------------------------------------------------------------------------------------------

_FINGERS = ("Thumb", "Index", "Middle", "Ring", "Little")
# (base relative to the hand joint, segment vectors proximal/intermediate/distal/tip) for the LEFT hand
# in T-pose: fingers along +X, palm down, thumb towards the front (+Z).
_FINGER_LAYOUT = {
    "Thumb": ((0.022, -0.012, 0.022), ((0.030, -0.006, 0.022), (0.028, -0.003, 0.012), (0.024, 0.0, 0.006))),
    "Index": ((0.088, 0.0, 0.024), ((0.044, 0.0, 0.003), (0.026, 0.0, 0.001), (0.021, 0.0, 0.0))),
    "Middle": ((0.092, 0.0, 0.004), ((0.048, 0.0, 0.0), (0.029, 0.0, 0.0), (0.023, 0.0, 0.0))),
    "Ring": ((0.088, 0.0, -0.015), ((0.044, 0.0, -0.002), (0.027, 0.0, -0.001), (0.021, 0.0, 0.0))),
    "Little": ((0.080, -0.002, -0.032), ((0.034, 0.0, -0.004), (0.021, 0.0, -0.002), (0.019, 0.0, 0.0))),
}
_FINGER_RADIUS = {"Thumb": 0.0105, "Index": 0.0088, "Middle": 0.0090, "Ring": 0.0085, "Little": 0.0075}


def default_skeleton() -> Skeleton:
    """The built-in avatar's humanoid skeleton (T-pose, metres, facing +Z).

    >>> sk = default_skeleton(); sk.names[sk.parents[sk.index("LeftHand")]]
    'LeftLowerArm'
    """
    names: list[str] = []
    parents: list[int] = []
    pos: list[tuple[float, float, float]] = []
    end_sites: dict[int, np.ndarray] = {}

    def add(name: str, parent: str | None, p: tuple[float, float, float]) -> int:
        names.append(name)
        parents.append(names.index(parent) if parent else -1)
        pos.append(p)
        return len(names) - 1

    add("Hips", None, (0.0, 0.98, 0.0))
    add("Spine", "Hips", (0.0, 1.07, -0.005))
    add("Chest", "Spine", (0.0, 1.18, -0.005))
    add("UpperChest", "Chest", (0.0, 1.29, -0.01))
    add("Neck", "UpperChest", (0.0, 1.455, -0.015))
    head = add("Head", "Neck", (0.0, 1.56, -0.005))
    end_sites[head] = np.array([0.0, 0.2, 0.0])
    for side, sx in (("Left", 1.0), ("Right", -1.0)):
        add(f"{side}Shoulder", "UpperChest", (sx * 0.025, 1.415, -0.012))
        add(f"{side}UpperArm", f"{side}Shoulder", (sx * 0.185, 1.415, -0.02))
        add(f"{side}LowerArm", f"{side}UpperArm", (sx * 0.465, 1.415, -0.025))
        hand = add(f"{side}Hand", f"{side}LowerArm", (sx * 0.715, 1.415, -0.02))
        hp = np.array(pos[hand])
        for finger in _FINGERS:
            base, segs = _FINGER_LAYOUT[finger]
            p = hp + np.array(base) * [sx, 1, 1]
            parent = f"{side}Hand"
            for seg_name, seg in zip(("Proximal", "Intermediate", "Distal"), segs[:3]):
                j = add(f"{side}{finger}{seg_name}", parent, tuple(p))
                parent = names[j]
                p = p + np.array(seg) * [sx, 1, 1]
            end_sites[len(names) - 1] = np.array(segs[2]) * [sx, 1, 1]
    for side, sx in (("Left", 1.0), ("Right", -1.0)):
        add(f"{side}UpperLeg", "Hips", (sx * 0.092, 0.93, 0.0))
        add(f"{side}LowerLeg", f"{side}UpperLeg", (sx * 0.092, 0.50, 0.005))
        add(f"{side}Foot", f"{side}LowerLeg", (sx * 0.092, 0.085, -0.02))
        toes = add(f"{side}Toes", f"{side}Foot", (sx * 0.092, 0.02, 0.10))
        end_sites[toes] = np.array([0.0, 0.0, 0.06])
    pos_a = np.array(pos)
    par = np.array(parents)
    offsets = np.where(par[:, None] >= 0, pos_a - pos_a[np.maximum(par, 0)], pos_a)
    return Skeleton(names=tuple(names), parents=par, offsets=offsets, end_sites=end_sites, unit_scale=1.0)


# ---------------------------------------------------------------------------------------------
# Mesh assembly helpers
# ---------------------------------------------------------------------------------------------

def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((np.asarray(x, np.float64) - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _grid_faces(rows: int, cols: int, wrap: bool = True, offset: int = 0) -> np.ndarray:
    """Triangles of a rows x cols vertex grid (row-major), columns wrapping around when ``wrap``."""
    r = np.arange(rows - 1)[:, None]
    c = np.arange(cols if wrap else cols - 1)[None, :]
    c1 = (c + 1) % cols
    a = r * cols + c
    b = r * cols + c1
    d = (r + 1) * cols + c
    e = (r + 1) * cols + c1
    tris = np.concatenate([np.stack([a, d, b], -1).reshape(-1, 3), np.stack([b, d, e], -1).reshape(-1, 3)])
    return tris + offset


def _frames_along(path: np.ndarray, side_hint: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tangent, side and up unit vectors at each point of a polyline (side follows ``side_hint``)."""
    t = np.gradient(path, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    hint = np.broadcast_to(side_hint, path.shape)
    s = hint - (hint * t).sum(1, keepdims=True) * t
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    u = np.cross(t, s)
    return t, s, u


def _tube(path: np.ndarray, r_side: np.ndarray, r_up: np.ndarray, side_hint, n_around: int = 16,
          cap_start: bool = True, cap_end: bool = True, squareness: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A closed tube along ``path`` with elliptical (or rounded-box) sections and hemispherical caps.

    Rounded caps are extra rings whose radius follows a quarter circle, ending in a collapsed pole.
    """
    path = np.asarray(path, np.float64)
    r_side = np.broadcast_to(np.asarray(r_side, np.float64), len(path)).copy()
    r_up = np.broadcast_to(np.asarray(r_up, np.float64), len(path)).copy()
    t, s, u = _frames_along(path, np.asarray(side_hint, np.float64))
    rings_c, rings_s, rings_u, rs, ru = [path], [s], [u], [r_side], [r_up]
    if cap_start or cap_end:
        ang = np.linspace(0, np.pi / 2, 5)[1:]
        if cap_start:
            k = 0
            depth = 0.8 * min(r_side[k], r_up[k])
            pts = path[k] - np.sin(ang)[::-1, None] * depth * t[k]
            sc = np.cos(ang)[::-1]
            rings_c.insert(0, pts)
            rings_s.insert(0, np.repeat(s[k:k + 1], 4, 0))
            rings_u.insert(0, np.repeat(u[k:k + 1], 4, 0))
            rs.insert(0, r_side[k] * sc)
            ru.insert(0, r_up[k] * sc)
        if cap_end:
            k = -1
            depth = 0.8 * min(r_side[k], r_up[k])
            pts = path[k] + np.sin(ang)[:, None] * depth * t[k]
            sc = np.cos(ang)
            rings_c.append(pts)
            rings_s.append(np.repeat(s[k:], 4, 0))
            rings_u.append(np.repeat(u[k:], 4, 0))
            rs.append(r_side[k] * sc)
            ru.append(r_up[k] * sc)
    c = np.concatenate(rings_c)
    sv = np.concatenate(rings_s)
    uv = np.concatenate(rings_u)
    rsv = np.concatenate(rs)
    ruv = np.concatenate(ru)
    th = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    cs, sn = np.cos(th), np.sin(th)
    if squareness:
        # superellipse: flatter sides for palms and torsos
        e = 2.0 / (2.0 + 4.0 * squareness)
        cs = np.sign(cs) * np.abs(cs) ** e
        sn = np.sign(sn) * np.abs(sn) ** e
    verts = (c[:, None, :] + rsv[:, None, None] * cs[None, :, None] * sv[:, None, :]
             + ruv[:, None, None] * sn[None, :, None] * uv[:, None, :])
    faces = _grid_faces(len(c), n_around)
    # winding: outward normals need (tangent x side) orientation consistent with the grid; flip if inward
    v = verts.reshape(-1, 3)
    tri = faces
    fn = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])
    centre = c.repeat(n_around, 0)[tri[:, 0]]
    if (fn * (v[tri[:, 0]] - centre)).sum() < 0:
        faces = faces[:, [0, 2, 1]]
    return v, faces


def _outward(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Faces wound counter-clockwise seen from outside (the renderer culls back faces).

    Uses the signed volume (positive when normals point out of a closed surface); open shells (lids,
    hair, the torso with its open bottom) still give a clear sign because they enclose their centre.
    """
    c = verts.mean(axis=0)
    a, b, d = verts[faces[:, 0]] - c, verts[faces[:, 1]] - c, verts[faces[:, 2]] - c
    volume = np.einsum("ij,ij->i", a, np.cross(b, d)).sum()
    return faces if volume >= 0 else faces[:, [0, 2, 1]]


def _blend_in(joints: np.ndarray, weights: np.ndarray, extra_joints: list[int], extra: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Mix extra influences into four-per-vertex skin weights: ``extra`` is ``(V, k)`` weights of the joints
    ``extra_joints``; the existing weights shrink to make room, and the four largest of all are kept
    (largest first).

    >>> j, w = _blend_in(np.array([[0, 1, 0, 0]]), np.array([[0.5, 0.5, 0, 0]]), [7], np.array([[0.5]]))
    >>> j.tolist(), w.tolist()
    ([[7, 0, 1, 0]], [[0.5, 0.25, 0.25, 0.0]])
    """
    extra = np.clip(np.asarray(extra, np.float64), 0, 1)
    keep = np.clip(1 - extra.sum(axis=1, keepdims=True), 0, 1)
    all_j = np.concatenate([joints, np.broadcast_to(np.asarray(extra_joints), extra.shape)], axis=1)
    all_w = np.concatenate([weights * keep, extra], axis=1)
    top = np.argsort(-all_w, axis=1, kind="stable")[:, :4]
    j = np.take_along_axis(all_j, top, 1)
    w = np.take_along_axis(all_w, top, 1)
    w = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-12)
    return np.where(w > 0, j, 0), w


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of points ``p`` (N,3) to segments ``a->b`` (B,3): (N,B)."""
    ab = b - a
    ap = p[:, None, :] - a[None]
    t = np.clip((ap * ab[None]).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12)[None], 0, 1)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=-1)


class _MeshBuilder:
    """Collects parts (geometry, colour, material, skin weights) and tags vertex groups for morphs."""

    def __init__(self, skeleton: Skeleton, joint_pos: np.ndarray) -> None:
        self.sk = skeleton
        self.jp = joint_pos
        self.v: list[np.ndarray] = []
        self.n: list[np.ndarray] = []
        self.f: list[np.ndarray] = []
        self.c: list[np.ndarray] = []
        self.m: list[np.ndarray] = []
        self.j: list[np.ndarray] = []
        self.w: list[np.ndarray] = []
        self.count = 0
        self.groups: dict[str, np.ndarray] = {}

    def segment(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Bone segment of a joint: from the joint to its (first) child or end site."""
        j = self.sk.index(name)
        kids = self.sk.children(j)
        if name.endswith("Hand"):
            mid = self.sk.index(name.replace("Hand", "MiddleProximal"))
            return self.jp[j], self.jp[mid]
        if name.endswith("UpperChest"):
            return self.jp[j], self.jp[self.sk.index("Neck")]
        if kids:
            return self.jp[j], self.jp[kids[0]]
        tip = self.sk.end_sites.get(j, np.array([0.0, 0.02, 0.0]))
        return self.jp[j], self.jp[j] + tip

    def weights_for(self, verts: np.ndarray, bones: list[str], power: float = 4.0,
                    bias: dict[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        seg = [self.segment(b) for b in bones]
        a = np.array([s[0] for s in seg])
        b = np.array([s[1] for s in seg])
        d = _segment_distance(verts, a, b) + 1e-4
        if bias:
            d = d * np.array([bias.get(bn, 1.0) for bn in bones])[None]
        w = d ** -power
        ids = np.array([self.sk.index(bn) for bn in bones])
        k = min(4, len(bones))
        top = np.argsort(-w, axis=1)[:, :k]
        wt = np.take_along_axis(w, top, 1)
        wt /= wt.sum(1, keepdims=True)
        joints = np.zeros((len(verts), 4), np.int64)
        weights = np.zeros((len(verts), 4))
        joints[:, :k] = ids[top]
        weights[:, :k] = wt
        return joints, weights

    def add(self, verts: np.ndarray, faces: np.ndarray, color, material: int, bones: list[str] | None = None,
            joints: np.ndarray | None = None, weights: np.ndarray | None = None, group: str | None = None,
            normals: np.ndarray | None = None, power: float = 4.0, bias: dict[str, float] | None = None) -> np.ndarray:
        verts = np.asarray(verts, np.float64)
        nv = len(verts)
        faces = _outward(verts, np.asarray(faces, np.int64))
        if joints is None:
            joints, weights = self.weights_for(verts, bones, power, bias)
        col = np.broadcast_to(np.asarray(color, np.float64), (nv, 3)).copy()
        self.v.append(verts)
        self.n.append(vertex_normals(verts, faces) if normals is None else normals)
        self.f.append(np.asarray(faces, np.int64) + self.count)
        self.c.append(col)
        self.m.append(np.full(nv, material, np.uint8))
        self.j.append(joints)
        self.w.append(weights)
        idx = np.arange(self.count, self.count + nv)
        self.count += nv
        if group:
            self.groups[group] = np.concatenate([self.groups.get(group, np.zeros(0, np.int64)), idx])
        return idx


# ---------------------------------------------------------------------------------------------
# Palette (neutral, the same for every slot)
# ---------------------------------------------------------------------------------------------

SKIN = np.array([0.80, 0.62, 0.52])
SHIRT = np.array([0.42, 0.47, 0.53])
TROUSERS = np.array([0.20, 0.21, 0.23])
SHOES = np.array([0.12, 0.11, 0.11])
HAIR = np.array([0.20, 0.14, 0.10])
BROW = np.array([0.22, 0.15, 0.11])
LIPS = np.array([0.68, 0.43, 0.40])
MOUTH = np.array([0.16, 0.06, 0.06])
SCLERA = np.array([0.86, 0.84, 0.82])
IRIS = np.array([0.24, 0.16, 0.10])
PUPIL = np.array([0.03, 0.03, 0.03])
TEETH = np.array([0.92, 0.90, 0.84])
TONGUE = np.array([0.72, 0.38, 0.38])


# ---------------------------------------------------------------------------------------------
# Head
# ---------------------------------------------------------------------------------------------

# Head-local layout (metres, origin at the head centre, +Z forward)
_HEAD_R = np.array([0.074, 0.112, 0.094])
_EYE_X, _EYE_Y = 0.031, 0.008
_EYE_R = 0.0118
_LID_R = 0.0132
_MOUTH_Y = -0.058
_MOUTH_HW = 0.024  # half width of the mouth slit
_BROW_Y = 0.030


def _head_surface(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """Skull/face shape (without sockets, nose and lips) for longitude (0 = front) and latitude grids."""
    a, b, c = _HEAD_R
    x = a * np.cos(lat) * np.sin(lon)
    y = b * np.sin(lat)
    z = c * np.cos(lat) * np.cos(lon)
    yn = y / b
    low = _smoothstep(0.0, -1.0, yn)
    # jaw and cheeks narrow towards the chin; the back of the skull tucks into the neck
    x = x * (1.0 - 0.20 * low ** 1.3)
    # the cranium is rounder than an ellipsoid: widen the upper half
    up = np.clip(yn, 0, 1)
    x = x * (1.0 + 0.16 * np.sin(np.pi * up) ** 0.8 * (1 - 0.3 * up))
    front = np.clip(np.cos(lon), 0, 1)
    back = np.clip(-np.cos(lon), 0, 1)
    z = z * (1.0 - 0.35 * low * back)
    # chin juts forward, the face is flatter than an ellipsoid
    z = z + 0.028 * front ** 2 * _smoothstep(-0.2, -0.85, yn) * (1 - _smoothstep(-0.9, -1.0, yn))
    z = z + 0.006 * front * (1 - np.abs(yn))
    # cranium is larger at the back/top
    z = z - 0.012 * back * _smoothstep(-0.3, 0.5, yn)
    y = y - 0.010 * _smoothstep(0.5, 1.0, yn)
    return np.stack([x, y, z], -1)


def _gauss(d2: np.ndarray, sigma: float) -> np.ndarray:
    return np.exp(-d2 / (2 * sigma * sigma))


def _face_features(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Displace the base head surface for sockets, brow ridge, nose, lips and cheeks; return (p, lip mask)."""
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    front = _smoothstep(0.02, 0.06, z)
    out = p.copy()
    # eye sockets and brow ridge
    for sx in (1, -1):
        d2 = (x - sx * _EYE_X) ** 2 + ((y - _EYE_Y) * 1.25) ** 2
        out[..., 2] -= 0.0085 * _gauss(d2, 0.0105) * front
        d2b = (x - sx * 0.030) ** 2 * 0.5 + (y - 0.026) ** 2 * 4
        out[..., 2] += 0.0035 * _gauss(d2b, 0.010) * front
        # cheekbones
        d2c = (x - sx * 0.045) ** 2 + (y + 0.022) ** 2
        out[..., 2] += 0.004 * _gauss(d2c, 0.015) * front
    # nose: bridge to tip, then the columella back to the lip
    t = np.clip((0.012 - y) / 0.052, 0, 1)  # 0 at the bridge, 1 at the base
    height = 0.004 + 0.019 * t ** 1.3
    height = height * (1 - _smoothstep(0.86, 1.0, t))
    width = 0.0055 + 0.009 * t ** 2
    nose = height * _gauss(x ** 2, width) * _smoothstep(0.02, -0.004, y - 0.012) * _smoothstep(-0.058, -0.044, y)
    out[..., 2] += nose * front
    # nostril wings
    for sx in (1, -1):
        d2n = (x - sx * 0.013) ** 2 + (y + 0.037) ** 2 * 1.6
        out[..., 2] += 0.0075 * _gauss(d2n, 0.0055) * front
    # lips: a fuller lower lip, a thinner upper lip, both protruding
    dy = y - _MOUTH_Y
    lw = _MOUTH_HW * 1.05
    xr = np.clip(np.abs(x) / lw, 0, 2)
    # both lips thin out towards the corners (a band of constant height reads as a painted rectangle)
    taper = 1 - 0.6 * np.minimum(xr, 1.0) ** 2
    upper = _smoothstep(0.0105 * taper, 0.0075 * taper, dy) * (dy >= 0) * (1 - _smoothstep(0.8, 1.0, xr))
    lower = _smoothstep(-0.0125 * taper, -0.0095 * taper, dy) * (dy < 0) * (1 - _smoothstep(0.75, 1.0, xr))
    lipmask = np.maximum(upper, lower)
    lip_bulge = (0.0045 * _gauss(dy ** 2, 0.006) * (1 - _smoothstep(0.5, 1.25, xr)))
    out[..., 2] += lip_bulge * front
    # philtrum and chin dimple
    out[..., 2] -= 0.0015 * _gauss(x ** 2, 0.004) * _gauss((y + 0.047) ** 2, 0.004) * front
    out[..., 2] += 0.004 * _gauss(x ** 2 + (y + 0.098) ** 2, 0.014) * front
    return out, lipmask * front


def _head_grid() -> tuple[np.ndarray, np.ndarray]:
    """Longitudes and latitudes of the head surface: dense over the face, extra rows at the mouth slit."""
    # about 2 degrees (3 mm) over the eyes, nose and mouth, coarser towards the ears and the back
    lon_mid = np.arange(-26, 26.01, 2.36)
    lon_side = np.arange(30.5, 62.01, 4.5)
    lon_front = np.radians(np.concatenate([-lon_side[::-1], lon_mid, lon_side]))
    lon_back = np.radians(np.linspace(62, 298, 15)[1:-1])
    lon = np.concatenate([lon_front, lon_back])
    lon = np.where(lon > np.pi, lon - 2 * np.pi, lon)
    order = np.argsort(np.mod(lon + np.pi, 2 * np.pi))
    lon = lon[order]
    lat = list(np.radians(np.linspace(-89, -75, 3)))
    lat += list(np.radians(np.arange(-72, -50, 3.0)))
    lat += list(np.radians(np.arange(-50, 14, 1.9)))
    lat += list(np.radians(np.arange(14, 44, 3.0)))
    lat += list(np.radians(np.linspace(47, 89, 9)))
    b = _HEAD_R[1]
    lat_m = np.arcsin(_MOUTH_Y / b)
    # twice as many rows over the lips: their colour edge is per vertex and would blur over a whole row
    lips = lat_m + np.radians(np.arange(-7.6, 7.0, 0.95))
    lat = [x for x in lat if abs(x - lat_m) > np.radians(8.0)] + list(lips)
    lat = np.array(sorted(lat))
    # the mouth slit: five rows packed together at the lip line (they spread when the jaw opens)
    lat = lat[np.abs(lat - lat_m) > np.radians(0.9)]
    slit = lat_m + np.radians(np.array([0.30, 0.15, 0.0, -0.15, -0.30]))
    lat = np.array(sorted(np.concatenate([lat, slit])))
    return lon, lat


def _build_head(mb: _MeshBuilder, centre: np.ndarray) -> dict[str, np.ndarray]:
    """Head, face parts and their local coordinates (for the morph fields)."""
    lon, lat = _head_grid()
    LON, LAT = np.meshgrid(lon, lat)
    base = _head_surface(LON, LAT)
    p, lipmask = _face_features(base)
    rows, cols = LAT.shape
    faces = _grid_faces(rows, cols, wrap=True)
    # grid is built bottom->top with longitude increasing from the back; fix winding to face outwards
    pv = p.reshape(-1, 3)
    fn = np.cross(pv[faces[:, 1]] - pv[faces[:, 0]], pv[faces[:, 2]] - pv[faces[:, 0]])
    if (fn * pv[faces[:, 0]]).sum() < 0:
        faces = faces[:, [0, 2, 1]]
    x, y, z = pv[:, 0], pv[:, 1], pv[:, 2]
    col = np.tile(SKIN, (len(pv), 1))
    # hair is painted on the scalp (a soft hairline) and the cap below only adds volume
    hair_amt = _smoothstep(-0.07, 0.05, (LAT - _hairline(LON)).reshape(-1))
    col = col * (1 - hair_amt[:, None]) + HAIR * 0.92 * hair_amt[:, None]
    lm = lipmask.reshape(-1)
    col = col * (1 - lm[:, None]) + LIPS * lm[:, None]
    # the slit rows inside the mouth are the cavity: dark
    lat_m = np.arcsin(_MOUTH_Y / _HEAD_R[1])
    slit_row = np.abs(LAT - lat_m) < np.radians(0.2)
    inner = (slit_row & (np.abs(base[..., 0]) < _MOUTH_HW * 0.92) & (base[..., 2] > 0)).reshape(-1)
    col[inner] = MOUTH
    # subtle shading cues baked into the colour: cheeks slightly warmer, jaw/neck slightly darker
    for sx in (1, -1):
        g = _gauss((x - sx * 0.045) ** 2 + (y + 0.028) ** 2, 0.014) * (z > 0)
        col = col * (1 - 0.25 * g[:, None]) + np.array([0.85, 0.55, 0.50]) * 0.25 * g[:, None]
    world = pv + centre
    # The head follows Head; the lowest rows blend into Neck so the join bends smoothly.
    hj = mb.sk.index("Head")
    nj = mb.sk.index("Neck")
    wn = _smoothstep(-0.06, -0.125, y) * (z < 0.03) * 0.6
    joints = np.zeros((len(pv), 4), np.int64)
    weights = np.zeros((len(pv), 4))
    joints[:, 0], joints[:, 1] = hj, nj
    weights[:, 0], weights[:, 1] = 1 - wn, wn
    idx = mb.add(world, faces, col, MAT_SKIN, joints=joints, weights=weights, group="face")
    local = {"face": pv, "face_base": base.reshape(-1, 3), "face_lat": LAT.reshape(-1), "face_inner": inner}

    def head_weights(n: int) -> tuple[np.ndarray, np.ndarray]:
        jj = np.zeros((n, 4), np.int64)
        ww = np.zeros((n, 4))
        jj[:, 0] = hj
        ww[:, 0] = 1
        return jj, ww

    # eyes: sclera, iris and pupil by angle from the eye's forward axis
    eye_locals = []
    for side, sx in (("Left", 1), ("Right", -1)):
        ec = _eye_centre(sx)
        th = np.linspace(0, np.pi, 14)
        ph = np.linspace(0, 2 * np.pi, 20, endpoint=False)
        TH, PH = np.meshgrid(th, ph, indexing="ij")
        d = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], -1).reshape(-1, 3)
        # slight inward gaze (convergence) looks more alive than parallel eyes
        ang = np.arccos(np.clip(d[:, 2], -1, 1))
        v = ec + _EYE_R * d
        # cornea bulge
        v = v + (d * 0.0012 * _smoothstep(0.55, 0.0, ang)[:, None])
        c = np.tile(SCLERA, (len(d), 1))
        iris = _smoothstep(0.56, 0.50, ang)
        c = c * (1 - iris[:, None]) + IRIS * iris[:, None]
        ring = _gauss((ang - 0.53) ** 2, 0.03)
        c = c * (1 - 0.5 * ring[:, None])
        pupil = _smoothstep(0.24, 0.19, ang)
        c = c * (1 - pupil[:, None]) + PUPIL * pupil[:, None]
        f = _grid_faces(len(th), len(ph))
        f = f[:, [0, 2, 1]]
        jj, ww = head_weights(len(v))
        eidx = mb.add(v + centre, f, c, MAT_EYE, joints=jj, weights=ww, group=f"eye{side}")
        local[f"eye{side}"] = v
        eye_locals.append(eidx)
    # eyelids (upper and lower), brows, ears
    for side, sx in (("Left", 1), ("Right", -1)):
        for which in ("upper", "lower"):
            v, f, frac = _lid(sx, which, open_=True)
            c = np.tile(SKIN * np.array([0.93, 0.86, 0.84]), (len(v), 1))
            lash = _smoothstep(0.2, 0.0, frac)
            c = c * (1 - 0.85 * lash[:, None]) + HAIR * 0.5 * 0.85 * lash[:, None] if which == "upper" else c * (1 - 0.35 * lash[:, None]) + (SKIN * 0.6) * 0.35 * lash[:, None]
            jj, ww = head_weights(len(v))
            mb.add(v + centre, f, c, MAT_SKIN, joints=jj, weights=ww, group=f"lid_{which}{side}")
            local[f"lid_{which}{side}"] = v
        v, f = _brow(sx, lambda q: _face_features(_head_surface(*q))[0])
        jj, ww = head_weights(len(v))
        mb.add(v + centre, f, BROW, MAT_HAIR, joints=jj, weights=ww, group=f"brow{side}")
        local[f"brow{side}"] = v
        ear_c = np.array([sx * 0.072, -0.004, -0.010])
        th = np.linspace(0, np.pi, 10)
        ph = np.linspace(0, 2 * np.pi, 14, endpoint=False)
        TH, PH = np.meshgrid(th, ph, indexing="ij")
        d = np.stack([np.sin(TH) * np.cos(PH), np.cos(TH), np.sin(TH) * np.sin(PH)], -1).reshape(-1, 3)
        v = ear_c + d * [0.010, 0.030, 0.019]
        v[:, 0] += sx * 0.006 * (d[:, 2] + 0.3)  # stand out from the skull towards the back
        f = _grid_faces(len(th), len(ph))
        if (np.cross(v[f[0, 1]] - v[f[0, 0]], v[f[0, 2]] - v[f[0, 0]]) * (v[f[0, 0]] - ear_c)).sum() < 0:
            f = f[:, [0, 2, 1]]
        jj, ww = head_weights(len(v))
        mb.add(v + centre, f, SKIN * 0.95, MAT_SKIN, joints=jj, weights=ww)
    # hair cap: the skull surface pushed outwards above a hairline that is high in front, low at the back
    hl_lon = np.radians(np.linspace(-180, 180, 52, endpoint=False))
    v_frac = np.linspace(0, 1, 16)
    LON2, VF = np.meshgrid(hl_lon, v_frac)
    hairline = _hairline(LON2) + np.radians(6.0)
    front = np.clip(np.cos(LON2), 0, 1)
    LAT2 = hairline + (np.radians(90) - hairline) * VF ** 0.8
    hp = _head_surface(LON2, LAT2)
    n = hp / np.linalg.norm(hp / _HEAD_R, axis=-1, keepdims=True)
    thick = 0.004 + 0.010 * _smoothstep(0.0, 0.5, VF) * (1 - 0.3 * front)
    hp = hp + (hp / np.linalg.norm(hp, axis=-1, keepdims=True)) * thick[..., None]
    hp[..., 1] += 0.010 * _smoothstep(0.2, 1.0, VF)
    hv = hp.reshape(-1, 3)
    f = _grid_faces(len(v_frac), len(hl_lon))
    fn = np.cross(hv[f[:, 1]] - hv[f[:, 0]], hv[f[:, 2]] - hv[f[:, 0]])
    if (fn * hv[f[:, 0]]).sum() < 0:
        f = f[:, [0, 2, 1]]
    jj, ww = head_weights(len(hv))
    # the hairline edge is tucked into the skin so the open border never shows
    edge = VF.reshape(-1) < 0.06
    hv[edge] = hv[edge] - (hv[edge] / np.linalg.norm(hv[edge], axis=1, keepdims=True)) * 0.006
    shade = 0.92 + 0.08 * _smoothstep(0.0, 1.0, VF.reshape(-1))
    mb.add(hv + centre, f, HAIR[None] * shade[:, None], MAT_HAIR, joints=jj, weights=ww, group="hair")
    # teeth (upper fixed, lower on the jaw) and tongue
    for which, yoff in (("upper", 0.0045), ("lower", -0.0045)):
        ang = np.linspace(-1.0, 1.0, 13)
        arc = np.stack([0.022 * np.sin(ang), np.full_like(ang, _MOUTH_Y + yoff), 0.066 + 0.016 * np.cos(ang)], -1)
        v, f = _tube(arc, 0.0035, 0.0042, [0, 0, 1.0], n_around=10, cap_start=True, cap_end=True)
        v = v.reshape(-1, 3)
        v[:, 1] = np.clip(v[:, 1], _MOUTH_Y + yoff - 0.0045, _MOUTH_Y + yoff + 0.0045)
        jj, ww = head_weights(len(v))
        mb.add(v + centre, f, TEETH, MAT_TEETH, joints=jj, weights=ww, group=f"teeth_{which}")
        local[f"teeth_{which}"] = v
    th = np.linspace(0, np.pi, 10)
    ph = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    TH, PH = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], -1).reshape(-1, 3)
    v = np.array([0.0, _MOUTH_Y - 0.010, 0.056]) + d * [0.018, 0.006, 0.026]
    f = _grid_faces(len(th), len(ph))[:, [0, 2, 1]]
    jj, ww = head_weights(len(v))
    mb.add(v + centre, f, TONGUE, MAT_SKIN, joints=jj, weights=ww, group="tongue")
    local["tongue"] = v
    return local


def _hairline(lon: np.ndarray) -> np.ndarray:
    """Latitude (radians) of the hairline: high on the forehead, lower at the temples, low at the nape."""
    front = np.clip(np.cos(lon), 0, 1)
    return np.radians(-32 + 66 * front ** 1.6 - 10 * np.abs(np.sin(lon)) * front)


def _eye_centre(sx: int) -> np.ndarray:
    lon = np.arcsin(sx * _EYE_X / _HEAD_R[0])
    lat = np.arcsin(_EYE_Y / _HEAD_R[1])
    surf = _head_surface(np.array(lon), np.array(lat))
    return np.array([sx * _EYE_X, _EYE_Y, float(surf[2]) - _EYE_R + 0.0005])


def _lid_arc(alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """Directions on the lid sphere: a horizontal arc (beta) tilted up by alpha about the eye's x axis."""
    return np.stack([np.sin(beta), np.cos(beta) * np.sin(alpha), np.cos(beta) * np.cos(alpha)], -1)


_LID_EDGES = {  # alpha of the lid edge (radians): open, blink, squint, wide
    "upper": (np.radians(19.0), np.radians(-19.0), np.radians(6.0), np.radians(34.0)),
    "lower": (np.radians(-24.0), np.radians(-20.0), np.radians(-10.0), np.radians(-28.0)),
}


def _lid_alpha(which: str, edge: float, frac: np.ndarray) -> np.ndarray:
    far = np.radians(120.0) if which == "upper" else np.radians(-120.0)
    return edge + (far - edge) * frac


def _lid(sx: int, which: str, edge: float | None = None, open_: bool = True):
    beta = np.radians(np.linspace(-78, 78, 16))
    frac = np.linspace(0, 1, 10) ** 1.4
    F, B = np.meshgrid(frac, beta, indexing="ij")
    e = _LID_EDGES[which][0] if edge is None else edge
    d = _lid_arc(_lid_alpha(which, e, F), B)
    v = _eye_centre(sx) + _LID_R * d.reshape(-1, 3)
    f = _grid_faces(len(frac), len(beta), wrap=False)
    ec = _eye_centre(sx)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    if (fn * (v[f[:, 0]] - ec)).sum() < 0:
        f = f[:, [0, 2, 1]]
    return v, f, F.reshape(-1)


def _lid_shape(sx: int, which: str, edge: float) -> np.ndarray:
    return _lid(sx, which, edge=edge)[0]


def _brow(sx: int, surface) -> tuple[np.ndarray, np.ndarray]:
    s = np.linspace(0, 1, 14)
    x = sx * (0.011 + 0.047 * s)
    y = _BROW_Y + 0.006 * np.sin(np.pi * (s * 0.85 + 0.1)) - 0.004 * s ** 2
    lon = np.arcsin(np.clip(x / _HEAD_R[0], -1, 1))
    lat = np.arcsin(np.clip(y / _HEAD_R[1], -1, 1))
    p = surface((lon, lat))
    p = np.asarray(p).reshape(-1, 3).copy()
    p[:, 1] = y
    p[:, 2] += 0.0012
    r_up = 0.0026 * (1 - 0.5 * s) + 0.0010
    r_side = 0.0016 * np.ones_like(s)
    v, f = _tube(p, r_side, r_up, [0, 0, 1.0], n_around=8)
    return v, f


# ---------------------------------------------------------------------------------------------
# Morph targets (ARKit): displacement fields in head space
# ---------------------------------------------------------------------------------------------

def _rot_x(points: np.ndarray, pivot: np.ndarray, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    q = points - pivot
    y = c * q[:, 1] - s * q[:, 2]
    z = s * q[:, 1] + c * q[:, 2]
    return np.stack([q[:, 0], y, z], -1) + pivot


def _rot_y(points: np.ndarray, pivot: np.ndarray, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    q = points - pivot
    x = c * q[:, 0] + s * q[:, 2]
    z = -s * q[:, 0] + c * q[:, 2]
    return np.stack([x, q[:, 1], z], -1) + pivot


_JAW_PIVOT = np.array([0.0, -0.010, -0.012])
_JAW_OPEN = np.radians(17.0)


def _jaw_weight(p: np.ndarray, lat: np.ndarray | None) -> np.ndarray:
    """How much each face vertex follows the jaw: 1 on the chin and lower lip, 0 above the lip line.

    Inside the mouth the slit rows spread evenly between the lips; at the cheeks the transition is soft.
    """
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    soft = _smoothstep(_MOUTH_Y + 0.006, _MOUTH_Y - 0.030, y)
    lat_m = np.arcsin(_MOUTH_Y / _HEAD_R[1])
    if lat is not None:
        span = np.radians(0.30)
        sharp = np.clip((lat_m + span - lat) / (2 * span), 0, 1)
        sharp = np.where(lat > lat_m + span, 0.0, np.where(lat < lat_m - span, 1.0, sharp))
    else:
        sharp = (y < _MOUTH_Y).astype(float)
    lateral = _smoothstep(_MOUTH_HW * 0.95, _MOUTH_HW * 1.6, np.abs(x))
    w = sharp * (1 - lateral) + soft * lateral
    # the jaw ends below the ears; the back of the head does not move
    w = w * _smoothstep(-0.045, 0.0, z) * (1 - _smoothstep(0.062, 0.074, np.abs(x)) * (y > _MOUTH_Y - 0.03))
    return w


def _morphs(local: dict[str, np.ndarray], groups: dict[str, np.ndarray], n_vertices: int) -> np.ndarray:
    """All 52 ARKit morph targets as (52, V, 3) displacements (head space == world space axes)."""
    M = len(ARKIT_NAMES)
    deltas = np.zeros((M, n_vertices, 3))
    idx = {name: i for i, name in enumerate(ARKIT_NAMES)}

    def put(name: str, group: str, d: np.ndarray) -> None:
        deltas[idx[name], groups[group]] += d

    face = local["face"]
    lat = local["face_lat"]
    fx, fy, fz = face[:, 0], face[:, 1], face[:, 2]
    frontal = _smoothstep(0.02, 0.06, fz)[:, None]

    # --- jaw ------------------------------------------------------------------------------------
    wj = _jaw_weight(face, lat)[:, None]
    jaw_d = (_rot_x(face, _JAW_PIVOT, _JAW_OPEN) - face) * wj
    # the cavity rows sink into the head so the open mouth reads as a hole, not a stretched skin
    inner = local["face_inner"].astype(float)
    lat_m = np.arcsin(_MOUTH_Y / _HEAD_R[1])
    mid = np.clip(1 - np.abs(lat - lat_m) / np.radians(0.30), 0, 1)
    in_mouth = (1 - _smoothstep(_MOUTH_HW * 0.6, _MOUTH_HW * 1.0, np.abs(fx))) * (np.abs(lat - lat_m) <= np.radians(0.31))
    sink = np.zeros_like(face)
    sink[:, 2] = -0.022 * mid * in_mouth
    put("jawOpen", "face", jaw_d + sink * frontal)
    for which, w in (("teeth_lower", 1.0), ("tongue", 1.0)):
        p = local[which]
        put("jawOpen", which, (_rot_x(p, _JAW_PIVOT, _JAW_OPEN) - p) * w)
    fwd = np.zeros_like(face)
    fwd[:, 2] = 0.008
    put("jawForward", "face", fwd * wj)
    put("jawForward", "teeth_lower", np.tile([0, 0, 0.008], (len(local["teeth_lower"]), 1)))
    for name, s in (("jawLeft", 1), ("jawRight", -1)):
        put(name, "face", (_rot_y(face, _JAW_PIVOT, s * np.radians(6)) - face) * wj)
        p = local["teeth_lower"]
        put(name, "teeth_lower", _rot_y(p, _JAW_PIVOT, s * np.radians(6)) - p)

    # --- mouth ------------------------------------------------------------------------------------
    dy = fy - _MOUTH_Y
    around = _gauss(fx ** 2 / 1.6 + dy ** 2, 0.016)[:, None] * frontal
    upper_lip = (_gauss(fx ** 2 / 2.5 + (dy - 0.006) ** 2, 0.007) * (lat >= lat_m - 1e-9))[:, None] * frontal
    lower_lip = (_gauss(fx ** 2 / 2.5 + (dy + 0.007) ** 2, 0.008) * (lat < lat_m + 1e-9))[:, None] * frontal
    # mouthClose: lips meet while the jaw is open (undo the slit spreading for the lower lip)
    put("mouthClose", "face", -jaw_d * np.clip(1 - _smoothstep(_MOUTH_Y - 0.004, _MOUTH_Y - 0.03, fy), 0, 1)[:, None] * 0.9 * frontal)
    lip_zone = np.maximum(upper_lip, lower_lip)
    to_centre = np.zeros_like(face)
    to_centre[:, 0] = -fx * 0.35
    to_centre[:, 2] = 0.008
    put("mouthPucker", "face", to_centre * around)
    fun = np.zeros_like(face)
    fun[:, 0] = -fx * 0.2
    # the lips part only between the mouth corners: beyond them the slit rows must stay together, or the
    # stretched skin between them shows as a light crack across the cheeks
    fun[:, 1] = np.sign(dy) * 0.003 * (1 - _smoothstep(_MOUTH_HW * 0.8, _MOUTH_HW * 1.1, np.abs(fx)))
    fun[:, 2] = 0.007
    put("mouthFunnel", "face", fun * around)
    for name, s in (("mouthLeft", 1), ("mouthRight", -1)):
        d = np.zeros_like(face)
        d[:, 0] = s * 0.008
        put(name, "face", d * around)
    for side, sx in (("Left", 1), ("Right", -1)):
        corner = _gauss((fx - sx * _MOUTH_HW) ** 2 + (dy * 1.2) ** 2, 0.013)[:, None] * frontal
        put(f"mouthSmile{side}", "face", corner * np.array([sx * 0.006, 0.0085, -0.004]))
        put(f"mouthFrown{side}", "face", corner * np.array([sx * 0.001, -0.006, 0.0]))
        put(f"mouthDimple{side}", "face", corner * np.array([sx * 0.002, 0.001, -0.005]))
        put(f"mouthStretch{side}", "face", corner * np.array([sx * 0.007, -0.003, -0.002]))
        put(f"mouthPress{side}", "face", (corner * 0.6 + lip_zone * 0.4) * np.array([0.0, 0.0, -0.003])
            + (upper_lip - lower_lip) * np.array([0, -0.0015, 0]) * (fx * sx > 0)[:, None])
        half = _smoothstep(-0.004, 0.012, fx * sx)[:, None]
        put(f"mouthLowerDown{side}", "face", lower_lip * half * np.array([0, -0.006, 0.001]))
        put(f"mouthUpperUp{side}", "face", upper_lip * half * np.array([0, 0.005, 0.001]))
        # cheeks and nose
        cheek = _gauss((fx - sx * 0.040) ** 2 + (fy + 0.022) ** 2, 0.013)[:, None] * frontal
        put(f"cheekSquint{side}", "face", cheek * np.array([0.0, 0.004, 0.001]))
        nose = _gauss((fx - sx * 0.012) ** 2 + (fy + 0.030) ** 2, 0.008)[:, None] * frontal
        put(f"noseSneer{side}", "face", nose * np.array([0.0, 0.0035, 0.001]))
    put("mouthRollLower", "face", lower_lip * np.array([0, 0.002, -0.004]))
    put("mouthRollUpper", "face", upper_lip * np.array([0, -0.002, -0.004]))
    put("mouthShrugLower", "face", lower_lip * np.array([0, 0.004, 0.002]))
    put("mouthShrugUpper", "face", upper_lip * np.array([0, 0.003, 0.001]))
    puff = np.zeros_like(face)
    for sx in (1, -1):
        g = _gauss((fx - sx * 0.045) ** 2 + (fy + 0.050) ** 2, 0.016)
        puff[:, 0] += sx * 0.007 * g
        puff[:, 2] += 0.003 * g
    put("cheekPuff", "face", puff * frontal)
    tg = local["tongue"]
    put("tongueOut", "tongue", np.tile([0.0, -0.002, 0.030], (len(tg), 1)) * _smoothstep(0.03, 0.08, tg[:, 2])[:, None]
        + np.tile([0.0, 0.0, 0.012], (len(tg), 1)))

    # --- brows ----------------------------------------------------------------------------------
    for side, sx in (("Left", 1), ("Right", -1)):
        for group in ("face", f"brow{side}"):
            p = local[group] if group != "face" else face
            px, py = p[:, 0], p[:, 1]
            region = _gauss((px - sx * 0.034) ** 2 * 0.35 + (py - _BROW_Y) ** 2, 0.010)[:, None]
            region = region * (px * sx > -0.004)[:, None]
            if group == "face":
                region = region * frontal * 0.8
            inner = _smoothstep(0.045, 0.012, np.abs(px))[:, None]
            outer = _smoothstep(0.025, 0.055, np.abs(px))[:, None]
            put(f"browDown{side}", group, region * (np.array([-sx * 0.0025, -0.0055, 0.0]) * (0.5 + 0.5 * inner)))
            put("browInnerUp", group, region * inner * np.array([0.0, 0.0085, 0.0]))
            put(f"browOuterUp{side}", group, region * outer * np.array([0.0, 0.0075, 0.0]))

    # --- eyes -----------------------------------------------------------------------------------
    for side, sx in (("Left", 1), ("Right", -1)):
        ec = _eye_centre(sx)
        for which in ("upper", "lower"):
            g = f"lid_{which}{side}"
            open_v = local[g]
            e_open, e_blink, e_squint, e_wide = _LID_EDGES[which]
            put(f"eyeBlink{side}", g, _lid_shape(sx, which, e_blink) - open_v)
            put(f"eyeSquint{side}", g, _lid_shape(sx, which, e_squint) - open_v)
            put(f"eyeWide{side}", g, _lid_shape(sx, which, e_wide) - open_v)
        eye = local[f"eye{side}"]
        look = {"Up": (_rot_x, -np.radians(22)), "Down": (_rot_x, np.radians(24)),
                "In": (_rot_y, -sx * np.radians(26)), "Out": (_rot_y, sx * np.radians(26))}
        for direction, (rot, ang) in look.items():
            put(f"eyeLook{direction}{side}", f"eye{side}", rot(eye, ec, ang) - eye)
        # the upper lid follows an upward/downward look a little, as real lids do
        lid_up = local[f"lid_upper{side}"]
        put(f"eyeLookDown{side}", f"lid_upper{side}", (_lid_shape(sx, "upper", np.radians(14)) - lid_up) * 0.6)
    return deltas.astype(np.float32)


# ---------------------------------------------------------------------------------------------
# Body
# ---------------------------------------------------------------------------------------------

def _build_body(mb: _MeshBuilder) -> None:
    jp = mb.jp
    sk = mb.sk
    P = lambda n: jp[sk.index(n)]  # noqa: E731
    spine_bones = ["Hips", "Spine", "Chest", "UpperChest", "Neck", "LeftShoulder", "RightShoulder"]
    # torso: sections from the crotch to the base of the neck (y, half width, half depth, z centre)
    prof = np.array([
        [0.830, 0.050, 0.045, 0.000],
        [0.870, 0.140, 0.072, 0.000],
        [0.930, 0.170, 0.100, -0.004],
        [0.990, 0.165, 0.098, -0.002],
        [1.060, 0.145, 0.092, 0.004],
        [1.120, 0.140, 0.094, 0.010],
        [1.190, 0.148, 0.100, 0.014],
        [1.260, 0.158, 0.106, 0.014],
        [1.320, 0.170, 0.104, 0.008],
        [1.380, 0.182, 0.096, -0.002],
        [1.425, 0.178, 0.084, -0.010],
        [1.455, 0.150, 0.072, -0.014],
        [1.472, 0.092, 0.064, -0.016],
        [1.488, 0.050, 0.046, -0.018],  # narrower than the neck: its tube comes out of a crew neck here
    ])
    # rows every ~1.5 cm, with extra rows at the belt so the shirt/trousers edge stays crisp
    ys = np.unique(np.concatenate([np.linspace(prof[0, 0], prof[-1, 0], 34), 1.02 + np.array([-0.02, -0.013, -0.006, 0.0, 0.006, 0.013, 0.02])]))
    hw = np.interp(ys, prof[:, 0], prof[:, 1])
    hd = np.interp(ys, prof[:, 0], prof[:, 2])
    zc = np.interp(ys, prof[:, 0], prof[:, 3])
    path = np.stack([np.zeros_like(ys), ys, zc], -1)
    # the open bottom hides between the legs; the top is closed under the neck
    v, f = _tube(path, hw, hd, [1.0, 0, 0], n_around=32, cap_start=False, cap_end=True, squareness=0.35)
    # chest and shoulder blades: a little relief so the light catches form
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    for sx in (1, -1):
        v[:, 2] += 0.010 * _gauss((x - sx * 0.065) ** 2 + (y - 1.27) ** 2 * 1.5, 0.04) * (z > 0)
        v[:, 2] -= 0.008 * _gauss((x - sx * 0.07) ** 2 + (y - 1.30) ** 2, 0.04) * (z < 0)
    # trapezius slopes from the neck down to the shoulders
    top = _smoothstep(1.40, 1.49, y)
    v[:, 1] -= 0.030 * top * _smoothstep(0.04, 0.16, np.abs(x))
    col = np.where((v[:, 1] < 1.02)[:, None], TROUSERS, SHIRT)
    belt = np.abs(v[:, 1] - 1.02) < 0.0095
    col[belt] = TROUSERS * 0.6
    # crew neck: the neck (skin) comes out of the shirt. A neckline painted on these ~1.5 cm rows would be
    # smeared across a row by per-vertex colour; the neck tube's edge against the torso is crisp.
    # Below the hips the torso narrows into the crotch between the legs. Its own normals face down there,
    # so it would read as a separately lit patch ("briefs") where it shows between the thigh tubes: shade
    # it with level normals, as the vertical thighs are, and the trousers read as one piece of cloth.
    f = _outward(v, f)
    nrm = vertex_normals(v, f).astype(np.float64)
    level = _smoothstep(0.99, 0.93, v[:, 1])
    nrm[:, 1] *= 1 - level
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    bias = {"LeftShoulder": 1.25, "RightShoulder": 1.25, "Neck": 1.3}
    joints, weights = mb.weights_for(v, spine_bones + ["LeftUpperArm", "RightUpperArm"],
                                     bias={**bias, "LeftUpperArm": 1.6, "RightUpperArm": 1.6})
    # below the hip joints the torso is the top of the trousers: it follows the thighs, so a pelvis tilted
    # against the legs bends the crotch instead of swinging it forwards through the thigh tubes
    hip_y = P("LeftUpperLeg")[1]
    to_legs = _smoothstep(hip_y + 0.02, hip_y - 0.07, v[:, 1])
    left = _smoothstep(-0.03, 0.03, v[:, 0])
    joints, weights = _blend_in(joints, weights, [sk.index("LeftUpperLeg"), sk.index("RightUpperLeg")],
                                np.stack([to_legs * left, to_legs * (1 - left)], axis=1))
    mb.add(v, f, col, MAT_CLOTH, joints=joints, weights=weights, normals=nrm.astype(np.float32))
    # neck
    ys = np.linspace(1.38, 1.59, 9)
    path = np.stack([np.zeros_like(ys), ys, -0.02 + 0.02 * (ys - 1.40)], -1)
    r = 0.064 - 0.010 * _smoothstep(1.40, 1.52, ys)
    v, f = _tube(path, r, r * 0.95, [1.0, 0, 0], n_around=16, cap_start=False, cap_end=False)
    mb.add(v, f, SKIN, MAT_SKIN, bones=["UpperChest", "Neck", "Head"], bias={"Head": 1.4})
    # arms: one tube from the shoulder to the wrist (sleeve), the hand separately
    for side, sx in (("Left", 1), ("Right", -1)):
        a, e, w = P(f"{side}UpperArm"), P(f"{side}LowerArm"), P(f"{side}Hand")
        sh = a + np.array([-sx * 0.03, -0.012, 0.0])
        upper_len = np.linalg.norm(e - sh)
        total = upper_len + np.linalg.norm(w - e)
        # rings every ~2.5 cm, plus pairs a millimetre either side of the cuff's edges: per-vertex colour
        # would otherwise smear the sleeve into the skin over a whole ring spacing
        edges = total - np.array([0.048, 0.032])
        d = np.unique(np.concatenate([np.linspace(0, total, 23), edges - 0.001, edges + 0.001]))
        s = d / total
        path = np.where((d < upper_len)[:, None], sh + (e - sh) * (d / upper_len)[:, None],
                        e + (w - e) * ((d - upper_len) / (total - upper_len))[:, None])
        ru = np.interp(s, [0, 0.08, 0.25, 0.5, 0.56, 0.75, 1.0], [0.040, 0.045, 0.043, 0.037, 0.038, 0.035, 0.026])
        rs = np.interp(s, [0, 0.08, 0.25, 0.5, 0.56, 0.75, 1.0], [0.046, 0.048, 0.042, 0.036, 0.039, 0.036, 0.030])
        v, f = _tube(path, rs, ru, [0, 0, 1.0], n_around=18, cap_start=True, cap_end=True)
        col = np.tile(SHIRT, (len(v), 1))
        along = (v - sh) @ ((w - sh) / np.linalg.norm(w - sh))
        col[along > edges[1]] = SKIN
        col[(along > edges[0]) & (along <= edges[1])] = SHIRT * 0.8  # cuff
        mb.add(v, f, col, MAT_CLOTH, bones=[f"{side}Shoulder", f"{side}UpperArm", f"{side}LowerArm", f"{side}Hand"],
               bias={f"{side}Shoulder": 1.5})
        _build_hand(mb, side, sx)
    # legs and shoes (simple: the framing is mostly upper body)
    for side, sx in (("Left", 1), ("Right", -1)):
        hip, knee, ankle = P(f"{side}UpperLeg"), P(f"{side}LowerLeg"), P(f"{side}Foot")
        s = np.linspace(0, 1, 14)
        # starts inside the pelvis, a little towards the middle: the two thighs meet below the crotch, so
        # from the front the trousers show two legs and a seam, not the torso's narrowing bottom
        # (high and closed: a pelvis tilted 15 degrees against the thighs, as BEAT's rest pose is, lifts the
        # torso's front edge by some 3 cm, and an open tube end just below it would show)
        top = hip + np.array([-sx * 0.016, 0.06, 0])
        path = np.where((s < 0.5)[:, None], top + (knee - top) * (s / 0.5)[:, None],
                        knee + (ankle - knee) * ((s - 0.5) / 0.5)[:, None])
        # nearly straight at the top (a bulge would catch the light as a seam); the open top stays inside
        # the hips
        r = np.interp(s, [0, 0.077, 0.154, 0.3, 0.5, 0.7, 0.95, 1],
                      [0.082, 0.081, 0.078, 0.068, 0.056, 0.055, 0.045, 0.044])
        v, f = _tube(path, r, r * 1.05, [1.0, 0, 0], n_around=20, cap_start=True, cap_end=False)
        joints, weights = mb.weights_for(v, [f"{side}UpperLeg", f"{side}LowerLeg", f"{side}Foot"])
        # and the top of the thigh, inside the hips, follows the pelvis as the torso there does
        joints, weights = _blend_in(joints, weights, [sk.index("Hips")],
                                    _smoothstep(hip[1] - 0.07, hip[1] + 0.02, v[:, 1])[:, None])
        mb.add(v, f, TROUSERS, MAT_CLOTH, joints=joints, weights=weights)
        toe = P(f"{side}Toes")
        fpath = np.array([ankle + [0, -0.03, -0.07], ankle + [0, -0.045, 0.0], toe + [0, -0.01, 0.0], toe + [0, -0.012, 0.065]])
        fs = np.linspace(0, 1, 7)
        fp = np.array([np.interp(fs, np.linspace(0, 1, 4), fpath[:, k]) for k in range(3)]).T
        rs = np.interp(fs, [0, 0.4, 0.8, 1], [0.040, 0.046, 0.048, 0.036])
        ru = np.interp(fs, [0, 0.4, 0.8, 1], [0.050, 0.045, 0.030, 0.024])
        v, f = _tube(fp, rs, ru, [1.0, 0, 0], n_around=10)
        v[:, 1] = np.maximum(v[:, 1], 0.0)
        mb.add(v, f, SHOES, MAT_CLOTH, bones=[f"{side}Foot", f"{side}Toes"])


def _build_hand(mb: _MeshBuilder, side: str, sx: int) -> None:
    sk, jp = mb.sk, mb.jp
    P = lambda n: jp[sk.index(n)]  # noqa: E731
    wrist = P(f"{side}Hand")
    # palm: a flattened rounded box from the wrist to the knuckles
    knuckle_x = P(f"{side}MiddleProximal")[0]
    s = np.linspace(0, 1, 7)
    path = np.stack([wrist[0] + sx * (-0.012 + s * (abs(knuckle_x - wrist[0]) + 0.012)),
                     np.full_like(s, wrist[1] - 0.002), wrist[2] + 0.0 * s - 0.003], -1)
    half_width = np.interp(s, [0, 0.3, 1], [0.030, 0.040, 0.044])
    half_thick = np.interp(s, [0, 0.4, 1], [0.017, 0.016, 0.012])
    v, f = _tube(path, half_width, half_thick, [0, 0, 1.0], n_around=16, squareness=0.5)
    thumb_side = v[:, 2] > wrist[2]
    v[thumb_side, 1] -= 0.003 * _smoothstep(0.0, 0.4, (v[thumb_side, 0] - wrist[0]) * sx / 0.09)
    mb.add(v, f, SKIN, MAT_SKIN, bones=[f"{side}LowerArm", f"{side}Hand", f"{side}ThumbProximal",
                                      f"{side}IndexProximal", f"{side}MiddleProximal", f"{side}RingProximal",
                                      f"{side}LittleProximal"],
           bias={f"{side}Hand": 0.55, f"{side}LowerArm": 1.6, f"{side}ThumbProximal": 1.2})
    for finger in _FINGERS:
        names = [f"{side}{finger}{seg}" for seg in ("Proximal", "Intermediate", "Distal")]
        pts = [P(n) for n in names]
        tip = pts[-1] + sk.end_sites[sk.index(names[-1])]
        poly = np.array(pts + [tip])
        if finger == "Thumb":
            poly = np.vstack([wrist + np.array([sx * 0.012, -0.008, 0.012]), poly])
        seg_len = np.linalg.norm(np.diff(poly, axis=0), axis=1)
        cum = np.concatenate([[0], np.cumsum(seg_len)])
        t = np.linspace(0, cum[-1], 11)
        path = np.array([np.interp(t, cum, poly[:, k]) for k in range(3)]).T
        r0 = _FINGER_RADIUS[finger]
        prof = r0 * np.interp(t / cum[-1], [0, 0.5, 1], [1.1 if finger == "Thumb" else 1.0, 0.92, 0.80])
        v, f = _tube(path, prof, prof * 0.88, [0, 0, 1.0], n_around=8, cap_start=True, cap_end=True)
        bones = names + [f"{side}Hand"]
        mb.add(v, f, SKIN, MAT_SKIN, bones=bones, bias={f"{side}Hand": 1.6}, power=6.0)


# ---------------------------------------------------------------------------------------------
# Build
# ---------------------------------------------------------------------------------------------

#: The built-in avatar's arrays kept on disk (everything else is fixed by the code).
_CACHED_ARRAYS = ("vertices", "normals", "indices", "colors", "joints", "weights", "inverse_bind", "morph_deltas",
                  "morph_normal_deltas", "material")
_CACHED_DTYPES = {"vertices": "f4", "normals": "f4", "indices": "u4", "colors": "f4", "joints": "u2", "weights": "f4",
                  "inverse_bind": "f4", "morph_deltas": "f4", "morph_normal_deltas": "f4", "material": "u1"}


def _cache_file() -> Path:
    """Where the built-in avatar's arrays are kept: named by what they are made from."""
    import hashlib

    from studyapp.face import arkit
    from studyapp.motion import fk, skeleton

    h = hashlib.sha256(np.__version__.encode())
    for module in (__file__, arkit.__file__, fk.__file__, skeleton.__file__):
        h.update(Path(module).read_bytes())
    env = os.environ.get("STUDYAPP_CACHE_DIR")
    if env:
        base = Path(env)
    else:
        import platformdirs

        base = Path(platformdirs.user_cache_dir("studyapp", appauthor=False))
    return base / "avatar" / f"builtin-{h.hexdigest()[:32]}.npz"


def _from_arrays(arrays: dict[str, np.ndarray]) -> Avatar:
    return Avatar(skeleton=default_skeleton(), morph_names=ARKIT_NAMES, name="builtin", **arrays)


def _load_or_build() -> Avatar:
    """The built-in avatar from the disk cache, or modelled now (and kept for the next process)."""
    try:
        path = _cache_file()
    except OSError:
        return _build()
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in _CACHED_ARRAYS}
        n_vertices = len(arrays["vertices"])
        sk = default_skeleton()
        if (all(arrays[k].dtype == np.dtype(t) for k, t in _CACHED_DTYPES.items())
                and all(len(arrays[k]) == n_vertices for k in ("normals", "colors", "joints", "weights", "material"))
                and arrays["morph_deltas"].shape == arrays["morph_normal_deltas"].shape == (len(ARKIT_NAMES), n_vertices, 3)
                and arrays["inverse_bind"].shape == (len(sk.names), 4, 4)):
            return _from_arrays(arrays)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        pass  # missing or damaged: model it again
    av = _build()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
        np.savez(tmp, **{k: getattr(av, k) for k in _CACHED_ARRAYS})
        os.replace(tmp, path)  # whole or not at all, whoever else writes it at the same time
    except OSError:
        pass  # a read-only cache only means the next process models it again
    return av


@functools.lru_cache(maxsize=1)
def _build_cached() -> Avatar:
    av = _load_or_build()
    for arr in (av.vertices, av.normals, av.indices, av.colors, av.joints, av.weights, av.inverse_bind,
                av.morph_deltas, av.morph_normal_deltas, av.material):
        arr.setflags(write=False)  # shared by every caller of the cache
    return av


def _build() -> Avatar:
    """Model the built-in avatar (deterministic)."""
    sk = default_skeleton()
    rest = rest_global_transforms(sk)
    jp = rest[:, :3, 3]
    mb = _MeshBuilder(sk, jp)
    _build_body(mb)
    head_centre = jp[sk.index("Head")] + np.array([0.0, 0.088, 0.020])
    local = _build_head(mb, head_centre)
    verts = np.concatenate(mb.v)
    normals = np.concatenate(mb.n)
    faces = np.concatenate(mb.f)
    deltas = _morphs(local, mb.groups, len(verts))
    # morph normals: recompute normals of the fully-morphed face and store the difference
    face_idx = mb.groups["face"]
    normal_deltas = np.zeros_like(deltas)
    face_tris = faces[np.isin(faces[:, 0], face_idx) & np.isin(faces[:, 1], face_idx) & np.isin(faces[:, 2], face_idx)]
    remap = np.full(len(verts), -1)
    remap[face_idx] = np.arange(len(face_idx))
    ft = remap[face_tris]
    base_n = vertex_normals(verts[face_idx], ft)
    for m in range(len(ARKIT_NAMES)):
        d = deltas[m, face_idx]
        if np.abs(d).max() > 1e-6:
            normal_deltas[m, face_idx] = vertex_normals(verts[face_idx] + d, ft) - base_n
    inv_bind = np.linalg.inv(rest).astype(np.float32)
    av = Avatar(
        skeleton=sk, vertices=verts, normals=normals, indices=faces, colors=np.concatenate(mb.c),
        joints=np.concatenate(mb.j), weights=np.concatenate(mb.w), inverse_bind=inv_bind,
        morph_names=ARKIT_NAMES, morph_deltas=deltas, morph_normal_deltas=normal_deltas,
        material=np.concatenate(mb.m), name="builtin",
    )
    return av


def build_default_avatar() -> Avatar:
    """The built-in humanoid avatar (deterministic, built once per process and cached; arrays read-only)."""
    return _build_cached()
