"""Fill the GL driver's shader cache with the programs a participant's first trial frame draws.

Why (issue 20, "the first trial frame within 1.5 s"): a GL driver turns a program into machine code when it
is first drawn with a given state (vertex layout, bound textures, blending, framebuffer format). On Mesa's
software rasteriser (llvmpipe) that is an LLVM compile per program and state: 50-60 ms for the backdrop,
floor and label programs and 120-260 ms for each of the avatar's two vertex-shader variants on a 2-core
machine, about 0.6 s in all, paid by the first frame of a process whose driver cache is empty (a lab PC's
first participant). Mesa keeps that code in its on-disk cache (``$MESA_SHADER_CACHE_DIR``, else
``$XDG_CACHE_HOME/mesa_shader_cache``), which every later process on the machine reads instead.

:func:`warm_shader_cache` draws one frame of a rest-pose scene of each given avatar offscreen, through
:meth:`Renderer.draw_canvas <studyapp.render.renderer.Renderer.draw_canvas>` as the participant window's
scene cache does (at :data:`WARM_SIZE`), so the programs, variants and states are those of a trial frame (the avatars' own meshes, textures
and morph textures; three labelled slots), and the driver stores them. ``studyapp validate`` calls it on the
machine it runs on (:func:`warm_in_child`, in a process of its own, so ``validate`` itself never holds a GL
context): in a lab the experimenter validates on the PC the participants then use (see the README), so the
first participant's first trial frame finds the code compiled. Online participants do not run GL at all
(they are sent pre-rendered videos), so it is not needed there.

It is best effort: with no usable offscreen context, or a driver that fails, it does nothing and says why.
A record (:func:`warm_record`: an empty file in ``$STUDYAPP_CACHE_DIR/gl-warm``, else the user cache folder)
keyed by the shader sources, the code that picks programs and states, the avatar files and the driver cache
folder makes a second call for the same avatars cost a file check; deleting it is safe.
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import subprocess
import sys
from pathlib import Path
from typing import Sequence

from studyapp.errors import StudyappError
from studyapp.render.avatar import Avatar
from studyapp.resources import read_shader

log = logging.getLogger(__name__)

#: What the participant window's first trial frame is drawn at in ``bench_startup`` (the 3D view above
#: an 84-pixel answer footer). A label texture's size follows the viewport height; a different window size
#: costs at most the label program's compile again.
WARM_SIZE = (1280, 720)
WARM_FOOTER = 84
_SHADERS = ("skinned.vert", "skinned.frag", "lighting.glsl", "fullscreen.vert", "background.frag",
            "floor.vert", "floor.frag", "label.vert", "label.frag")


def driver_cache_dir() -> Path | None:
    """Mesa's on-disk shader cache folder, as Mesa picks it; None when it is switched off."""
    for var in ("MESA_SHADER_CACHE_DISABLE", "MESA_GLSL_CACHE_DISABLE"):
        if os.environ.get(var, "").lower() in ("1", "true", "yes"):
            return None
    for var in ("MESA_SHADER_CACHE_DIR", "MESA_GLSL_CACHE_DIR"):
        if os.environ.get(var):
            return Path(os.environ[var])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "mesa_shader_cache"


