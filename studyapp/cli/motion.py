"""``studyapp inspect`` and ``studyapp convert``.

inspect PATH [--fps F] [--json] [--name-map-template]
    Summary of a motion (BVH / NPZ / NPY), a face file (JSON / CSV, an NPZ with ``weights`` and
    ``names``, a bare ``(F, 52)`` NPY when ``--fps`` is given), a WAV or an avatar (GLB / glTF / VRM: see
    :mod:`studyapp.render.avatar_report`). For a raw rotation array it
    lists the representations whose width fits each array's shape and, when a 6D reading fits, says
    that ``sixd`` (columns) and ``sixd_rows`` (rows) cannot be told apart from the numbers. For a
    skeleton it shows the rig recognised and its humanoid map; ``--name-map-template`` prints the
    ``[conditions.name_map]`` table to complete when bones are missing.
convert IN OUT [--fps F] [--in-fps F] [--order XYZ] [--template T] [--representation R] ...
    BVH -> BVH (new rotation order and/or frame rate), NPZ/NPY rotation arrays -> BVH or NPZ (needs
    ``--template``), BVH -> NPZ (studyapp motion NPZ with world joint positions). ``--avatar builtin|FILE``
    writes the motion as it plays on that avatar (humanoid bone names, zero pose = the avatar's rest).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from pathlib import Path
from typing import Any

from studyapp.errors import InputError
# the motion package (numpy included) is already imported by the time this module loads
from studyapp.motion.rotations import REPRESENTATIONS

_FACE_EXT = (".json", ".csv")
_AUDIO_EXT = (".wav",)
_AVATAR_EXT = (".glb", ".gltf", ".vrm")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "inspect",
        help="summarize a motion, face, audio or avatar file",
        description="Print what studyapp reads from a BVH/NPZ/NPY motion, a face JSON/CSV/NPZ/NPY, a WAV file "
                    "or a GLB/glTF/VRM avatar (joints, humanoid bones, ARKit morph targets, facing, extensions).",
    )
    p.add_argument("path", help="file to inspect")
    p.add_argument("--fps", type=float, default=None, help="true frame rate (overrides a BVH header's Frame Time)")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    p.add_argument("--name-map-template", action="store_true",
                   help="print a [conditions.name_map] TOML table for a motion file's skeleton: the bones found "
                        "filled in, every other joint as a comment to complete")
    p.set_defaults(func=cmd_inspect)

    c = subparsers.add_parser(
        "convert",
        help="convert motion between BVH and NPZ/NPY, rotation orders and frame rates",
        description=(
            "Convert a motion file. BVH -> BVH (--order, --fps), rotation arrays (.npz/.npy) -> BVH or NPZ "
            "(--template, --representation, --in-fps), BVH -> NPZ. SMPL, SMPL-H and SMPL-X files need no "
            "options (--body-model gives their rest skeleton); an SMPL-X file -> CSV writes its face (jawOpen "
            "from the jaw, FLAME expressions with --flame-map) as an ARKit CSV for a stimulus's face."
        ),
    )
    c.add_argument("input", help="source file (.bvh, .npz, .npy)")
    c.add_argument("output", help="destination file (.bvh or .npz; .csv for an SMPL-X file's face)")
    c.add_argument("--fps", type=float, default=None, help="frame rate of the output (the motion is resampled)")
    c.add_argument(
        "--in-fps", type=float, default=None,
        help="true frame rate of the input (overrides a BVH header; for arrays defaults to --fps)",
    )
    c.add_argument("--order", default=None, help="rotation order of every joint in an output BVH, e.g. ZXY")
    c.add_argument("--template", default=None, help="skeleton for rotation arrays: a BVH/NPZ file or 'beat'")
    c.add_argument(
        "--representation", default=None, choices=list(REPRESENTATIONS),
        help="rotation representation of an array input. 6D has two layouts the numbers cannot tell apart: "
             "sixd = Zhou et al. first two columns [R00,R10,R20,R01,R11,R21]; sixd_rows = first two rows "
             "[R00,R01,R02,R10,R11,R12] (PyTorch3D matrix_to_rotation_6d, EMAGE/BEAT-derived code)",
    )
    c.add_argument("--joints", default=None, help="comma-separated template joints the array columns map to")
    c.add_argument("--in-order", default=None, help="Euler order of an 'euler' array (default: template's per joint)")
    c.add_argument("--key", default=None, help="NPZ array name holding the rotations")
    c.add_argument("--root-key", default=None, help="NPZ array name holding the (F, 3) root translation")
    c.add_argument("--radians", action="store_true", help="Euler array angles are radians, not degrees")
    c.add_argument("--precision", type=int, default=6, help="decimals written to BVH (default 6)")
    c.add_argument("--avatar", default=None,
                   help="write the motion as it plays on this avatar ('builtin' or a glTF/GLB/VRM file): retargeted "
                        "onto its skeleton, humanoid bone names, Y up, zero pose = the avatar's rest pose facing +Z")
    c.add_argument("--body-model", default=None,
                   help="your SMPL/SMPL-H/SMPL-X model .npz: the rest skeleton of an SMPL-family input")
    c.add_argument("--flame-map", default=None,
                   help="(E, 52) .npy mapping an SMPL-X file's FLAME expressions to ARKit shapes (CSV output)")
    c.set_defaults(func=cmd_convert)


def smplx_face_of(path: str | Path, fps: float | None = None, flame_map: str | None = None) -> Any:
    """The face an SMPL-X motion file carries (:func:`studyapp.face.smplx.smplx_face`), or ``None`` for any
    other file (SMPL and SMPL-H have no jaw)."""
    from studyapp.face.smplx import load_flame_map, smplx_face
    from studyapp.motion.smpl import read_smpl, recognise_smpl

    if Path(path).suffix.lower() not in (".npz", ".npy") or recognise_smpl(path) != "smplx":
        if flame_map is not None:
            raise InputError(str(path), None, "--flame-map applies to SMPL-X files only; this is not one")
        return None
    data = read_smpl(path, fps=fps)
    mapping = None
    if flame_map is not None:
        if data.expressions is None:
            raise InputError(str(path), "keys", "no FLAME expressions in this file for --flame-map to map")
        mapping = load_flame_map(flame_map, data.expressions.shape[1])
    return smplx_face(data.jaw, data.fps, data.expressions, mapping, source=str(path))


# ---------------------------------------------------------------------------------------------


_MOTION_EXT = {".bvh", ".npz", ".npy"}


def summarize_any(path: str, fps: float | None = None) -> dict[str, Any]:
    """Summary dict of a motion, face or audio file (chosen by extension)."""
    p = Path(path)
    if not p.exists():
        raise InputError(path, None, "file not found")
    ext = p.suffix.lower()
    if ext in _FACE_EXT:
        from studyapp.face.io import summarize as face_summarize

        return {"kind": "face", **(face_summarize(path) if fps is None else face_summarize(path, fps=fps))}
    if ext in _AUDIO_EXT:
        from studyapp.audio.wav import summarize as wav_summarize

        return {"kind": "audio", **wav_summarize(path)}
    if ext in _AVATAR_EXT:
        from studyapp.render.avatar_report import summarize_avatar

        return {"kind": "avatar", **summarize_avatar(path)}
    if ext in (".npz", ".npy") and _looks_like_face_array(p, fps):
        from studyapp.face.io import summarize as face_summarize

        return {"kind": "face", **face_summarize(path, fps=fps)}
    if ext not in _MOTION_EXT:
        known = ", ".join(sorted(_MOTION_EXT | set(_FACE_EXT) | set(_AUDIO_EXT) | set(_AVATAR_EXT)))
        raise InputError(path, None, f"inspect does not know {ext or 'files without an extension'}; it reads "
                                     f"motion, face, audio and avatar files ({known})")
    from studyapp.motion.io import summarize_motion

    summary = {"kind": "motion", **summarize_motion(path, fps=fps)}
    from studyapp.face.arkit import N_ARKIT

    if ext == ".npy" and fps is None and _npy_width(p) == N_ARKIT:
        # a bare face NPY carries no frame rate, so it cannot be told from a rotation array without one
        summary.setdefault("warnings", []).append(
            f"{N_ARKIT} columns: if these are ARKit blendshape weights (Apple order), pass --fps to read it as face data"
        )
    return summary


def _npy_width(path: Path) -> int | None:
    """Column count of a 2-D numeric ``.npy`` (header only; ``None`` for anything else)."""
    from studyapp.errors import InputError
    from studyapp.safe_io import npy_header

    try:
        h = npy_header(path)
    except InputError:
        return None
    if len(h.shape) != 2 or h.dtype.kind not in "biuf":
        return None
    return int(h.shape[1])


def _looks_like_face_array(path: Path, fps: float | None) -> bool:
    """Whether an ``.npz`` / ``.npy`` holds blendshape weights rather than joint rotations.

    Face NPZ files name their columns (``weights`` + ``names``), so they are recognised by their keys;
    a bare ``(F, 52)`` NPY is face data only when the caller gives the frame rate it lacks.
    """
    from studyapp.errors import InputError
    from studyapp.face.arkit import N_ARKIT
    from studyapp.safe_io import open_npz

    if path.suffix.lower() == ".npy":
        return fps is not None and _npy_width(path) == N_ARKIT
    try:
        with open_npz(path) as z:
            keys = set(z.files)
    except InputError:
        return False
    return {"weights", "names"} <= keys and "rotations" not in keys


def _text(value: Any, nested: bool = False) -> str:
    if nested and isinstance(value, dict):
        return "(" + ", ".join(f"{k} {_text(v, True)}" for k, v in value.items()) + ")"
    if nested and isinstance(value, (list, tuple)):
        return "[" + ", ".join(_text(v, True) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.6g}" if math.isfinite(value) else str(value)
    if isinstance(value, dict):
        return ", ".join(f"{k}: {_text(v, True)}" for k, v in value.items()) or "-"
    if isinstance(value, (list, tuple)):
        if len(value) > 12:
            return ", ".join(_text(v) for v in value[:12]) + f", ... ({len(value)} in all)"
        return ", ".join(_text(v) for v in value) or "-"
    if value is None:
        return "-"
    return str(value)


def format_summary(summary: dict[str, Any]) -> str:
    """Human-readable ``key: value`` lines; warnings last, one per line."""
    lines = []
    width = max((len(k) for k in summary), default=0)
    for key, value in summary.items():
        if key == "warnings":
            continue
        lines.append(f"{key.replace('_', ' '):<{width}}  {_text(value)}")
    for w in summary.get("warnings") or []:
        lines.append(f"warning: {w}")
    return "\n".join(lines)


def cmd_inspect(args: argparse.Namespace) -> int:
    if args.name_map_template:
        from studyapp.motion.io import load_motion
        from studyapp.motion.rigs import name_map_template

        if Path(args.path).suffix.lower() != ".bvh":
            raise InputError(args.path, None, "--name-map-template reads a BVH file's skeleton (for an array, "
                                              "give its template BVH)")
        print(name_map_template(load_motion(args.path, fps=args.fps).skeleton, Path(args.path).name), end="")
        return 0
    summary = summarize_any(args.path, fps=args.fps)
    if args.json:
        print(json.dumps(summary, indent=2, default=str))
    else:
        print(format_summary(summary))
    return 0


_TEMPLATE_KINDS = "--template takes a BVH file, a studyapp motion .npz or 'beat'"


def load_template(name: str) -> Any:
    """The skeleton ``--template`` names, read now: ``"beat"``, or the :class:`Motion` of a BVH file or
    studyapp motion NPZ. A missing, unreadable or wrong kind of file is one :class:`InputError` naming the
    template path (and the line, for a broken BVH) and what is wrong with it."""
    if name.strip().lower() == "beat":
        return "beat"
    from studyapp.motion.arrays import is_motion_npz, load_motion_npz
    from studyapp.motion.bvh import read_bvh

    path = Path(name)
    ext = path.suffix.lower()
    if not path.exists():
        raise InputError(name, None, f"template file not found; {_TEMPLATE_KINDS}")
    if path.is_dir():
        raise InputError(name, None, f"template is a folder, not a BVH file; {_TEMPLATE_KINDS}")
    try:
        if ext == ".bvh":
            return read_bvh(path)
        if ext == ".npz" and is_motion_npz(path):
            return load_motion_npz(path)
    except InputError as exc:
        kind = "BVH file" if ext == ".bvh" else "studyapp motion .npz"
        raise InputError(exc.path or name, exc.where, f"template is not a readable {kind}: {exc.problem}") from None
    except OSError as exc:
        raise InputError(name, None, f"template cannot be read ({exc.strerror or exc})") from None
    if ext == ".npy":
        what = "a .npy array, which holds no skeleton"
    elif ext == ".npz":
        what = "not a studyapp motion .npz (no skeleton in it, or not a readable NPZ)"
    else:
        what = f"not a BVH file ({ext or 'no extension'})"
    raise InputError(name, None, f"template is {what}; {_TEMPLATE_KINDS}")


def _check_fps(value: float | None, option: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise InputError(None, option, f"frame rate must be a positive number, got {value:g}")


def cmd_convert(args: argparse.Namespace) -> int:
    _check_fps(args.fps, "--fps")
    _check_fps(args.in_fps, "--in-fps")
    src, dst = Path(args.input), Path(args.output)
    out_ext = dst.suffix.lower()
    if out_ext not in (".bvh", ".npz", ".csv"):
        raise InputError(str(dst), None, f"cannot write {out_ext or 'files without extension'}; use .bvh or .npz "
                                         "(.csv for an SMPL-X file's face)")
    if args.order is not None and out_ext != ".bvh":
        raise InputError(str(dst), None, "--order only applies to BVH output")
    # tolerated oddities (a header frame count that disagrees, an unused root array) are reported as
    # "warning:" lines like inspect's, not as Python warnings pointing into studyapp's source
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UserWarning)
            return _convert(args, src, dst, out_ext)
    finally:
        for w in caught:
            if issubclass(w.category, UserWarning):
                print(f"warning: {w.message}", file=sys.stderr)
            else:
                warnings.showwarning(w.message, w.category, w.filename, w.lineno)


def _on_avatar(motion: Any, spec: str) -> Any:
    """The motion as the study plays it on an avatar (the same retargeting and placement), its zero pose
    the avatar's rest pose and its joints named as humanoid bones, ready to check in Blender."""
    from studyapp.motion.rest_frame import humanoid_names, zero_at_rest
    from studyapp.motion.rigs import merge_name_map
    from studyapp.render.pose import to_avatar_skeleton
    from studyapp.render.scene import load_avatar

    avatar = load_avatar(spec)
    played = to_avatar_skeleton(avatar, motion)
    mapping = merge_name_map(avatar.skeleton, getattr(avatar, "bone_map", None) or None)
    return humanoid_names(zero_at_rest(played), mapping)


