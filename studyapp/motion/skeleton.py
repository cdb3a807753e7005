"""Plain data classes for skeletal animation.

Conventions used everywhere in studyapp (state them once, rely on them always):

* Joints are stored in depth-first order, so ``parents[j] < j`` for every non-root joint; batched
  forward kinematics relies on this to walk the array once.
* Quaternions are scalar-last ``(x, y, z, w)``, as in ``scipy.spatial.transform.Rotation``.
* Rotations are *local* (relative to the parent joint's frame); translations are local too and
  equal the joint's rest ``offset`` unless the source animates that joint's position.
* World space is right-handed, +Y up, units as in the source file (``Skeleton.unit_scale`` converts
  to metres when known).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy with rest offsets.

    Attributes
    ----------
    names:
        Joint names, unique, depth-first order.
    parents:
        ``(J,)`` int array, ``-1`` for roots, ``parents[j] < j`` otherwise.
    offsets:
        ``(J, 3)`` rest translation of each joint relative to its parent.
    channels:
        For BVH round trips: the channel names of each joint (``("Xposition", ..., "Zrotation")``);
        empty tuples for joints without channels. Non-BVH sources use the BVH default layout.
    end_sites:
        ``{joint index: (3,) offset}`` for joints that carry a BVH ``End Site``.
    unit_scale:
        Factor that converts this skeleton's length unit to metres (0.01 for centimetres); ``None``
        when unknown.
    rest_rotations:
        ``(J, 4)`` local rotation of each joint in the rest (bind) pose. Identity for BVH, whose rest
        pose is all channels at zero; glTF rigs carry non-identity node rotations.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...] = ()
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)
    unit_scale: float | None = None
    rest_rotations: np.ndarray | None = None

    def __post_init__(self) -> None:
        parents = np.asarray(self.parents, dtype=np.int64)
        offsets = np.asarray(self.offsets, dtype=np.float64).reshape(-1, 3)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "names", tuple(self.names))
        n = len(self.names)
        if parents.shape != (n,) or offsets.shape != (n, 3):
            raise ValueError(f"skeleton arrays disagree: {n} names, parents {parents.shape}, offsets {offsets.shape}")
        if len(set(self.names)) != n:
            dup = sorted({x for x in self.names if self.names.count(x) > 1})
            raise ValueError(f"duplicate joint names: {dup}")
        idx = np.arange(n)
        bad = (parents >= idx) | (parents < -1)
        if bad.any():
            raise ValueError(f"joints must be in depth-first order (parent before child); bad: {[self.names[i] for i in idx[bad]]}")
        if self.rest_rotations is None:
            rest = np.zeros((n, 4))
            rest[:, 3] = 1.0
        else:
            rest = np.asarray(self.rest_rotations, dtype=np.float64).reshape(n, 4)
        object.__setattr__(self, "rest_rotations", rest)
        if not self.channels:
            chans = tuple(
                ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation") if p < 0
                else ("Zrotation", "Xrotation", "Yrotation")
                for p in parents
            )
            object.__setattr__(self, "channels", chans)
        elif len(self.channels) != n:
            raise ValueError(f"channels given for {len(self.channels)} joints, skeleton has {n}")

    @property
    def n_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of a joint by exact name (``KeyError`` listing close names when absent)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no joint named {name!r} in skeleton ({self.n_joints} joints)") from None

    def children(self, j: int) -> list[int]:
        return [int(c) for c in np.flatnonzero(self.parents == j)]

    def rotation_order(self, j: int) -> str | None:
        """Intrinsic Euler order of joint ``j`` as upper-case axes (``"ZXY"``), or None without rotation channels."""
        axes = "".join(c[0].upper() for c in self.channels[j] if c.lower().endswith("rotation"))
        return axes or None

    def has_position_channels(self, j: int) -> bool:
        return any(c.lower().endswith("position") for c in self.channels[j])

    def subset(self, keep: list[int] | np.ndarray) -> "Skeleton":
        """A skeleton of the given joints (each kept joint re-parented to its nearest kept ancestor).

        Offsets of re-parented joints are *not* composed; use it for joint selection, not retargeting.
        """
        keep = sorted(int(k) for k in keep)
        remap = {old: new for new, old in enumerate(keep)}
        parents = []
        for old in keep:
            p = int(self.parents[old])
            while p >= 0 and p not in remap:
                p = int(self.parents[p])
            parents.append(remap.get(p, -1))
        return Skeleton(
            names=tuple(self.names[k] for k in keep),
            parents=np.array(parents),
            offsets=self.offsets[keep].copy(),
            channels=tuple(self.channels[k] for k in keep),
            end_sites={remap[k]: v for k, v in self.end_sites.items() if k in remap},
            unit_scale=self.unit_scale,
            rest_rotations=self.rest_rotations[keep].copy(),
        )


@dataclass(eq=False)
class Motion:
    """Skeletal animation: local rotations and translations per frame.

    Attributes
    ----------
    skeleton:
        The joint hierarchy.
    fps:
        Frames per second.
    rotations:
        ``(F, J, 4)`` local rotations as unit quaternions, scalar-last.
    translations:
        ``(F, J, 3)`` local translations (rest offsets where not animated).
    source:
        Where the motion came from (file path or description), for messages.
    """

    skeleton: Skeleton
    fps: float
    rotations: np.ndarray
    translations: np.ndarray
    source: str = ""

    def __post_init__(self) -> None:
        self.rotations = np.asarray(self.rotations, dtype=np.float64)
        self.translations = np.asarray(self.translations, dtype=np.float64)
        j = self.skeleton.n_joints
        if self.rotations.ndim != 3 or self.rotations.shape[1:] != (j, 4):
            raise ValueError(f"rotations must be (frames, {j}, 4), got {self.rotations.shape}")
        if self.translations.shape != self.rotations.shape[:2] + (3,):
            raise ValueError(f"translations must be (frames, {j}, 3), got {self.translations.shape}")
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"fps must be a positive number, got {self.fps}")

    @property
    def n_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def duration(self) -> float:
        """Length in seconds (``n_frames / fps``)."""
        return self.n_frames / float(self.fps)

    @classmethod
    def rest(cls, skeleton: Skeleton, n_frames: int = 1, fps: float = 30.0) -> "Motion":
        """A motion that holds the rest pose for ``n_frames``."""
        rot = np.broadcast_to(skeleton.rest_rotations, (n_frames, skeleton.n_joints, 4)).copy()
        trans = np.broadcast_to(skeleton.offsets, (n_frames, skeleton.n_joints, 3)).copy()
        return cls(skeleton, fps, rot, trans, source="rest pose")
