"""Fill the GL driver's shader cache with the programs a participant's first trial frame draws.

Why (issue 20, "the first trial frame within 1.5 s"): a GL driver turns a program into machine code when it
is first drawn with a given state (vertex layout, bound textures, blending, framebuffer format). On Mesa's
software rasteriser (llvmpipe) that is an LLVM compile per program and state: 50-60 ms for the backdrop,
floor and label programs and 120-260 ms for each of the avatar's two vertex-shader variants on a 2-core
machine, about 0.6 s in all, paid by the first frame of a process whose driver cache is empty (a lab PC's
first participant). Mesa keeps that code in its on-disk cache (``$MESA_SHADER_CACHE_DIR``, else
``$XDG_CACHE_HOME/mesa_shader_cache``), which every later process on the machine reads instead.

:func:`warm_shader_cache` draws one frame of a rest-pose scene of each given avatar offscreen, through
:meth:`Renderer.draw_canvas <studyapp.render.renderer.Renderer.draw_canvas>` at the participant window's
size, so the programs, variants and states are those of a trial frame (the avatars' own meshes, textures
and morph textures; three labelled slots), and the driver stores them. ``studyapp validate`` calls it on the
machine it runs on: in a lab the experimenter validates on the PC the participants then use (see the
README), so the first participant's first trial frame finds the code compiled. Online participants do not
run GL at all (they are sent pre-rendered videos), so it is not needed there.

It is best effort: with no usable offscreen context, or a driver that fails, it does nothing and says why.
A record (an empty file in ``$STUDYAPP_CACHE_DIR/gl-warm``, else the user cache folder) keyed by the shader
sources, the avatar files and the driver cache folder makes a second call for the same avatars cost a file
check; deleting it is safe.
"""
from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path
from typing import Sequence

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


def _record(avatars: Sequence[Avatar], sources: Sequence[str | Path | None]) -> Path:
    h = hashlib.sha256()
    for name in _SHADERS:
        h.update(read_shader(name).encode())
    h.update(str(driver_cache_dir()).encode())
    for src in sources:  # the avatar files by identity; the built-in one by its arrays' shapes
        p = Path(src) if src else None
        if p is not None and p.is_file():
            st = p.stat()
            h.update(f"{p.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
        else:
            h.update(b"builtin")
    for av in avatars:
        h.update(f"{av.name}|{len(av.vertices)}|{av.texture is not None}|{av.double_sided}".encode())
    env = os.environ.get("STUDYAPP_CACHE_DIR")
    if env:
        base = Path(env)
    else:
        import platformdirs

        base = Path(platformdirs.user_cache_dir("studyapp", appauthor=False))
    return base / "gl-warm" / h.hexdigest()[:32]


def warm_shader_cache(avatars: Sequence[Avatar], sources: Sequence[str | Path | None] = (), *,
                      size: tuple[int, int] = WARM_SIZE, footer: int = WARM_FOOTER) -> str:
    """Draw one trial frame of each of ``avatars`` offscreen so the driver caches its compiled programs.

    ``sources``: the avatars' files (None for the built-in one), for the record that lets the next call
    skip. Returns what happened, in a few words: ``"compiled"``, ``"already cached"``, or why nothing was
    done (no offscreen context, a driver error); it never raises for a GL failure.
    """
    cache = driver_cache_dir()
    record = _record(avatars, sources)
    if cache is not None and cache.is_dir() and record.is_file():
        return "already cached"
    from studyapp.motion.skeleton import Motion
    from studyapp.render.context import create_offscreen_context
    from studyapp.render.pose import prepare_slot
    from studyapp.render.renderer import Renderer
    from studyapp.render.scene import make_scene

    try:
        ctx = create_offscreen_context()
    except Exception as exc:  # no EGL/OSMesa here (a server): nothing to warm
        return f"no offscreen GL context ({str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__})"
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
    except Exception as exc:  # a broken driver: the participant's start will say so, not validate
        log.info("shader cache warm-up failed: %s", exc)
        return f"driver error ({type(exc).__name__})"
    finally:
        ctx.release()
    try:
        record.parent.mkdir(parents=True, exist_ok=True)
        record.touch()
    except OSError:
        pass  # a read-only cache folder: the next call warms again
    return "compiled"
