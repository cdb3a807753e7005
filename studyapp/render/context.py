"""OpenGL contexts: an offscreen one (tests, stills, video) and a GLFW window (the study UI).

The same :class:`~studyapp.render.renderer.Renderer` draws into both; only the target framebuffer
differs. Everything here asks for OpenGL 3.3 core, which Mesa's llvmpipe and every desktop GPU of the
last decade provide.

Example (offscreen)::

    >>> from studyapp.render.context import create_offscreen_context, OffscreenTarget
    >>> ctx = create_offscreen_context()
    >>> target = OffscreenTarget(ctx, (64, 32))
    >>> target.clear((1.0, 0.0, 0.0))
    >>> target.read_rgb()[0, 0].tolist()
    [255, 0, 0]
"""
from __future__ import annotations

import os

import logging
import warnings
from collections.abc import Callable

import moderngl
import numpy as np

from studyapp.errors import StudyappError

log = logging.getLogger(__name__)

WINDOW_TITLE = "studyapp"  # never a model name: participants must not learn which model is where


class ContextError(StudyappError):
    """No OpenGL context could be created."""


def create_offscreen_context() -> moderngl.Context:
    """A headless OpenGL (>= 3.3 core) context.

    Tries EGL first (Mesa llvmpipe or a GPU driver, no display needed), then OSMesa through GLFW's null
    platform (``libosmesa6``). Raises :class:`ContextError` naming both failures when neither works.
    A standalone context has no default framebuffer: draw into an :class:`OffscreenTarget`.
    """
    # STUDYAPP_OFFSCREEN=osmesa skips EGL: for machines whose EGL driver is present but broken, and so the
    # fallback path can be tested on machines where EGL works.
    backends = ("osmesa",) if os.environ.get("STUDYAPP_OFFSCREEN", "").lower() == "osmesa" else ("egl", "osmesa")
    errors = []
    if "egl" in backends:
        try:
            ctx = moderngl.create_standalone_context(backend="egl", require=330)
            log.debug("offscreen context: EGL, %s", ctx.info.get("GL_RENDERER"))
            return ctx
        except Exception as exc:  # glcontext raises plain Exception subclasses for missing libraries
            errors.append(f"EGL: {exc}")
    try:
        return _osmesa_context()
    except Exception as exc:
        errors.append(f"OSMesa via GLFW: {exc}")
    raise ContextError(
        "could not create a headless OpenGL 3.3 context (" + "; ".join(errors) + "). "
        "Install Mesa's EGL (libegl1, libgl1-mesa-dri) or libosmesa6, or run with a display."
    )


_OSMESA_WINDOWS: list = []  # keep the hidden GLFW windows alive as long as their contexts


def make_current(ctx: moderngl.Context) -> None:
    """Make a headless context current again (EGL; an OSMesa context through GLFW stays current anyway)."""
    try:
        ctx.__enter__()
    except Exception:  # a loader-made context (OSMesa) has no switch: it is the only one
        pass


def _osmesa_context() -> moderngl.Context:
    import glfw

    if hasattr(glfw, "PLATFORM") and hasattr(glfw, "PLATFORM_NULL"):
        glfw.init_hint(glfw.PLATFORM, glfw.PLATFORM_NULL)
    if not glfw.init():
        raise RuntimeError("glfw.init() failed for the null platform")
    glfw.default_window_hints()
    glfw.window_hint(glfw.CONTEXT_CREATION_API, glfw.OSMESA_CONTEXT_API)
    glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
    glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
    glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
    glfw.window_hint(glfw.VISIBLE, glfw.FALSE)
    win = glfw.create_window(16, 16, WINDOW_TITLE, None, None)
    if not win:
        raise RuntimeError("glfw could not create an OSMesa context")
    glfw.make_context_current(win)
    _OSMESA_WINDOWS.append(win)
    moderngl.init_context(loader=_GlfwLoader())
    ctx = moderngl.get_context()
    if ctx.version_code < 330:
        raise RuntimeError(f"OSMesa gives OpenGL {ctx.version_code}, need 330")
    log.debug("offscreen context: OSMesa, %s", ctx.info.get("GL_RENDERER"))
    return ctx


class _GlfwLoader:
    """Function loader for ``moderngl.init_context``: glcontext cannot find an OSMesa context itself."""

    def load_opengl_function(self, name: str) -> int:
        import ctypes

        import glfw

        ptr = glfw.get_proc_address(name)
        return ctypes.cast(ptr, ctypes.c_void_p).value or 0 if ptr else 0

    def release(self) -> None:
        pass


_GL_FLUSH: list = []  # [glFlush or None], looked up once


