"""One entry point for reading motion files, dispatching on the extension.

``.bvh`` -> :func:`~studyapp.motion.bvh.read_bvh`; ``.npz`` written by studyapp ->
:func:`~studyapp.motion.arrays.load_motion_npz`; SMPL, SMPL-H and SMPL-X files (recognised by their keys and
shapes) -> :func:`~studyapp.motion.smpl.load_smpl_motion`; other ``.npz`` / ``.npy`` (model output arrays) ->
:func:`~studyapp.motion.arrays.load_rotation_array`, which needs a template skeleton, a
representation and the frame rate.

>>> unit_name(0.01), unit_name(None)
('cm', 'unknown')
"""
from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from studyapp.errors import InputError
from studyapp.motion.skeleton import Motion

__all__ = ["MOTION_EXTENSIONS", "load_motion", "summarize_motion", "unit_name"]

MOTION_EXTENSIONS = (".bvh", ".npz", ".npy")


def unit_name(unit_scale: float | None) -> str:
    """Human name of a metres-per-unit factor (``0.01`` -> ``"cm"``)."""
    if unit_scale is None:
        return "unknown"
    for value, name in ((1.0, "m"), (0.01, "cm"), (0.001, "mm"), (0.0254, "inch")):
        if abs(unit_scale - value) <= 1e-9:
            return name
    return f"{unit_scale:g} m"


def load_motion(
    path: str | Path,
    fps: float | None = None,
    template: Any = None,
    representation: str | None = None,
    body_model: str | Path | None = None,
    **kw: Any,
) -> Motion:
    """Read a motion file of any supported format.

    ``fps`` overrides a BVH's (or SMPL file's) frame rate and is required for raw arrays. ``body_model`` is a
    user's SMPL-family model ``.npz`` giving an SMPL file its rest joints (else built-in proportions). ``template`` and
    ``representation`` (and ``joints=``, ``order=``, ``key=``, ``root_key=``) are for raw rotation
    arrays; see :func:`~studyapp.motion.arrays.load_rotation_array`.
    """
    p = Path(path)
    ext = p.suffix.lower()
    if not p.exists():
        raise InputError(str(path), None, "file not found")
    if ext == ".bvh":
        from studyapp.motion.bvh import read_bvh

        return read_bvh(p, fps=fps)
    if ext in (".npz", ".npy"):
        from studyapp.motion.arrays import check_numpy_file, is_motion_npz, load_motion_npz, load_rotation_array

        check_numpy_file(p)
        if ext == ".npz" and is_motion_npz(p) and template is None:
            return load_motion_npz(p, fps=fps)
        from studyapp.motion.smpl import FAMILY_NAMES, load_smpl_motion, recognise_smpl

        family = recognise_smpl(p)
        if family is not None:
            if template is not None or representation is not None:
                # read as a raw array it would fail on a joint count ("55 joints ... 75 mapped"), hiding the cause
                raise InputError(str(path), None, f"an {FAMILY_NAMES[family]} file carries its own skeleton, rotation "
                                                  "layout and frame rate: drop the template and representation")
            return load_smpl_motion(p, fps=fps, body_model=body_model)
        if template is None or representation is None:
            raise InputError(
                str(path), None,
                "a rotation array needs a template skeleton and a representation "
                "(e.g. --template beat --representation axis_angle)",
            )
        if fps is None:
            raise InputError(str(path), None, "a rotation array carries no frame rate; pass fps")
        return load_rotation_array(p, template, representation, fps, **kw)
    raise InputError(str(path), None, f"unsupported motion format {ext or '(no extension)'}; expected one of {', '.join(MOTION_EXTENSIONS)}")


#: Said whenever an array could hold 6D rotations: the two layouts cannot be told apart from the numbers
#: (each joint's six numbers read the other way are its inverse rotation, just as valid), so only the
#: model's own code can say which one it wrote.
SIXD_LAYOUT_NOTE = (
    "if this array holds 6D rotations, its layout cannot be read from the numbers: --representation sixd "
    "reads Zhou's first two matrix columns [R00,R10,R20,R01,R11,R21], sixd_rows the first two rows "
    "[R00,R01,R02,R10,R11,R12] (PyTorch3D matrix_to_rotation_6d, EMAGE/BEAT-derived code); "
    "check how the model flattens it"
)


def _array_facts(a: np.ndarray) -> dict[str, Any]:
    """Shape, dtype and the representations whose per-joint width fits the shape (numeric arrays)."""
    from studyapp.motion.arrays import fitting_representations

    fits = fitting_representations(a.shape) if np.issubdtype(a.dtype, np.number) else []
    return {"shape": list(a.shape), "dtype": str(a.dtype), "fits": fits}