def warm_record(sources: Sequence[str | Path | None]) -> Path:
    """The record that the driver cache holds the programs for avatars ``sources`` (None: the built-in one).

    Keyed by the shader sources, the code that decides programs and draw states (renderer, skin groups, the
    built-in avatar's model), the driver cache folder, and each avatar file's path, size and modification
    time, so any change of these warms again."""
    h = hashlib.sha256()
    for name in _SHADERS:
        h.update(read_shader(name).encode())
    for module in ("avatar.py", "gpu.py", "renderer.py"):  # read, not imported: validate stays GL-free
        h.update((Path(__file__).parent / module).read_bytes())
    h.update(str(driver_cache_dir()).encode())
    for src in sorted(str(s) if s else "builtin" for s in sources):
        p = Path(src)
        if src != "builtin" and p.is_file():
            st = p.stat()
            h.update(f"{p.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
        else:
            h.update(src.encode())
    env = os.environ.get("STUDYAPP_CACHE_DIR")
    if env:
        base = Path(env)
    else:
        import platformdirs

        base = Path(platformdirs.user_cache_dir("studyapp", appauthor=False))
    return base / "gl-warm" / h.hexdigest()[:32]


def is_warm(sources: Sequence[str | Path | None]) -> bool:
    """Whether a warm-up for ``sources`` was recorded and the driver cache folder it filled still exists."""
    cache = driver_cache_dir()
    return cache is not None and cache.is_dir() and warm_record(sources).is_file()


def warm_shader_cache(avatars: Sequence[Avatar], sources: Sequence[str | Path | None] = (), *,
                      size: tuple[int, int] = WARM_SIZE, footer: int = WARM_FOOTER) -> str:
    """Draw one trial frame of each of ``avatars`` offscreen, in this process, so the driver caches its
    compiled programs, and record it for ``sources`` (the avatars' files, None for the built-in one).

    Returns what happened, in a few words: ``"compiled"``, or why nothing was done (no offscreen context,
    a driver error); it never raises for a GL failure. It leaves no GL context current: call it where no
    other context is in use (:func:`warm_in_child` runs it in a process of its own).
    """
    from studyapp.motion.skeleton import Motion
    from studyapp.render.context import create_offscreen_context
    from studyapp.render.pose import prepare_slot
    from studyapp.render.renderer import Renderer
    from studyapp.render.scene import make_scene

    try:
        ctx = create_offscreen_context()
    except Exception as exc:  # no EGL/OSMesa here (a server): nothing to warm
        return f"no offscreen GL context ({type(exc).__name__})"
    try:
        renderer = Renderer(ctx)
        w, h = size
        for av in {id(a): a for a in avatars}.values():
            slot = prepare_slot(av, Motion.rest(av.skeleton, 2, 30.0), None)
            scene = make_scene([slot] * 3, av, labels=("A", "B", "C"))
            renderer.upload_avatar(av)
            renderer.draw_canvas(scene, 0.0, (w, h), (0, footer, w, h - footer), (0.11, 0.12, 0.14))
            ctx.finish()
        renderer.release()
    except Exception as exc:  # a broken driver: the participant's start will say so, not this
        log.info("shader cache warm-up failed: %s", exc)
        return f"driver error ({type(exc).__name__})"
    finally:
        ctx.release()
    record = warm_record(sources)
    try:
        record.parent.mkdir(parents=True, exist_ok=True)
        record.touch()
    except OSError:
        pass  # a read-only cache folder: the next call warms again
    return "compiled"


def warm_in_child(sources: Sequence[str | Path | None], bone_map: dict[str, str] | None = None, *,
                  timeout: float = 60.0) -> str:
    """:func:`warm_shader_cache` for the avatars ``sources`` (files, None for the built-in one; loaded as
    a trial loads them, with the design's ``bone_map``) in a child process, unless :func:`is_warm`. The
    caller's process stays free of GL (no context of its own made current or released, and a driver that
    crashes takes only the child); waits for it (at most ``timeout`` seconds). Returns what happened."""
    if is_warm(sources):
        return "already cached"
    cmd = [sys.executable, "-m", "studyapp.render.warmup", "--bone-map", json.dumps(dict(bone_map or {}))]
    cmd += [str(Path(s).resolve()) if s else "builtin" for s in sources]
    # run from the folder holding this studyapp: `-m` puts the working folder first on the child's path, and
    # another checkout there would otherwise be the code that warms
    root = Path(__file__).resolve().parents[2]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=root)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"not done ({type(exc).__name__})"
    lines = (out.stdout or out.stderr or "").strip().splitlines()
    return lines[-1] if out.returncode == 0 and lines else f"not done (exit status {out.returncode})"


def main(argv: Sequence[str]) -> int:
    """``python -m studyapp.render.warmup [--bone-map JSON] AVATAR...`` (``builtin`` or a file): warm, print
    what happened."""
    from studyapp.render.scene import load_avatar

    args = list(argv)
    bone_map: dict[str, str] = {}
    if args[:1] == ["--bone-map"]:
        bone_map = json.loads(args[1])
        args = args[2:]
    sources = [None if a == "builtin" else a for a in args]
    try:
        avatars = [load_avatar(s, bone_map=(bone_map or None) if s else None) for s in sources]
    except (StudyappError, OSError, ValueError) as exc:
        print(f"not done (avatar: {exc})")
        return 0
    print(warm_shader_cache(avatars, sources))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
