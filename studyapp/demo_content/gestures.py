"""Rule-based upper-body gestures on the BEAT skeleton, driven by a speech energy envelope.

Three demo "models" come from this one generator so that the demo study has a known right answer:

* ``synced``: beat gestures whose strokes land on stressed syllables (energy peaks), hands raised into the
  gesture space in front of the chest while speaking and lowered in pauses, head nods and a little spine
  motion with the strokes. Which hand(s), the gesture-space position and the stroke direction vary from
  one gesture unit (the stretch between two pauses) and one stroke to the next.
* ``lagged``: the very same gestures as ``synced``, 300 ms late (same hands, positions and amplitudes).
* ``static``: arms resting at the sides, breathing and a slow idle drift of the hands only.

Poses are built as BVH Euler angles (BEAT's ``Xrotation Yrotation Zrotation`` channel order) so the
written file holds exactly the angles designed here. Rest pose of the rig is a T-pose facing +Z with the
right arm along -X; "down" is a Z rotation (+ for the right arm), "forward" a negative X rotation of the
upper arm, and elbow flexion a Y rotation of the forearm (+ right, - left).

>>> import numpy as np
>>> from studyapp.motion.beat import beat_skeleton
>>> e = np.zeros(60); e[20:40] = np.hanning(20)
>>> m = gesture_motion(beat_skeleton(), e, fps=30.0, seed=1, condition="synced")
>>> m.n_frames, m.fps
(60, 30.0)
"""
from __future__ import annotations

import numpy as np

from studyapp.demo_content.signals import delay, smooth, speech_activity, stress_peaks
from studyapp.motion.fk import rest_joint_positions
from studyapp.motion.rotations import euler_to_quat
from studyapp.motion.skeleton import Motion, Skeleton

CONDITIONS: tuple[str, ...] = ("synced", "lagged", "static")
#: How late the ``lagged`` condition's gestures are.
LAG_S = 0.3

# Rest: arms hanging slightly away from the body, elbows a little bent, fingers relaxed.
_REST_DOWN = 80.0        # upper arm Z (right +, left -)
_REST_FORWARD = -6.0     # upper arm X (negative = forward)
_REST_ELBOW = 16.0       # forearm Y (right +, left -)
_REST_WRIST = 6.0
_FINGER_CURL = {"1": 14.0, "2": 18.0}


def _strokes(t: np.ndarray, centers: np.ndarray, amps: np.ndarray, rise_s: float = 0.3, fall_s: float = 0.07) -> np.ndarray:
    """Sum of beat strokes: a slow preparation up to ``amps[i]``, then a fast return that is fastest at ``centers[i]``.

    Each stroke is two half-Gaussians meeting at the apex ``fall_s`` before the centre (value and slope
    continuous), so the hand's peak speed of the stroke falls on the stressed syllable itself.
    """
    if centers.size == 0:
        return np.zeros_like(t)
    u = t[:, None] - centers[None, :] + fall_s
    width = np.where(u < 0, rise_s, fall_s)
    return (np.exp(-0.5 * (u / width) ** 2) * amps[None, :]).sum(axis=1)