def gl_flush() -> None:
    """``glFlush`` on the current context: hand what was drawn so far to the driver without waiting for it.

    moderngl has no flush (only ``finish``, which waits). On llvmpipe a flush starts the raster threads
    on the commands binned so far while the calling thread goes on shading the next vertices: the
    renderer flushes after each slot (see :class:`~studyapp.render.renderer.Renderer`). Looked up through
    the GL dispatch library (glvnd's ``libOpenGL``, else ``libGL`` / ``opengl32``), which reaches GLX and
    EGL contexts alike; where none is found (or for OSMesa, outside that dispatch) it does nothing, which
    is only slower.
    """
    if not _GL_FLUSH:
        _GL_FLUSH.append(_find_gl_flush())
    fn = _GL_FLUSH[0]
    if fn is not None:
        fn()


def _find_gl_flush():
    import ctypes
    import ctypes.util

    for name in ("OpenGL", "GL", "opengl32"):
        path = ctypes.util.find_library(name)
        if not path:
            continue
        try:
            fn = getattr(ctypes.CDLL(path), "glFlush")
        except (OSError, AttributeError):
            continue
        fn.restype = None
        fn.argtypes = []
        return fn
    return None


class OffscreenTarget:
    """A colour + depth framebuffer of a fixed size, optionally multisampled.

    ``fbo`` is what renderers draw into. With ``samples > 0`` drawing goes to a multisample buffer and
    :meth:`read_rgb` resolves it first. (The :class:`Renderer` already resolves its own MSAA buffer,
    so ``samples=0`` is the usual choice for it.)
    """

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], samples: int = 0) -> None:
        self.ctx = ctx
        self.size = (int(size[0]), int(size[1]))
        if self.size[0] <= 0 or self.size[1] <= 0:
            raise ValueError(f"target size must be positive, got {size}")
        self.samples = min(int(samples), ctx.max_samples) if samples else 0
        self._color = ctx.texture(self.size, 4)
        self._depth = ctx.depth_renderbuffer(self.size)
        self._resolved = ctx.framebuffer([self._color], self._depth)
        if self.samples:
            self._ms_color = ctx.renderbuffer(self.size, 4, samples=self.samples)
            self._ms_depth = ctx.depth_renderbuffer(self.size, samples=self.samples)
            self.fbo = ctx.framebuffer([self._ms_color], self._ms_depth)
        else:
            self.fbo = self._resolved

    @property
    def texture(self) -> moderngl.Texture:
        """The resolved colour texture (call :meth:`resolve` first when multisampled)."""
        return self._color

    def clear(self, rgb: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.fbo.use()
        self.fbo.clear(*rgb, 1.0, depth=1.0)

    def resolve(self) -> None:
        if self.samples:
            self.ctx.copy_framebuffer(self._resolved, self.fbo)

    def read_rgb(self) -> np.ndarray:
        """The image as ``(H, W, 3) uint8``, top row first (OpenGL stores bottom row first)."""
        self.resolve()
        data = self._resolved.read(components=3, alignment=1)
        img = np.frombuffer(data, dtype=np.uint8).reshape(self.size[1], self.size[0], 3)
        return img[::-1].copy()

    def release(self) -> None:
        for obj in (self.fbo, self._resolved, self._color, self._depth,
                    getattr(self, "_ms_color", None), getattr(self, "_ms_depth", None)):
            if obj is not None:
                obj.release()


class Window:
    """A GLFW window with a moderngl context (what participants see).

    Parameters
    ----------
    size:
        Window size in screen coordinates (ignored for fullscreen, which uses the monitor's mode).
    fullscreen:
        Open on the primary monitor in its current video mode.
    maximized:
        Open maximized (GLFW ``MAXIMIZED`` hint; the window manager decides, ``size`` is the size it
        returns to). The participant window opens so: the figures get the whole screen but the title bar.
    vsync:
        Swap at the display's refresh rate (``swap_interval(1)``).
    resizable, visible:
        GLFW window hints; tests use ``visible=False`` where a mapped window is not needed.

    Drawing goes to :attr:`fbo` (the default framebuffer) with the size :attr:`framebuffer_size`, which
    differs from the window size on HiDPI screens (:attr:`content_scale`). Register
    ``on_framebuffer_size(callback)`` to learn about resizes and ``on_key(callback)`` for keys; the raw
    GLFW handle is :attr:`handle` (for ImGui's GLFW backend).
    """

    def __init__(self, size: tuple[int, int] = (1280, 720), *, fullscreen: bool = False, vsync: bool = True,
                 resizable: bool = True, visible: bool = True, title: str = WINDOW_TITLE,
                 maximized: bool = False) -> None:
        import glfw

        self._glfw = glfw
        # GLFW reports why it failed as a Python warning; fold it into the one error the user sees
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            ok = glfw.init()
        if not ok:
            why = "; ".join(str(w.message) for w in caught) or "no display?"
            raise ContextError(f"cannot open a window ({why}): run on a desktop, set DISPLAY, or use Xvfb")
        glfw.default_window_hints()
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, glfw.TRUE)  # required on macOS, harmless elsewhere
        glfw.window_hint(glfw.RESIZABLE, glfw.TRUE if resizable else glfw.FALSE)
        glfw.window_hint(glfw.VISIBLE, glfw.TRUE if visible else glfw.FALSE)
        glfw.window_hint(glfw.SCALE_TO_MONITOR, glfw.TRUE)
        glfw.window_hint(glfw.MAXIMIZED, glfw.TRUE if maximized and not fullscreen else glfw.FALSE)
        monitor = glfw.get_primary_monitor() if fullscreen else None
        w, h = int(size[0]), int(size[1])
        if monitor:
            mode = glfw.get_video_mode(monitor)
            w, h = mode.size.width, mode.size.height
            glfw.window_hint(glfw.REFRESH_RATE, mode.refresh_rate)
        self.handle = glfw.create_window(w, h, title, monitor, None)
        if not self.handle:
            raise ContextError("GLFW could not open an OpenGL 3.3 core window (driver too old or no display)")
        glfw.make_context_current(self.handle)
        glfw.swap_interval(1 if vsync else 0)
        self.ctx = moderngl.create_context(require=330)
        self.fbo = self.ctx.detect_framebuffer()
        self._windowed_geometry = (100, 100, w, h)
        self._size_callbacks: list[Callable[[int, int], None]] = []
        self._key_callbacks: list[Callable[[int, int, int, int], None]] = []
        glfw.set_framebuffer_size_callback(self.handle, self._on_fb_size)
        glfw.set_key_callback(self.handle, self._on_key)

    # -- events ---------------------------------------------------------------------------------
    def _on_fb_size(self, _win, width: int, height: int) -> None:
        self.fbo = self.ctx.detect_framebuffer()
        for cb in list(self._size_callbacks):
            cb(width, height)

    def _on_key(self, _win, key: int, scancode: int, action: int, mods: int) -> None:
        for cb in list(self._key_callbacks):
            cb(key, scancode, action, mods)

    def on_framebuffer_size(self, callback: Callable[[int, int], None]) -> None:
        """Call ``callback(width, height)`` (pixels) whenever the framebuffer is resized."""
        self._size_callbacks.append(callback)

    def on_key(self, callback: Callable[[int, int, int, int], None]) -> None:
        """Call ``callback(key, scancode, action, mods)`` (GLFW constants) on key events."""
        self._key_callbacks.append(callback)

    def poll_events(self) -> None:
        self._glfw.poll_events()

    # -- state ----------------------------------------------------------------------------------
    @property
    def framebuffer_size(self) -> tuple[int, int]:
        w, h = self._glfw.get_framebuffer_size(self.handle)
        return int(w), int(h)

    @property
    def window_size(self) -> tuple[int, int]:
        w, h = self._glfw.get_window_size(self.handle)
        return int(w), int(h)

    @property
    def content_scale(self) -> tuple[float, float]:
        """Ratio of pixels to screen coordinates requested by the OS (UI scaling, HiDPI)."""
        sx, sy = self._glfw.get_window_content_scale(self.handle)
        return float(sx), float(sy)

    @property
    def should_close(self) -> bool:
        return bool(self._glfw.window_should_close(self.handle))

    def request_close(self) -> None:
        self._glfw.set_window_should_close(self.handle, True)

    @property
    def is_fullscreen(self) -> bool:
        # pyGLFW returns a NULL monitor pointer (falsy, never None) for a windowed window
        return bool(self._glfw.get_window_monitor(self.handle))

    def set_fullscreen(self, on: bool) -> None:
        """Switch between fullscreen on the primary monitor and the last windowed geometry."""
        glfw = self._glfw
        if on == self.is_fullscreen:
            return
        if on:
            x, y = glfw.get_window_pos(self.handle)
            w, h = glfw.get_window_size(self.handle)
            self._windowed_geometry = (x, y, w, h)
            monitor = glfw.get_primary_monitor()
            mode = glfw.get_video_mode(monitor)
            glfw.set_window_monitor(self.handle, monitor, 0, 0, mode.size.width, mode.size.height,
                                    mode.refresh_rate)
        else:
            x, y, w, h = self._windowed_geometry
            glfw.set_window_monitor(self.handle, None, x, y, w, h, 0)

    def use(self) -> None:
        """Make this window's context current and bind its framebuffer (before drawing)."""
        self._glfw.make_context_current(self.handle)
        self.fbo.use()

    def swap_buffers(self) -> None:
        self._glfw.swap_buffers(self.handle)

    def read_rgb(self) -> np.ndarray:
        """The back buffer as ``(H, W, 3) uint8``, top row first (call before :meth:`swap_buffers`)."""
        w, h = self.framebuffer_size
        data = self.fbo.read(viewport=(0, 0, w, h), components=3, alignment=1)
        return np.frombuffer(data, dtype=np.uint8).reshape(h, w, 3)[::-1].copy()

    def close(self) -> None:
        if self.handle is not None:
            self._glfw.destroy_window(self.handle)
            self.handle = None

    def __enter__(self) -> "Window":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
