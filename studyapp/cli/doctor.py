"""``studyapp doctor``: can this PC run the study? (GL, display, audio + latency, render speed, verdict)."""
from __future__ import annotations

import argparse
import json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "doctor",
        help="check whether this computer can run a study (graphics, display, audio, render speed)",
        description="Measure OpenGL, the display, audio outputs and their latency, and the speed of drawing "
                    "three avatars, then say whether this computer can run the study. The participant window "
                    "runs the same check before the first clip.",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--audio-device", default=None,
                   help="output to check (index or part of the name; default: the system default)")
    p.add_argument("--frames", type=int, default=60, help="frames of the render benchmark (default 60)")
    p.set_defaults(func=_cmd_doctor)


def _cmd_doctor(args: argparse.Namespace) -> int:
    from studyapp.ui.envcheck import gather

    report = gather(audio_device=args.audio_device, bench_frames=max(0, args.frames))
    d = report.as_dict()
    if args.json:
        print(json.dumps(d, indent=2, default=str))
    else:
        print(format_report(d))
    return 0 if d["ok"] else 1


def format_report(d: dict) -> str:
    """Human-readable doctor output."""
    lines = ["studyapp doctor", ""]
    gl = f"{d['gl_renderer']} / {d['gl_version']}" if d.get("gl_renderer") else "none"
    lines.append(f"  OpenGL        {gl}")
    if d.get("display"):
        size = "x".join(str(v) for v in d["display_size"]) if d.get("display_size") else "size unknown"
        hz = f"{d['refresh_hz']:.0f} Hz" if d.get("refresh_hz") else "refresh unknown"
        lines.append(f"  Display       {d['display']}: {size}, {hz}")
    else:
        lines.append("  Display       no display")
    lines.append("  Audio outputs " + ("; ".join(d["audio_devices"]) if d["audio_devices"] else "none"))
    if d.get("audio_device"):
        lat = f"{d['audio_latency_ms']:.0f} ms" if d.get("audio_latency_ms") is not None else "unknown"
        lines.append(f"  Audio used    {d['audio_device']} (measured output latency {lat})")
    elif d.get("audio_error"):
        lines.append(f"  Audio used    none: {d['audio_error']}")
    if d.get("render_fps") is not None:
        w, h = d["render_size"]
        lines.append(f"  Rendering     {d['render_fps']:.1f} fps, three avatars at {w}x{h} "
                     f"({d['render_frames']} frames, with read-back)")
    elif d.get("render_error"):
        lines.append(f"  Rendering     {d['render_error']}")
    lines.append("")
    for c in d["checks"]:
        lines.append(f"  [{c['status'].upper():4s}] {c['name']}: {c['detail']}")
    lines.append("")
    lines.append(d["verdict"])
    return "\n".join(lines)