def _units(active: np.ndarray) -> list[tuple[int, int]]:
    """``[start, end)`` frame ranges where ``active`` (boolean) holds: the gesture units."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], active.astype(np.int8), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def _idle(rng: np.random.Generator, n: int, fps: float, sigma_s: float, amp: float) -> np.ndarray:
    """Slow smooth random drift with roughly ``amp`` standard deviation (no jitter: heavily low-passed)."""
    x = smooth(rng.standard_normal(n + 200), fps, sigma_s)[100:100 + n]
    return amp * x / (x.std() + 1e-9)


def _gesture_drive(energy: np.ndarray, fps: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Per-frame gesture controls from the energy envelope: lift, beats and nods per hand."""
    n = energy.size
    t = np.arange(n) / fps
    act = speech_activity(energy, fps)
    units = _units(act > 0.5)
    # Per gesture unit: which hand(s) and where in gesture space; smoothed so units blend, never jump.
    w_r, w_l = np.full(n, 0.6), np.full(n, 0.6)
    fwd, elbow, abduct, inward = np.full(n, 10.0), np.full(n, 76.0), np.full(n, 4.0), np.full(n, 25.0)
    for a, b in units:
        mode = rng.choice(3, p=[0.45, 0.25, 0.3])
        w_r[a:b], w_l[a:b] = [(1.0, 0.3), (0.3, 1.0), (1.0, 1.0)][mode]
        # Upper arms stay near the body (elbows low); the forearms bring the hands up in front of the chest.
        fwd[a:b] = rng.uniform(4.0, 16.0)
        elbow[a:b] = rng.uniform(68.0, 86.0)
        abduct[a:b] = rng.uniform(0.0, 8.0)
        inward[a:b] = rng.uniform(15.0, 35.0)
    w_r, w_l, fwd, elbow, abduct, inward = (smooth(x, fps, 0.2) for x in (w_r, w_l, fwd, elbow, abduct, inward))
    # Raising the hands into gesture space is slow compared with the strokes, so the fast motion belongs to
    # the strokes; it is centred just after the voice starts (not in the silence before it) so that even the
    # lift's motion is in time with speech rather than ahead of it.
    act = delay(smooth(act, fps, 0.3), fps, 0.15, hold_first=True)

    # A stroke on every syllable peak, scaled by its loudness so stressed syllables get the big beats
    # and weak ones barely a flick (squared: 0.5 relative loudness -> a quarter of the amplitude).
    peaks = stress_peaks(energy, fps, min_height=0.2, min_gap_s=0.15)
    tp = peaks / fps
    strength = smooth(energy, fps, 0.03)[peaks] if peaks.size else np.zeros(0)
    # Loudness relative to this clip's typical stressed syllable (the upper quartile of peaks), so one
    # shout does not shrink every other beat.
    ref = np.percentile(strength, 75) if peaks.size else 1.0
    amp = np.clip(strength / ref, 0.0, 1.15) ** 2 * rng.uniform(0.75, 1.25, size=peaks.size)
    # Each stroke mixes three directions differently: an up-down beat (elbow), a forward push (shoulder
    # flexion) and an outward flick (abduction); the mix is drawn per stroke so no two beats are alike.
    mix = rng.dirichlet([3.0, 1.0, 1.0], size=peaks.size) if peaks.size else np.zeros((0, 3))
    # Beats: the hand rises (elbow flexes) during the preparation and strikes down on the stressed peak.
    beat_elbow = _strokes(t, tp, 24.0 * amp * mix[:, 0])
    beat_fwd = _strokes(t, tp, 20.0 * amp * mix[:, 1])
    beat_out = _strokes(t, tp, 16.0 * amp * mix[:, 2])
    beat_wrist = _strokes(t, tp, -14.0 * amp)
    # Between strokes the hands keep "rolling" with the voice: a small circular motion whose phase advances
    # with the energy, so its speed is proportional to loudness and it stops when the voice stops.
    phase = 2 * np.pi * 2.5 * np.cumsum(smooth(energy, fps, 0.03)) / fps
    roll_a, roll_b = np.sin(phase), np.cos(phase) - 1.0
    # The head lifts slightly with the preparation and drops with the stroke: a nod on the stress.
    nod = _strokes(t, tp, -3.0 * amp * rng.uniform(0.5, 1.2, size=peaks.size), rise_s=0.25, fall_s=0.1)
    return {
        "act": act, "w_r": w_r, "w_l": w_l, "fwd": fwd, "elbow": elbow, "abduct": abduct, "inward": inward,
        "beat_elbow": beat_elbow, "beat_fwd": beat_fwd, "beat_out": beat_out, "beat_wrist": beat_wrist,
        "nod": nod, "roll_a": roll_a, "roll_b": roll_b,
    }


def _standing_height(skeleton: Skeleton) -> float:
    """Hips height that puts the lowest rest joint on the floor (y = 0)."""
    return float(-rest_joint_positions(skeleton)[:, 1].min())


