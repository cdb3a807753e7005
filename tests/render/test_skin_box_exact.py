"""The framing box from two points per joint and frame (a moved box's exact extent) is the box of its eight
moved corners, computed here independently, on a real retargeted clip."""
from __future__ import annotations

import numpy as np

from fixtures.synthetic import bvh_text
from studyapp.render import scene as S
from studyapp.render.avatar import build_default_avatar
from studyapp.render.camera import framing_box
from studyapp.render.pose import prepare_slot


def test_skin_box_equals_the_box_of_every_moved_corner(tmp_path) -> None:
    avatar = build_default_avatar()
    path = tmp_path / "clip.bvh"
    path.write_text(bvh_text(np.linspace(-70.0, 80.0, 90)))  # arms swing through the box
    from studyapp.motion.io import load_motion

    slot = prepare_slot(avatar, load_motion(path), None)
    legs, hands, hips = S._joint_sets(avatar)
    corners = S._skin_corners(avatar)
    idx = np.unique(np.linspace(0, slot.n_frames - 1, min(slot.n_frames, S.FRAMING_SAMPLES)).round().astype(int))
    pal = slot.palettes[idx].astype(np.float64)
    every = np.einsum("fjab,jkb->fjka", pal[:, :, :3], corners)  # all eight corners moved
    rest_hips_y = float(np.linalg.inv(avatar.inverse_bind[hips].astype(np.float64))[1, 3])
    for framing in ("upper-body", "full-body"):
        want = framing_box(framing, every, legs, rest_hips_y, avatar.bounds())
        got = S._skin_box([slot], avatar, framing)
        np.testing.assert_allclose(got[0], want[0], atol=1e-9)
        np.testing.assert_allclose(got[1], want[1], atol=1e-9)