def _convert(args: argparse.Namespace, src: Path, dst: Path, out_ext: str) -> int:
    from studyapp.motion.arrays import save_motion_npz
    from studyapp.motion.bvh import write_bvh
    from studyapp.motion.io import load_motion
    from studyapp.motion.resample import resample

    if out_ext == ".csv":
        return _convert_face(args, src, dst)
    in_ext = src.suffix.lower()
    kw: dict[str, Any] = {}
    in_fps = args.in_fps
    template = load_template(args.template) if args.template is not None else None
    if in_ext in (".npy", ".npz") and template is not None:
        in_fps = in_fps if in_fps is not None else args.fps
        kw.update(
            joints=[j.strip() for j in args.joints.split(",")] if args.joints else None,
            order=args.in_order,
            key=args.key,
            root_key=args.root_key,
            degrees=not args.radians,
        )
    if args.body_model is not None:
        kw["body_model"] = args.body_model
    motion = load_motion(src, fps=in_fps, template=template, representation=args.representation, **kw)
    if args.fps is not None and float(args.fps) != float(motion.fps):
        motion = resample(motion, args.fps)
    if args.avatar is not None:
        motion = _on_avatar(motion, args.avatar)
    if out_ext == ".bvh":
        order = args.order.upper() if args.order else None
        if order is not None and (len(order) != 3 or set(order) != set("XYZ")):
            raise InputError(None, "--order", f"rotation order must be a permutation of XYZ, got {args.order!r}")
        write_bvh(motion, dst, order=order, precision=args.precision)
    else:
        save_motion_npz(motion, dst)
    print(f"wrote {dst} ({motion.n_frames} frames at {motion.fps:g} fps, {motion.skeleton.n_joints} joints)")
    return 0


def _convert_face(args: argparse.Namespace, src: Path, dst: Path) -> int:
    """An SMPL-X file's face as an ARKit CSV (``time`` column and the 52 shapes) a stimulus can name as its face."""
    from studyapp.face.io import save_face_csv

    face = smplx_face_of(src, fps=args.in_fps, flame_map=args.flame_map)
    if face is None:
        raise InputError(str(src), None, "only an SMPL-X file's face can be written as CSV (its jaw drives jawOpen); "
                                         "write motion to .bvh or .npz")
    if args.fps is not None:
        face = face.resample(args.fps)
    save_face_csv(face, dst)
    print(f"wrote {dst} ({face.n_frames} frames at {face.fps:g} fps, jawOpen up to "
          f"{float(face.weight('jawOpen').max()):.2f})")
    return 0
