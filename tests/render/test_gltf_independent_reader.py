"""Our GLB export read back by an independent glTF reader (trimesh), not only by our own loader.

trimesh reads glTF geometry but not skins or morph targets (DOMAIN.md), so it checks the part both
implement: the accessors, buffer views and mesh layout a real-world viewer sees.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from studyapp.render.avatar import build_default_avatar
from studyapp.render.gltf import export_glb


def test_exported_glb_geometry_reads_identically_in_trimesh(tmp_path: Path) -> None:
    avatar = build_default_avatar()
    path = export_glb(avatar, tmp_path / "avatar.glb")
    scene = trimesh.load(path, process=False)
    meshes = list(scene.geometry.values()) if isinstance(scene, trimesh.Scene) else [scene]
    assert len(meshes) == 1
    mesh = meshes[0]
    np.testing.assert_array_equal(np.asarray(mesh.vertices, np.float32), avatar.vertices)
    np.testing.assert_array_equal(np.asarray(mesh.faces), avatar.indices.astype(np.int64))
    # a person-sized figure in metres, standing on the floor
    lo, hi = mesh.bounds
    assert -0.05 < lo[1] < 0.05 and 1.5 < hi[1] < 2.0
