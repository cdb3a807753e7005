"""One motion file read as a design condition reads it (``studyapp view``).

``view`` takes every setting a ``[[conditions]]`` table has (name map, template, representation, fps,
rotation order, joints, degrees) and the avatar. They become a :class:`~studyapp.study.design.Condition`
through the design's own checks (:func:`~studyapp.study.design.condition_from_settings`) and the motion is
loaded by the study's own :func:`~studyapp.study.stimuli.load_condition_motion`, so a setting means in
``view`` exactly what it means in a design, and what ``view`` shows is what a participant would see.

A name map comes as ``JOINT=BONE`` pairs or as a TOML file: the ``[conditions.name_map]`` table that
``studyapp inspect FILE --name-map-template`` writes, a ``[name_map]`` table, or plain ``JOINT = "BONE"``
lines.

>>> parse_name_map(["lShldr=LeftUpperArm", "rShldr = RightUpperArm"])
{'lShldr': 'LeftUpperArm', 'rShldr': 'RightUpperArm'}
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from studyapp import tomlfile
from studyapp.errors import InputError
from studyapp.motion.skeleton import Motion
from studyapp.study.design import Condition, Design, Stimulus, condition_from_settings


def parse_name_map(items: list[str] | None) -> dict[str, str]:
    """Source joint -> humanoid bone from ``--name-map`` values (``JOINT=BONE`` pairs or TOML files)."""
    out: dict[str, str] = {}
    for item in items or []:
        path = Path(item)
        if path.suffix.lower() == ".toml" or ("=" not in item and path.exists()):
            out.update(_name_map_file(path))
            continue
        joint, sep, bone = item.partition("=")
        if not sep or not joint.strip() or not bone.strip():
            raise InputError(None, "--name-map", f"{item!r} is neither JOINT=BONE (e.g. lShldr=LeftUpperArm) "
                             "nor a TOML file with a [name_map] table")
        out[joint.strip()] = bone.strip()
    return out


def _name_map_file(path: Path) -> dict[str, str]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(path, None, f"cannot read the name map ({exc.strerror or exc})") from None
    try:
        data = tomlfile.loads(text)
    except tomlfile.TOMLDecodeError as exc:
        raise InputError(path, None, f"not a TOML name map: {exc}") from None
    table: Any = data
    if isinstance(data.get("conditions"), dict) and "name_map" in data["conditions"]:
        table = data["conditions"]["name_map"]      # what `inspect --name-map-template` writes
    elif "name_map" in data:
        table = data["name_map"]
    if not isinstance(table, dict) or not table:
        raise InputError(path, None, "no name map in the file: write JOINT = \"BONE\" lines, under "
                         "[name_map] or [conditions.name_map]")
    bad = [k for k, v in table.items() if not isinstance(v, str)]
    if bad:
        key_line = re.compile(rf'^\s*"?{re.escape(bad[0])}"?\s*=')
        line = next((i + 1 for i, ln in enumerate(text.splitlines()) if key_line.match(ln)), None)
        raise InputError(path, f"line {line}" if line else f"key {bad[0]}",
                         f"{bad[0]!r} must map to a bone name in quotes, e.g. {bad[0]} = \"LeftHand\"")
    return dict(table)


def _cli_fix(fix: str) -> str:
    """A design-file fix hint in command-line words: ``add fps = 15`` -> ``--fps 15``."""
    return re.sub(r"\b(?:add )?([a-z_]+) = ", lambda m: f"--{m.group(1).replace('_', '-')} ", fix)


def preview_condition(motion: str | Path, **settings: Any) -> Condition:
    """The condition ``view`` reads ``motion`` with; ``settings`` are condition keys (None: not given).

    Every problem the design would report for these settings is raised as one :class:`InputError` per
    run, naming the motion file, the option and the fix.
    """
    given = {k: v for k, v in settings.items() if v is not None and v != {} and v != ()}
    if "joints" in given:
        given["joints"] = list(given["joints"])
    motion = Path(motion)
    if set(given) <= {"fps", "name_map"} and _self_describing(motion):
        # studyapp's own motion NPZ (`convert`, bundles) carries its skeleton and frame rate: no array settings
        if "fps" in given and not given["fps"] > 0:
            raise InputError(motion, "--fps", f"must be a positive frame rate, got {given['fps']}")
        return Condition(id="view", motion=str(motion), fps=given.get("fps"), name_map=dict(given.get("name_map", {})))
    cond, problems = condition_from_settings({"motion": str(motion), **given}, motion)
    if problems:
        p = problems[0]
        key = p.key.split('.')[0] if p.key else ""
        rest = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        if key == "motion":  # the file itself, given as `view`'s argument: there is no --motion option
            where, fix = None, "; fix: give a .bvh, .npz or .npy motion file (`studyapp convert` makes one)"
        else:
            where = f"--{key.replace('_', '-')}" if key else None
            fix = f"; fix: {_cli_fix(p.fix)}" if p.fix else ""
        raise InputError(motion, where, f"{p.message}{fix}{rest}")
    assert cond is not None
    return cond


def _self_describing(path: Path) -> bool:
    from studyapp.motion.arrays import is_motion_npz

    return path.suffix.lower() == ".npz" and path.is_file() and is_motion_npz(path)


def load_preview_motion(motion: str | Path, condition: Condition) -> Motion:
    """The motion of ``condition`` for the one file ``motion``, through the study's loader."""
    from studyapp.study.stimuli import load_condition_motion

    path = Path(motion).resolve()
    if not path.is_file():
        raise InputError(motion, None, "motion file not found")
    # A one-condition, one-stimulus design around the file: the loader fills the motion pattern in and
    # resolves the template against the design's folder, so both are made absolute here.
    pattern = str(path).replace("{", "{{").replace("}", "}}")
    template = str(Path(condition.template).resolve()) if condition.template else None
    body_model = str(Path(condition.body_model).resolve()) if condition.body_model else None
    cond = Condition(id=condition.id, motion=pattern, fps=condition.fps, representation=condition.representation,
                     template=template, rotation_order=condition.rotation_order, name_map=dict(condition.name_map),
                     joints=condition.joints, degrees=condition.degrees, body_model=body_model)
    stim = Stimulus(id=path.stem, audio=path)
    design = Design(path=path.parent / "(view)", title="view", instructions="", conditions=[cond],
                    stimuli=[stim], criteria=[])
    if template is not None and not Path(template).is_file():
        raise InputError(condition.template, None, "template BVH not found (--template)")
    return load_condition_motion(design, cond, stim)
