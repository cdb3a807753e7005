"""The demo study's stimuli, generated from fixed seeds: speech audio, ARKit face and three "models".

``python -m studyapp.demo_content OUT_DIR`` writes::

    OUT_DIR/audio/clip01.wav .. clip04.wav        16 kHz mono int16 synthetic speech (spk1: 1-2, spk2: 3-4)
    OUT_DIR/face/clip01.csv ..                    30 fps ARKit weights (time + 52 names)
    OUT_DIR/motion/<condition>/clip01.bvh ..      BEAT 75-joint skeleton, 30 fps, for synced / lagged / static
    OUT_DIR/manifest.json                         clip list: speaker, seed, duration, frames

The shipped copy lives in ``study_designs/demo/``; a test regenerates it and compares, so the data cannot
drift from this code. The three conditions have a known ranking for synchronization (synced > lagged,
static has nothing to synchronize) and diversity (static last), which the demo's analysis should find.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from studyapp.audio.wav import save_wav
from studyapp.demo_content.face_anim import speech_face
from studyapp.demo_content.gestures import CONDITIONS, gesture_motion
from studyapp.demo_content.signals import speech_energy
from studyapp.demo_content.speech import SPEAKERS, synthesize_speech
from studyapp.face.io import save_face_csv

#: Frame rate of the demo's face and motion files.
FPS = 30.0
#: Length of every demo clip in seconds.
CLIP_SECONDS = 10.0
#: Decimal places kept in BVH angles (0.01 degree: quantization steps far below what a viewer can see, no jitter).
BVH_DECIMALS = 2
#: Decimal places kept in face weights.
FACE_DECIMALS = 4


@dataclass(frozen=True)
class ClipSpec:
    name: str
    speaker: str
    seed: int


CLIPS: tuple[ClipSpec, ...] = (
    ClipSpec("clip01", "spk1", 101),
    ClipSpec("clip02", "spk1", 102),
    ClipSpec("clip03", "spk2", 201),
    ClipSpec("clip04", "spk2", 202),
)


def _compact_numbers(line: str) -> str:
    """Drop trailing zeros of fixed-point numbers ("12.50" -> "12.5", "0.00" -> "0"): a third of the size."""
    out = []
    for tok in line.split():
        if "." in tok:
            tok = tok.rstrip("0").rstrip(".")
        out.append("0" if tok in ("-0", "", "-") else tok)
    return " ".join(out)


def _write_compact_bvh(motion, path: Path) -> None:
    """Write with the motion package's BVH writer, then trim the frame lines' trailing zeros."""
    from studyapp.motion.bvh import write_bvh

    write_bvh(motion, path, precision=BVH_DECIMALS)
    text = path.read_text()
    head, sep, body = text.partition("\nMOTION\n")
    lines = body.split("\n")
    # lines[0] "Frames: N", lines[1] "Frame Time: t", then one line per frame
    frames = [_compact_numbers(ln) if ln.strip() else ln for ln in lines[2:]]
    path.write_text(head + sep + "\n".join(lines[:2] + frames), encoding="utf-8", newline="\n")


def generate(out_dir: Path) -> dict:
    """Write the demo stimuli into ``out_dir`` and return the written paths.

    Returns ``{"audio": {clip: path}, "face": {clip: path}, "motion": {condition: {clip: path}},
    "manifest": path}``. Deterministic: the same files (byte for byte on one platform) every run.
    """
    from studyapp.motion.beat import beat_skeleton

    out_dir = Path(out_dir)
    written: dict = {"audio": {}, "face": {}, "motion": {c: {} for c in CONDITIONS}}
    for sub in ["audio", "face", *(f"motion/{c}" for c in CONDITIONS)]:
        (out_dir / sub).mkdir(parents=True, exist_ok=True)
    skeleton = beat_skeleton()
    manifest = {"fps": FPS, "conditions": list(CONDITIONS), "clips": []}
    for clip in CLIPS:
        audio, script = synthesize_speech(SPEAKERS[clip.speaker], clip.seed, CLIP_SECONDS)
        energy = speech_energy(audio, FPS)
        p = out_dir / "audio" / f"{clip.name}.wav"
        save_wav(audio, p, subtype="int16")
        written["audio"][clip.name] = p
        p = out_dir / "face" / f"{clip.name}.csv"
        save_face_csv(speech_face(energy, FPS, clip.seed), p, decimals=FACE_DECIMALS)
        written["face"][clip.name] = p
        for cond in CONDITIONS:
            p = out_dir / "motion" / cond / f"{clip.name}.bvh"
            _write_compact_bvh(gesture_motion(skeleton, energy, FPS, clip.seed, cond), p)
            written["motion"][cond][clip.name] = p
        manifest["clips"].append({
            "name": clip.name, "speaker": clip.speaker, "seed": clip.seed,
            "duration_s": audio.duration, "frames": int(energy.size),
            "phrases": len(script.phrases), "syllables": len(script.syllables),
        })
    p = out_dir / "manifest.json"
    p.write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    written["manifest"] = p
    return written


__all__ = ["CLIPS", "CLIP_SECONDS", "FPS", "ClipSpec", "generate"]
