"""Dear ImGui inside a moderngl context: one context, fonts, theme, scaling and the GL backend.

The UI works in framebuffer pixels (``io.display_size`` = framebuffer size, framebuffer scale 1) and
scales itself: :func:`ui_scale` grows with the framebuffer height (the layout is designed at 1280x720)
and never drops below the monitor's content scale, so text is equally readable in a 720p window, on
a 4K monitor in fullscreen and on a HiDPI laptop. ImGui 1.92 rasterizes fonts at the size they are
drawn, so large text stays sharp.

Rendering uses imgui-bundle's compiled OpenGL3 backend, which draws into whatever framebuffer is
bound (the window's, or an FBO offscreen) and restores the GL state it touches.

``extra_font``: a system font merged into both UI fonts for the characters Roboto lacks (a design in
Chinese; see :mod:`studyapp.study.design.fonts`). ImGui 1.92 loads glyphs as they are first drawn, so
only the characters the texts use are rasterised, from Roboto when it has them, else from this font.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import moderngl

#: Font size in pixels at scale 1 (a 1280x720 framebuffer).
BASE_FONT_PX = 19.0
#: Height the layout is designed for.
DESIGN_HEIGHT = 720.0


def ui_scale(framebuffer_size: tuple[int, int], content_scale: float = 1.0) -> float:
    """UI scale factor for a framebuffer (pixels) on a monitor with the given content scale.

    >>> ui_scale((1280, 720)), ui_scale((3840, 2160)), ui_scale((1280, 720), 2.0)
    (1.0, 3.0, 2.0)
    >>> ui_scale((640, 360))   # small windows keep the monitor's text size (legible, may scroll)
    1.0
    """
    w, h = framebuffer_size
    by_height = min(h / DESIGN_HEIGHT, w / (DESIGN_HEIGHT * 16 / 9) * 1.15)
    return round(max(by_height, float(content_scale), 0.8), 3)


def _font_dir() -> Path:
    import imgui_bundle

    return Path(imgui_bundle.__file__).resolve().parent / "assets" / "fonts"


# Calm, high-contrast palette; nothing in it differs between slots.
_COLORS = {
    "window_bg": (0.13, 0.14, 0.16, 0.96),
    "child_bg": (0.17, 0.18, 0.21, 1.0),
    "popup_bg": (0.13, 0.14, 0.16, 0.98),
    "border": (0.32, 0.34, 0.40, 1.0),
    "text": (0.94, 0.95, 0.97, 1.0),
    "text_disabled": (0.58, 0.60, 0.65, 1.0),
    "button": (0.22, 0.40, 0.68, 1.0),
    "button_hovered": (0.28, 0.48, 0.80, 1.0),
    "button_active": (0.18, 0.34, 0.60, 1.0),
    "frame_bg": (0.22, 0.23, 0.27, 1.0),
    "frame_bg_hovered": (0.28, 0.30, 0.35, 1.0),
    "frame_bg_active": (0.30, 0.33, 0.40, 1.0),
    "check_mark": (0.55, 0.78, 1.0, 1.0),
    "separator": (0.32, 0.34, 0.40, 1.0),
    "drag_drop_target": (1.0, 0.80, 0.25, 1.0),
    "plot_histogram": (0.35, 0.70, 0.45, 1.0),
    "scrollbar_bg": (0.10, 0.11, 0.13, 1.0),
    "scrollbar_grab": (0.46, 0.49, 0.56, 1.0),
    "scrollbar_grab_hovered": (0.58, 0.62, 0.70, 1.0),
    "scrollbar_grab_active": (0.66, 0.70, 0.78, 1.0),
}


class ImGuiLayer:
    """Owns the ImGui context and its OpenGL3 renderer for one moderngl context.

    Call :meth:`new_frame` (after feeding input), build the UI with imgui calls, then
    :meth:`render` with the target framebuffer bound.
    """

    def __init__(self, ctx: moderngl.Context, extra_font: Path | None = None) -> None:
        from imgui_bundle import imgui

        self.ctx = ctx
        self.imgui = imgui
        self.context = imgui.create_context()
        imgui.set_current_context(self.context)
        io = imgui.get_io()
        io.set_ini_filename(None)  # never write imgui.ini next to the participant's files
        io.config_windows_move_from_title_bar_only = True
        io.config_input_trickle_event_queue = True  # a click's press and release land in separate frames
        fonts = io.fonts
        regular = _font_dir() / "Roboto" / "Roboto-Regular.ttf"
        bold = _font_dir() / "Roboto" / "Roboto-Bold.ttf"
        self.font = fonts.add_font_from_file_ttf(str(regular), BASE_FONT_PX)
        if extra_font is not None:
            self._merge(extra_font)
        self.font_bold = fonts.add_font_from_file_ttf(str(bold), BASE_FONT_PX)
        if extra_font is not None:
            self._merge(extra_font)
        self.extra_font = extra_font
        self.scale = 0.0
        self._apply_style(1.0)
        imgui.backends.opengl3_init("#version 330")
        self._time = 0.0

    def _merge(self, path: Path) -> None:
        """Merge ``path`` into the font added last: its glyphs fill in the characters that one lacks."""
        cfg = self.imgui.ImFontConfig()
        cfg.merge_mode = True
        cfg.font_no = 0  # the first face of a collection (.ttc)
        self.imgui.get_io().fonts.add_font_from_file_ttf(str(path), BASE_FONT_PX, cfg)

    def _apply_style(self, scale: float) -> None:
        imgui = self.imgui
        style = imgui.get_style()
        imgui.style_colors_dark(style)
        # Reset sizes to the defaults, then scale once: scale_all_sizes multiplies the current values.
        defaults = imgui.Style()
        for name in ("window_padding", "frame_padding", "item_spacing", "item_inner_spacing",
                     "cell_padding", "touch_extra_padding", "indent_spacing", "scrollbar_size",
                     "grab_min_size", "window_rounding", "frame_rounding", "child_rounding",
                     "popup_rounding", "grab_rounding", "scrollbar_rounding", "window_border_size",
                     "frame_border_size", "child_border_size"):
            setattr(style, name, getattr(defaults, name))
        style.window_padding = (16, 14)
        style.frame_padding = (12, 7)
        style.item_spacing = (10, 9)
        style.frame_rounding = 6.0
        style.window_rounding = 8.0
        style.child_rounding = 6.0
        style.grab_rounding = 4.0
        style.scrollbar_size = 18.0
        style.frame_border_size = 1.0
        style.scale_all_sizes(scale)
        style.font_size_base = BASE_FONT_PX
        style.font_scale_main = scale
        for name, rgba in _COLORS.items():
            idx = getattr(imgui.Col_, name)
            style.set_color_(idx, imgui.ImVec4(*rgba))
        self.scale = scale

    def new_frame(self, framebuffer_size: tuple[int, int], dt: float, content_scale: float = 1.0) -> None:
        imgui = self.imgui
        imgui.set_current_context(self.context)
        scale = ui_scale(framebuffer_size, content_scale)
        if abs(scale - self.scale) > 0.01:
            self._apply_style(scale)
        io = imgui.get_io()
        io.display_size = (float(framebuffer_size[0]), float(framebuffer_size[1]))
        io.display_framebuffer_scale = (1.0, 1.0)
        io.delta_time = max(float(dt), 1e-4)
        imgui.backends.opengl3_new_frame()
        imgui.new_frame()

    @property
    def io(self) -> Any:
        return self.imgui.get_io()

    def render(self, viewport_size: tuple[int, int]) -> None:
        """Finish the frame and draw it into the currently bound framebuffer."""
        imgui = self.imgui
        imgui.render()
        self.ctx.viewport = (0, 0, int(viewport_size[0]), int(viewport_size[1]))
        imgui.backends.opengl3_render_draw_data(imgui.get_draw_data())

    def shutdown(self) -> None:
        imgui = self.imgui
        if self.context is not None:
            imgui.set_current_context(self.context)
            imgui.backends.opengl3_shutdown()
            imgui.destroy_context(self.context)
            self.context = None
