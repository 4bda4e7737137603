"""The render engine: one Panda3D ``GraphicsEngine`` and pipe, and the choice of renderer.

:class:`RenderEngine` is headless by default. Two offscreen renderers are offered:

- ``software``: Panda3D's ``p3tinydisplay``, a CPU rasteriser. No display and no GPU needed;
  the default wherever there is no GPU.
- ``egl``: Panda3D's ``p3headlessgl``, OpenGL through EGL without a display. On a machine with a
  GPU it draws on the GPU; without one, Mesa answers with a CPU implementation (``llvmpipe``),
  which is slower than ``p3tinydisplay`` on our scenes.

``auto`` (:func:`resolve_renderer`) picks ``egl`` when EGL opens on a GPU, and ``software``
otherwise (an EGL that reports a software implementation does not count). The two renderers
draw the same scene with small differences in texture sampling, so frames differ by a few grey
levels on average: the renderer is part of a run's conditions and is recorded with its results
(:func:`renderer_info`).

Engine options are set when an engine is created, in a config page that is removed again on
``close()``; nothing is set at import and no ``ShowBase`` is used, so several engines can be
created and closed one after the other in one process.
"""

from __future__ import annotations

import functools

import numpy as np

#: Renderer names accepted by :class:`RenderEngine`, ``SimConfig.renderer`` and ``--renderer``.
RENDERERS = ("auto", "software", "egl")
#: The renderer used unless one is asked for.
DEFAULT_RENDERER = "auto"
#: What an OpenGL renderer string contains when no GPU draws (Mesa's CPU drivers).
SOFTWARE_GL_MARKERS = ("llvmpipe", "softpipe", "swrast", "lavapipe", "software")
#: How the software renderer describes itself where a GL renderer string is recorded.
SOFTWARE_DESCRIPTION = "p3tinydisplay (software)"

_ENGINE_OPTIONS = {
    "load-display": "p3tinydisplay",
    "window-type": "offscreen",
    "framebuffer-multisample": "0",
    "multisamples": "0",
    "sync-video": "0",
    "audio-library-name": "null",
    "td-ignore-mipmaps": "0",
    "td-perspective-textures": "1",
    "textures-power-2": "up",
    "notify-level-display": "error",
}
_PIPES = {"software": ("TinyOffscreenGraphicsPipe", "p3tinydisplay"),
          "egl": ("eglGraphicsPipe", "p3headlessgl")}


def check_renderer(name: str) -> str:
    """``name`` if it is one of :data:`RENDERERS`, else ``ValueError``."""
    if name not in RENDERERS:
        raise ValueError(f"unknown renderer {name!r}; use one of {', '.join(RENDERERS)}")
    return name


class RenderEngine:
    """One Panda3D graphics engine and pipe; headless (offscreen) by default.

    ``renderer``: ``"software"``, ``"egl"`` or ``"auto"`` (see the module). ``window=True``
    selects the OpenGL pipe (``pandagl``) for an interactive window; offscreen buffers then come
    from the GPU. ``options`` adds or overrides PRC settings (strings); with ``window=True``,
    ``{"load-display": "p3tinydisplay"}`` gives the software renderer's window (for displays
    without OpenGL).
    """

    def __init__(self, *, window: bool = False, options: dict[str, str] | None = None,
                 renderer: str = DEFAULT_RENDERER):
        from panda3d.core import GraphicsEngine, GraphicsPipeSelection, load_prc_file_data

        self.renderer = "window" if window else resolve_renderer(renderer)
        settings = dict(_ENGINE_OPTIONS)
        if window:
            settings["load-display"] = "pandagl"
            settings["window-type"] = "onscreen"
        elif self.renderer == "egl":
            settings["load-display"] = "p3headlessgl"
        settings.update(options or {})
        text = "\n".join(f"{key} {value}" for key, value in settings.items())
        self._page = load_prc_file_data("clonedrive-render-engine", text)
        selection = GraphicsPipeSelection.get_global_ptr()
        if window:
            pipe = selection.make_module_pipe(settings["load-display"])
        elif self.renderer == "egl":
            pipe = _egl_pipe()
        else:
            pipe = selection.make_pipe(*_PIPES[self.renderer])
        if pipe is None or not pipe.is_valid():
            self._unload()
            kind = f"window ({settings['load-display']})" if window else \
                f"{self.renderer} ({_PIPES[self.renderer][1]})"
            raise RuntimeError(f"could not open a Panda3D {kind} graphics pipe")
        self.window = window
        self.pipe = pipe
        self.engine = GraphicsEngine(pipe)
        self._outputs: list = []
        self.closed = False

    def make_buffer(self, name: str, width: int, height: int):
        """An offscreen RGB buffer of ``width`` x ``height`` copied to RAM after each frame.

        Returns ``(buffer, texture)``; read pixels with :func:`texture_rgb`.
        """
        from panda3d.core import (
            FrameBufferProperties,
            GraphicsOutput,
            GraphicsPipe,
            Texture,
            WindowProperties,
        )

        self._check_open()
        props = FrameBufferProperties()
        props.set_rgb_color(True)
        props.set_color_bits(24)
        props.set_depth_bits(24)
        buffer = self.engine.make_output(
            self.pipe, name, 0, props, WindowProperties.size(width, height),
            GraphicsPipe.BF_refuse_window,
        )
        if buffer is None:
            raise RuntimeError(f"could not create a {width}x{height} offscreen buffer")
        texture = Texture(f"{name}-colour")
        buffer.add_render_texture(texture, GraphicsOutput.RTM_copy_ram)
        self._outputs.append(buffer)
        return buffer, texture

    def gl_renderer(self) -> str:
        """The OpenGL renderer string of this engine's device (after a frame was drawn), or
        :data:`SOFTWARE_DESCRIPTION` for the software renderer."""
        if self.renderer == "software":
            return SOFTWARE_DESCRIPTION
        for output in self._outputs:
            gsg = output.get_gsg()
            if gsg is not None and gsg.get_driver_renderer():
                return str(gsg.get_driver_renderer())
        return ""

    def remove(self, output) -> None:
        if output in self._outputs:
            self._outputs.remove(output)
            self.engine.remove_window(output)

    def render_frame(self) -> None:
        self._check_open()
        self.engine.render_frame()

    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError("the render engine is closed")

    def _unload(self) -> None:
        from panda3d.core import unload_prc_file

        if self._page is not None:
            unload_prc_file(self._page)
            self._page = None

    def close(self) -> None:
        if self.closed:
            return
        self.engine.remove_all_windows()
        self._outputs.clear()
        self.closed = True
        self._unload()