def summarize_motion(path: str | Path, fps: float | None = None) -> dict[str, Any]:
    """Facts about a motion file for ``studyapp inspect`` (JSON-serialisable).

    Keys: ``path``, ``format``, ``joints``, ``root``, ``frames``, ``fps``, ``duration_s``,
    ``rotation_orders`` (order -> joint count), ``position_channels`` (joints with them),
    ``channels``, ``figure_height`` (file units, first frame), ``unit_scale``, ``unit_guess``,
    ``height_m`` (when the unit is known), ``warnings``. A raw rotation array (no skeleton) gives
    ``format``, ``arrays`` (name -> shape, dtype, ``fits``: the representations whose per-joint width
    fits the shape) and ``warnings`` (with :data:`SIXD_LAYOUT_NOTE` when a 6D reading fits).
    """
    from studyapp.motion.fk import figure_height

    p = Path(path)
    ext = p.suffix.lower()
    out: dict[str, Any] = {"path": str(path)}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if ext == ".bvh":
            from studyapp.motion.bvh import read_bvh_channels

            data = read_bvh_channels(p)
            motion = data.to_motion(fps)
            out["format"] = "bvh"
            out["header_frame_time"] = data.frame_time
            out["header_frames"] = data.header_frames
        elif ext in (".npz", ".npy"):
            from studyapp.motion.arrays import check_numpy_file, is_motion_npz

            check_numpy_file(p)
            from studyapp.motion.smpl import read_smpl, recognise_smpl, smpl_motion, summarize_smpl

            if ext == ".npz" and is_motion_npz(p):
                motion = load_motion(p, fps=fps)
                out["format"] = "npz (studyapp motion)"
            elif recognise_smpl(p) is not None:
                data = read_smpl(p, fps=fps)
                motion = smpl_motion(data)
                smpl = summarize_smpl(data)
                out["format"] = f"{ext[1:]} ({smpl['family']}, {smpl.pop('layout')})"
                out["rest_skeleton"] = "built-in average adult, unless the condition names a body_model"
                for note in smpl.pop("notes"):
                    warnings.warn(note)
                out.update(smpl)
            else:
                from studyapp.safe_io import load_numpy

                loaded = load_numpy(p)
                if isinstance(loaded, np.ndarray):
                    arrays = {"array": loaded}
                else:
                    with loaded:
                        arrays = {k: loaded[k] for k in loaded.keys()}
                out["format"] = f"{ext[1:]} (rotation array; needs a template to become a motion)"
                out["arrays"] = {k: _array_facts(v) for k, v in arrays.items()}
                out["warnings"] = [str(w.message) for w in caught]
                if any("sixd" in a["fits"] for a in out["arrays"].values()):
                    out["warnings"].append(SIXD_LAYOUT_NOTE)
                return out
        else:
            motion = load_motion(p, fps=fps)
    sk = motion.skeleton
    orders: dict[str, int] = {}
    for j in range(sk.n_joints):
        o = sk.rotation_order(j)
        if o:
            orders[o] = orders.get(o, 0) + 1
    height = figure_height(motion)
    out.update(
        joints=sk.n_joints,
        root=sk.names[int(np.flatnonzero(sk.parents < 0)[0])],
        frames=motion.n_frames,
        fps=float(motion.fps),
        duration_s=float(motion.duration),
        rotation_orders=orders,
        position_channels=[sk.names[j] for j in range(sk.n_joints) if sk.has_position_channels(j)],
        channels=int(sum(len(c) for c in sk.channels)),
        end_sites=len(sk.end_sites),
        figure_height=round(height, 4),
        unit_scale=sk.unit_scale,
        unit_guess=unit_name(sk.unit_scale),
        height_m=None if sk.unit_scale is None else round(height * sk.unit_scale, 4),
        warnings=[str(w.message) for w in caught],
    )
    rig = _rig_facts(motion, str(path))
    out["warnings"] = out["warnings"] + rig.pop("warnings", [])
    out.update(rig)
    return out


def _rig_facts(motion: Motion, path: str) -> dict[str, Any]:
    """What retargeting will make of this skeleton: the rig recognised, bone by bone, and what is missing."""
    from studyapp.motion.bone_frames import is_standing
    from studyapp.motion.fk import rest_joint_positions
    from studyapp.motion.humanoid import HUMANOID_BONES, REQUIRED_BONES
    from studyapp.motion.rigs import recognise_rig

    rig, mapping = recognise_rig(motion.skeleton)
    by_bone = {b: j for j, b in mapping.items()}
    facts: dict[str, Any] = {"rig": rig, "humanoid_map": {b: by_bone[b] for b in HUMANOID_BONES if b in by_bone}}
    missing = [b for b in REQUIRED_BONES if b not in by_bone]
    facts["missing_bones"] = missing
    if missing:
        facts["warnings"] = [f"no joint found for the humanoid bones {', '.join(missing)}: a study needs a name_map "
                             f"for this rig (`studyapp inspect {path} --name-map-template` writes one to fill in)"]
    else:
        standing = is_standing(rest_joint_positions(motion.skeleton), {b: motion.skeleton.index(j)
                                                                       for b, j in by_bone.items()})
        facts["zero_pose"] = ("standing (its rest orientations are used)" if standing else
                              "not a standing figure (bone twist is read from the animation)")
    return facts