def gesture_motion(skeleton: Skeleton, energy: np.ndarray, fps: float, seed: int, condition: str) -> Motion:
    """A BEAT-skeleton :class:`Motion` of ``len(energy)`` frames for one demo condition.

    ``energy`` is the frame-aligned envelope from :func:`~studyapp.demo_content.signals.speech_energy`.
    The same ``seed`` gives the same idle motion (breathing, drift) in every condition, so conditions
    differ only in their gestures.
    """
    if condition not in CONDITIONS:
        raise ValueError(f"unknown condition {condition!r}; choose from {CONDITIONS}")
    energy = np.asarray(energy, dtype=np.float64)
    n = energy.size
    t = np.arange(n) / fps
    idle_rng = np.random.default_rng([seed, 0])
    breathe = np.sin(2 * np.pi * 0.23 * t + idle_rng.uniform(0, 2 * np.pi))
    drift = {k: _idle(idle_rng, n, fps, 1.2, 1.0) for k in ("arm_r", "arm_l", "elb_r", "elb_l", "head_y", "head_x", "sway")}

    if condition == "static":
        z = np.zeros(n)
        g = {k: z for k in ("act", "w_r", "w_l", "beat_elbow", "beat_fwd", "beat_out", "beat_wrist", "nod", "roll_a", "roll_b")}
        g.update(fwd=z, elbow=z, abduct=z, inward=z)
        idle_amp = 1.2
    else:
        g = _gesture_drive(energy, fps, np.random.default_rng([seed, 1]))
        if condition == "lagged":
            # The synced gestures themselves, late: re-running the generator on a delayed envelope would
            # draw other hands, positions and stroke mixes, and the two "models" would then differ in
            # diversity and realism too, where the demo's known answer is that only timing differs.
            g = {k: delay(v, fps, LAG_S, hold_first=True) for k, v in g.items()}
        idle_amp = 0.6
    act = g["act"]
    lift_r, lift_l = act * g["w_r"], act * g["w_l"]

    ang = np.zeros((n, skeleton.n_joints, 3))  # BVH XYZ Euler degrees per joint

    def put(name: str, axis: int, values: np.ndarray | float) -> None:
        if name in skeleton.names:
            ang[:, skeleton.index(name), axis] += values

    for side, sgn, lift, w in (("Right", 1.0, lift_r, g["w_r"]), ("Left", -1.0, lift_l, g["w_l"])):
        key = "r" if side == "Right" else "l"
        beat = w * act
        put(f"{side}Arm", 0, _REST_FORWARD - lift * g["fwd"] - beat * g["beat_fwd"] + idle_amp * drift[f"arm_{key}"])
        put(f"{side}Arm", 1, sgn * lift * g["inward"])
        put(f"{side}Arm", 2, sgn * (_REST_DOWN - lift * g["abduct"] - beat * g["beat_out"] - 6.0 * beat * g["roll_a"]))
        put(f"{side}ForeArm", 1, sgn * (_REST_ELBOW + lift * g["elbow"] + beat * g["beat_elbow"] + 7.0 * beat * g["roll_b"]
                                        + idle_amp * 1.5 * drift[f"elb_{key}"]))
        put(f"{side}Hand", 2, sgn * (_REST_WRIST + beat * g["beat_wrist"]))
        for finger in ("Index", "Middle", "Ring", "Pinky"):
            for seg, curl in _FINGER_CURL.items():
                put(f"{side}Hand{finger}{seg}", 2, sgn * curl * (1.0 - 0.3 * lift))

    # Torso: breathing, a slight lean into speaking, a twist towards the gesturing hand, nods with strokes.
    put("Spine", 0, 0.5 * breathe + 1.5 * act)
    put("Spine1", 0, 0.4 * breathe)
    put("Spine1", 1, 3.0 * (lift_r - lift_l))
    put("Spine2", 0, 0.3 * breathe)
    put("Neck", 0, 0.6 * g["nod"] - 0.3 * breathe)
    put("Head", 0, g["nod"] + 0.8 * drift["head_x"])
    put("Head", 1, 3.0 * drift["head_y"] * (0.4 + act))

    rotations = euler_to_quat(ang, "XYZ")
    translations = np.broadcast_to(skeleton.offsets, (n, skeleton.n_joints, 3)).copy()
    root = skeleton.index(skeleton.names[0])
    translations[:, root, 1] = _standing_height(skeleton) + 0.4 * breathe
    translations[:, root, 0] += 0.8 * drift["sway"]
    return Motion(skeleton, fps, rotations, translations, source=f"demo gestures ({condition}, seed {seed})")
