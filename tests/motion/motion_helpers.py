"""Shared helpers for the motion tests (imported by name; pytest puts this folder on sys.path)."""
from __future__ import annotations

from pathlib import Path

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"  # copies of ../shared/samples (see its README)
BEAT_SAMPLE = SAMPLES / "beat75_diffsheg_output_excerpt.bvh"
MIXAMO_SAMPLE = SAMPLES / "mixamo_test_freebvh_excerpt.bvh"
PYBVH_SAMPLE = SAMPLES / "pybvh_test1_zyx_excerpt.bvh"
ALL_SAMPLES = (BEAT_SAMPLE, MIXAMO_SAMPLE, PYBVH_SAMPLE)

SMALL_BVH = """HIERARCHY
ROOT Hips
{
\tOFFSET 0.0 90.0 0.0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Spine
\t{
\t\tOFFSET 0.0 10.0 0.0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0.0 80.0 0.0
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.0333333
1.0 90.0 2.0 10.0 20.0 30.0 5.0 6.0 7.0
1.5 91.0 2.5 11.0 21.0 31.0 8.0 9.0 10.0
"""


def write(tmp_path: Path, text: str, name: str = "m.bvh") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def scipy_fk(motion):
    """World rotations ``(F, J, 3, 3)`` and positions ``(F, J, 3)`` of a Motion, joint by joint with scipy:
    forward kinematics written apart from ``studyapp.motion.fk``, for tests to check it against."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    sk = motion.skeleton
    f, j = motion.rotations.shape[:2]
    rot = np.empty((f, j, 3, 3))
    pos = np.empty((f, j, 3))
    for k in range(j):
        local = Rotation.from_quat(motion.rotations[:, k].reshape(-1, 4)).as_matrix()
        p = int(sk.parents[k])
        if p < 0:
            rot[:, k], pos[:, k] = local, motion.translations[:, k]
        else:
            rot[:, k] = rot[:, p] @ local
            pos[:, k] = pos[:, p] + np.einsum("fij,fj->fi", rot[:, p], motion.translations[:, k])
    return rot, pos
