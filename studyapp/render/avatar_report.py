"""What ``studyapp inspect`` says about a glTF/GLB/VRM avatar: enough to write its ``[avatar.bone_map]``.

The report lists the joints, the humanoid bones recognised (and those still missing), the morph targets and
how many of the 52 ARKit shapes they cover, which way the figure faced in the file (it is turned to face the
camera when shown), the extensions the file uses, and every problem, each with what to do.

>>> import tempfile, pathlib
>>> from studyapp.render.avatar import build_default_avatar
>>> from studyapp.render.gltf import export_glb
>>> path = export_glb(build_default_avatar(), pathlib.Path(tempfile.mkdtemp()) / "builtin.glb")
>>> r = summarize_avatar(path)
>>> r["format"], r["arkit_coverage"], r["facing_in_file"], r["humanoid_missing"], r["problems"]
('GLB', '52/52', '+Z', [], [])
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from studyapp.errors import InputError

#: Prefix of the loader's note when it turned the figure (see :func:`studyapp.render.gltf.load_gltf`).
_TURNED = "faced "
_NOT_MEASURED = "facing not measured"


def _file_format(gltf: dict, path: Path) -> str:
    ext = gltf.get("extensions")
    ext = ext if isinstance(ext, dict) else {}
    if "VRMC_vrm" in ext:
        return "VRM 1.0"
    if "VRM" in ext:
        return "VRM 0.x"
    return "glTF" if path.suffix.lower() == ".gltf" else "GLB"


def _names(gltf: dict, key: str) -> list[str]:
    """A list of extension names, sorted; the strings only (a file that failed to load may hold anything)."""
    value = gltf.get(key)
    return sorted(x for x in value if isinstance(x, str)) if isinstance(value, list) else []


def _target_names(gltf: dict) -> list[str]:
    names: list[str] = []
    for mesh in gltf.get("meshes", []):
        mesh_names = list(mesh.get("extras", {}).get("targetNames", []))
        for prim in mesh.get("primitives", []):
            here = list(prim.get("extras", {}).get("targetNames", mesh_names))
            for i in range(len(prim.get("targets", []))):
                name = here[i] if i < len(here) else f"target{i}"
                if name not in names:
                    names.append(name)
    return names


def summarize_avatar(path: str | Path, bone_map: dict[str, str] | None = None) -> dict[str, Any]:
    """A report dict of an avatar file (keys in the order ``inspect`` prints them).

    Raises :class:`InputError` only when the file is not glTF at all; anything else wrong is listed
    under ``problems`` so the rest of the report still helps.
    """
    from studyapp.face.arkit import ARKIT_NAMES, match_arkit_name
    from studyapp.motion.humanoid import HUMANOID_BONES, REQUIRED_BONES
    from studyapp.render.avatar_rig import (BONE_MAP_FIX, bone_map_problems, humanoid_map, not_humanoid_message,
                                            not_upright_problem)
    from studyapp.render.gltf import _Doc, load_gltf

    path = Path(path)
    gltf = _Doc(path, check=False).gltf  # raises only when the file is not glTF at all
    report: dict[str, Any] = {"file": str(path), "format": _file_format(gltf, path)}
    problems: list[str] = []
    try:
        avatar = load_gltf(path, bone_map=bone_map)
    except InputError as exc:
        report["extensions_used"] = _names(gltf, "extensionsUsed")
        report["extensions_required"] = _names(gltf, "extensionsRequired")
        report["problems"] = [f"{exc.where}: {exc.problem}" if exc.where else exc.problem]
        return report
    sk = avatar.skeleton
    report["vertices"] = avatar.n_vertices
    report["triangles"] = avatar.n_triangles
    report["skins"] = len(gltf.get("skins", []))
    report["joint_count"] = sk.n_joints
    # one string, not a list: every name is needed to write a bone map, so none is cut off
    report["joints"] = ", ".join(sk.names)
    mapping = humanoid_map(sk, avatar.bone_map)
    by_bone = {b: j for j, b in mapping.items()}
    # a VRM's joints carry humanoid names; show the node's own name beside it (bone maps accept either)
    own = {joint: node for node, joint in avatar.joint_aliases.items()}
    report["humanoid_map"] = {b: by_bone[b] + (f" ({own[by_bone[b]]})" if by_bone[b] in own else "")
                              for b in HUMANOID_BONES if b in by_bone}
    missing = [b for b in REQUIRED_BONES if b not in by_bone]
    report["humanoid_missing"] = missing
    vrm_found = "VRM" in report["format"] and not avatar.bone_map
    report["humanoid_from"] = ("the file's VRM humanoid" if vrm_found else
                               "recognised names" + (" and the bone map" if avatar.bone_map else ""))
    for joint, problem in bone_map_problems(sk.names, bone_map or {}, avatar.joint_aliases):
        problems.append(f"[avatar.bone_map] {joint}: {problem}; {BONE_MAP_FIX}")
    if (upright := not_upright_problem(sk, avatar.bone_map)) is not None:
        problems.append(upright)
    elif missing:
        problems.append(not_humanoid_message(sk, missing))
    targets = _target_names(gltf)
    arkit = {match_arkit_name(t) for t in targets} - {None}
    report["morph_targets"] = targets
    from studyapp.render.gltf import _vrm_arkit_expressions

    by_expression = {a for binds in _vrm_arkit_expressions(gltf, gltf.get("nodes", [])).values() for a, _ in binds}
    if by_expression - arkit:
        report["arkit_from_vrm_expressions"] = sorted(by_expression - arkit, key=ARKIT_NAMES.index)
    arkit |= by_expression
    report["arkit_coverage"] = f"{len(arkit)}/{len(ARKIT_NAMES)}"
    if arkit and len(arkit) < len(ARKIT_NAMES):
        report["arkit_missing"] = [n for n in ARKIT_NAMES if n not in arkit]
    if not arkit:
        problems.append("no ARKit morph targets: the face will not animate (name them as ARKit does, "
                        "e.g. jawOpen, eyeBlinkLeft; prefixes and any case are fine)")
    turned = next((n for n in avatar.notes if n.startswith(_TURNED)), None)
    if turned is not None:
        report["facing_in_file"] = turned.split()[1]
        report["facing_shown"] = "+Z (turned at load)"
    elif any(n.startswith(_NOT_MEASURED) for n in avatar.notes):
        report["facing_in_file"] = "not measured (no left/right pair of humanoid bones); shown as stored"
    else:
        report["facing_in_file"] = "+Z"
    report["extensions_used"] = sorted(gltf.get("extensionsUsed", []))
    report["extensions_required"] = sorted(gltf.get("extensionsRequired", []))
    said = (_TURNED, _NOT_MEASURED, "no ARKit", "[avatar.bone_map]")  # reported above, not again as notes
    report["notes"] = [n for n in avatar.notes if not n.startswith(said)]
    report["problems"] = problems
    return report