@functools.cache
def _egl_pipe():
    """The process's one EGL pipe, shared by every EGL engine. Destroying an EGL pipe
    terminates the process's EGL display, which breaks every other EGL engine still open, so
    the pipe is made once and kept until the process ends."""
    from panda3d.core import GraphicsPipeSelection

    return GraphicsPipeSelection.get_global_ptr().make_pipe(*_PIPES["egl"])


@functools.cache
def probe_egl() -> str | None:
    """The OpenGL renderer string of Panda3D's EGL pipe (one 8x8 frame drawn to find it), or
    None where EGL does not open. Probed once per process: the answer is the machine's."""
    try:
        engine = RenderEngine(renderer="egl")
    except RuntimeError:
        return None
    try:
        engine.make_buffer("egl-probe", 8, 8)
        engine.render_frame()
        return engine.gl_renderer()
    except RuntimeError:
        return None
    finally:
        engine.close()


def is_software_gl(gl_renderer: str) -> bool:
    """True when an OpenGL renderer string names a CPU implementation (no GPU draws)."""
    text = gl_renderer.lower()
    return any(marker in text for marker in SOFTWARE_GL_MARKERS)


def resolve_renderer(name: str) -> str:
    """``"software"`` or ``"egl"`` for a renderer name: ``auto`` is ``egl`` where EGL opens on a
    GPU (:func:`probe_egl`), else ``software``."""
    check_renderer(name)
    if name != "auto":
        return name
    found = probe_egl()
    return "egl" if found and not is_software_gl(found) else "software"


def renderer_info(name: str) -> dict:
    """What a run records about its renderer: the name asked for, the one used, and the OpenGL
    renderer string of the device that draws (``gl_renderer``)."""
    used = resolve_renderer(name)
    gl = SOFTWARE_DESCRIPTION if used == "software" else (probe_egl() or "")
    return {"renderer": name, "renderer_used": used, "gl_renderer": gl}


def texture_rgb(texture) -> np.ndarray:
    """The RGB image (H, W, 3) uint8 of a render texture, top row first, C-contiguous."""
    import cv2

    width, height = texture.get_x_size(), texture.get_y_size()
    # Panda3D keeps 8-bit colour in RAM as BGR(A), bottom row first. OpenCV swaps the channels
    # and flips the rows in two passes of C code, faster than get_ram_image_as("RGB") plus a
    # NumPy flip, with the same pixels.
    bgr = np.frombuffer(texture.get_ram_image(), dtype=np.uint8).reshape(height, width, -1)
    code = cv2.COLOR_BGR2RGB if bgr.shape[2] == 3 else cv2.COLOR_BGRA2RGB
    return cv2.flip(cv2.cvtColor(bgr, code), 0)
