"""Lazy, display-free PyVista import shared by every renderer of the report.

On a machine with no display (no ``DISPLAY``/``WAYLAND_DISPLAY``), VTK's runtime window selection would first try
X11 and log a warning before falling back to EGL; we pick the off-screen back end up front instead (EGL when
``libEGL`` is present, else OSMesa), unless the user chose one with ``VTK_DEFAULT_OPENGL_WINDOW``. No X server
or xvfb is needed.
"""

from __future__ import annotations

import ctypes.util
import logging
import os
from typing import Any

from wptrack.core.errors import ConfigError

log = logging.getLogger(__name__)

_WINDOW_ENV = "VTK_DEFAULT_OPENGL_WINDOW"


def choose_backend() -> str | None:
    """Set ``VTK_DEFAULT_OPENGL_WINDOW`` for a display-less machine (idempotent); return the chosen class name.

    Returns:
        The render-window class requested (e.g. ``"vtkEGLRenderWindow"``), or None when VTK is left to choose
        (a display is present, or the variable was already set).
    """
    if os.environ.get(_WINDOW_ENV):
        return os.environ[_WINDOW_ENV]
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return None
    if ctypes.util.find_library("EGL"):
        choice = "vtkEGLRenderWindow"
    elif ctypes.util.find_library("OSMesa"):
        choice = "vtkOSMesaRenderWindow"
    else:
        return None
    os.environ[_WINDOW_ENV] = choice
    log.debug("no display: VTK renders off-screen with %s", choice)
    return choice


def import_pyvista() -> Any:
    """Import PyVista for off-screen rendering.

    Returns:
        The ``pyvista`` module.

    Raises:
        ConfigError: PyVista (or VTK) is not installed.
    """
    choose_backend()
    try:
        import pyvista
    except ImportError as e:  # pragma: no cover - pyvista is a dependency, absent on some GPU boxes
        raise ConfigError(f"rendered reports need pyvista and vtk (pip install pyvista): {e}") from None
    return pyvista


def new_plotter(width: int, height: int, background: str = "white", multi_samples: int = 0) -> Any:
    """An off-screen ``pyvista.Plotter`` of ``width`` x ``height`` pixels.

    ``multi_samples`` > 0 turns on multisample anti-aliasing: nicer stills, but several times slower per frame
    with a software renderer (Mesa llvmpipe), so the movie renders without it.

    Close it with ``plotter.close()`` when done.
    """
    pv = import_pyvista()
    plotter = pv.Plotter(off_screen=True, window_size=(int(width), int(height)), lighting="light kit")
    plotter.render_window.SetMultiSamples(int(multi_samples))
    plotter.set_background(background)
    plotter.theme.allow_empty_mesh = True  # this plotter's copy of the theme: dynamic meshes start empty
    return plotter


def renderer_info(plotter: Any) -> str:
    """Short description of the render window in use, e.g. ``vtkEGLRenderWindow``."""
    try:
        return str(plotter.render_window.GetClassName())
    except Exception:  # pragma: no cover - defensive: only used for the report header
        return "unknown"
