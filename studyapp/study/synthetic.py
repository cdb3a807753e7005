"""A tiny, self-contained synthetic study: generated speech-like WAVs, three BVH conditions, one TOML design.

Used by the session, kill and bundle tests and the storage benchmark, where a real study's minute-long
clips would only cost time. The three conditions differ the way real models differ, so the ``careful`` bot
has something to perceive: ``synced`` moves the arms with the speech envelope, ``lagged`` moves them with
the envelope delayed by half a second, ``static`` barely moves.

Example
-------
>>> import tempfile
>>> path = write_synthetic_study(tempfile.mkdtemp(), n_stimuli=2)
>>> path.name
'tiny.toml'
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

SAMPLE_RATE = 16000
FPS = 30.0

# name, parent index, offset (cm) -- depth-first, parents before children.
_JOINTS = (
    ("Hips", -1, (0.0, 95.0, 0.0)),
    ("Spine", 0, (0.0, 10.0, 0.0)),
    ("Spine1", 1, (0.0, 15.0, 0.0)),
    ("Neck", 2, (0.0, 20.0, 0.0)),
    ("Head", 3, (0.0, 10.0, 0.0)),
    ("RightShoulder", 2, (-5.0, 17.0, 0.0)),
    ("RightArm", 5, (-12.0, 0.0, 0.0)),
    ("RightForeArm", 6, (-27.0, 0.0, 0.0)),
    ("RightHand", 7, (-25.0, 0.0, 0.0)),
    ("LeftShoulder", 2, (5.0, 17.0, 0.0)),
    ("LeftArm", 9, (12.0, 0.0, 0.0)),
    ("LeftForeArm", 10, (27.0, 0.0, 0.0)),
    ("LeftHand", 11, (25.0, 0.0, 0.0)),
    ("RightUpLeg", 0, (-9.0, -5.0, 0.0)),
    ("RightLeg", 13, (0.0, -42.0, 0.0)),
    ("RightFoot", 14, (0.0, -42.0, 0.0)),
    ("LeftUpLeg", 0, (9.0, -5.0, 0.0)),
    ("LeftLeg", 16, (0.0, -42.0, 0.0)),
    ("LeftFoot", 17, (0.0, -42.0, 0.0)),
)


def speech_like(seconds: float, seed: int) -> np.ndarray:
    """Noise bursts with syllable-like (3-6 Hz) envelopes and pauses: float32 in [-1, 1]."""
    rng = np.random.default_rng(seed)
    n = int(seconds * SAMPLE_RATE)
    t = np.arange(n) / SAMPLE_RATE
    rate = rng.uniform(3.0, 6.0)
    env = np.clip(np.sin(2 * np.pi * rate * t + rng.uniform(0, np.pi)), 0, None) ** 2
    env *= (np.sin(2 * np.pi * 0.7 * t + rng.uniform(0, np.pi)) > -0.3)  # phrase pauses
    carrier = rng.standard_normal(n) * 0.3 + 0.5 * np.sin(2 * np.pi * rng.uniform(110, 220) * t)
    return (0.6 * env * carrier).astype(np.float32)


def envelope_at_fps(audio: np.ndarray, n_frames: int) -> np.ndarray:
    """RMS energy per motion frame, scaled to [0, 1]."""
    hop = SAMPLE_RATE / FPS
    out = np.empty(n_frames)
    for f in range(n_frames):
        seg = audio[int(f * hop): int((f + 1) * hop)]
        out[f] = np.sqrt(np.mean(seg.astype(np.float64) ** 2)) if seg.size else 0.0
    peak = out.max()
    return out / peak if peak > 0 else out


def bvh_text(arm_angles: np.ndarray) -> str:
    """A BVH whose arms swing by ``arm_angles[f]`` degrees (shoulders and elbows), ZXY channels."""
    lines = ["HIERARCHY"]
    order: list[int] = []  # joints in the order their channels appear

    def children(j: int) -> list[int]:
        return [k for k, (_, p, _) in enumerate(_JOINTS) if p == j]

    def emit(j: int, depth: int) -> None:
        name, parent, off = _JOINTS[j]
        pad = "  " * depth
        order.append(j)
        lines.append(f"{pad}{'ROOT' if parent < 0 else 'JOINT'} {name}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {off[0]:.4f} {off[1]:.4f} {off[2]:.4f}")
        if parent < 0:
            lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            lines.append(f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation")
        kids = children(j)
        if kids:
            for k in kids:
                emit(k, depth + 1)
        else:
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            lines.append(f"{pad}    OFFSET 0.0000 5.0000 0.0000")
            lines.append(f"{pad}  }}")
        lines.append(f"{pad}}}")

    emit(0, 0)
    n = len(arm_angles)
    lines += ["MOTION", f"Frames: {n}", f"Frame Time: {1.0 / FPS:.6f}"]
    names = [_JOINTS[j][0] for j in order]
    for a in arm_angles:
        vals = [0.0, 95.0, 0.0, 0.0, 0.0, 0.0]
        for name in names[1:]:
            z = x = y = 0.0
            if name == "RightArm":
                z = 70.0 - a
            elif name == "LeftArm":
                z = -70.0 + a
            elif name in ("RightForeArm", "LeftForeArm"):
                y = a * (1 if name.startswith("Right") else -1)
            vals += [z, x, y]
        lines.append(" ".join(f"{v:.4f}" for v in vals))
    return "\n".join(lines) + "\n"


def write_synthetic_study(
    folder: str | Path,
    *,
    n_stimuli: int = 4,
    seconds: float = 1.0,
    practice: bool = True,
    attention_check: bool = False,
    questionnaire: bool = False,
    max_attention_failures: int | None = None,
    allow_ties: bool = False,
    name: str = "tiny",
    seed: int = 7,
) -> Path:
    """Write a complete tiny study into ``folder`` and return the design path (``<name>.toml``).

    ``practice`` adds one practice clip; ``attention_check`` adds a known-worst check (the ``static``
    condition must rank last on realism) on an extra clip; ``questionnaire`` adds two Likert items and a
    text item.
    """
    from scipy.io import wavfile

    folder = Path(folder)
    (folder / "audio").mkdir(parents=True, exist_ok=True)
    ids = [f"s{i + 1}" for i in range(n_stimuli)]
    extra = (["p1"] if practice else []) + (["att1"] if attention_check else [])
    for k, sid in enumerate(ids + extra):
        audio = speech_like(seconds, seed * 1000 + k)
        wavfile.write(folder / "audio" / f"{sid}.wav", SAMPLE_RATE, (audio * 32767).astype(np.int16))
        n_frames = int(round(seconds * FPS))
        env = envelope_at_fps(audio, n_frames)
        lag = int(0.5 * FPS)
        motions = {
            "synced": 60.0 * env,
            "lagged": 60.0 * np.concatenate([np.zeros(lag), env])[:n_frames],
            "static": 0.5 * np.sin(np.arange(n_frames) * 0.05),
        }
        for cond, angles in motions.items():
            d = folder / "motion" / cond
            d.mkdir(parents=True, exist_ok=True)
            (d / f"{sid}.bvh").write_text(bvh_text(angles))
    out = [f'title = "Tiny synthetic study ({name})"',
           'instructions = "Watch the three figures and rank them."']
    if practice:
        out.append('practice = ["p1"]')
    for cond in ("synced", "lagged", "static"):
        out += ["", "[[conditions]]", f'id = "{cond}"', f'motion = "motion/{cond}/{{stimulus}}.bvh"', f"fps = {FPS}"]
    for k, sid in enumerate(ids + extra):
        out += ["", "[[stimuli]]", f'id = "{sid}"', f'audio = "audio/{sid}.wav"',
                f'tags = {{ speaker = "spk{k % 2 + 1}" }}']
        if sid in extra:
            out.append("in_rotation = false")
    if attention_check:
        out += ["", "[[attention_checks]]", 'stimulus = "att1"', 'kind = "known-worst"', 'condition = "static"',
                'criterion = "realism"', "rank = 3"]
    if questionnaire:
        for qid, text in (("q1", "The task was clear."), ("q2", "The figures looked natural.")):
            out += ["", "[[questionnaire]]", f'id = "{qid}"', 'kind = "likert"', f'text = "{text}"',
                    'scale = "experience"', "points = 7"]
        out += ["", "[[questionnaire]]", 'id = "comments"', 'kind = "text"', 'text = "Any comments?"']
    out += ["", "[ordering]", 'method = "balanced-latin-square"', f"seed = {seed}"]
    out += ["", "[playback]", f"allow_ties = {'true' if allow_ties else 'false'}"]
    out += ["", "[participants]", 'groups = { ordering_version = "v1" }']
    if max_attention_failures is not None:
        out.append(f"max_attention_failures = {max_attention_failures}")
    path = folder / f"{name}.toml"
    path.write_text("\n".join(out) + "\n")
    return path
