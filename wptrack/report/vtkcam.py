"""The one place where an OpenCV camera becomes a VTK camera.

OpenCV: ``X_cam = R X_world + t``, camera axes x right, y down, z forward; pixel ``(u, v)`` with the origin at the
top-left pixel *centre*; ``u = fx X/Z + cx``, ``v = fy Y/Z + cy`` (before distortion).

VTK: a camera position, a focal point along the viewing direction, a view-up vector, a vertical view angle and a
window centre (a shift of the projection centre in normalised device coordinates, NDC in [-1, 1]). Pixel ``i`` of
a ``w``-wide window covers NDC ``[2i/w - 1, 2(i+1)/w - 1]``, so the centre of pixel ``u`` is at
``(2u + 1)/w - 1``; rows are counted from the bottom in VTK and from the top in the screenshot.

The mapping (exact for an undistorted pinhole, checked by the tests against ``cv2.projectPoints``):

* position = camera centre ``-R^T t``; focal point = position + ``R^T e_z`` (the camera's +z axis);
* view up = ``-R^T e_y`` (image up is camera -y);
* vertical view angle = ``2 atan(h / (2 fy))``: VTK then uses the horizontal focal length ``fy`` too, and a user
  transform scales NDC x by ``fx / fy`` when they differ;
* window centre = ``((w - 1 - 2 cx) / (w s), (2 cy + 1 - h) / h)`` with ``s = fx / fy``: VTK's frustum centre moves
  by ``+window_centre``, which puts the optical axis at pixel ``(cx, cy)``.

Lens distortion cannot be rendered by VTK: undistort real images (``cv2.undistort``) before compositing a render
over them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from wptrack.cameras.rig import Camera

__all__ = ["VtkCameraParams", "apply_camera", "vtk_camera_params"]


@dataclass(frozen=True)
class VtkCameraParams:
    """VTK camera settings equivalent to an OpenCV pinhole camera (distortion ignored).

    Attributes:
        position: (3,) camera centre, world metres.
        focal_point: (3,) a point on the optical axis ``distance`` metres in front of the camera.
        view_up: (3,) unit world vector pointing to the top of the image.
        view_angle: Vertical view angle, degrees.
        window_center: (2,) VTK window centre (NDC shift of the projection centre).
        x_scale: ``fx / fy``; NDC x is scaled by it (1 for square pixels).
        width: Image width the parameters are for, pixels.
        height: Image height, pixels.
    """

    position: np.ndarray
    focal_point: np.ndarray
    view_up: np.ndarray
    view_angle: float
    window_center: tuple[float, float]
    x_scale: float
    width: int
    height: int


def vtk_camera_params(camera: Camera, distance: float = 1.0) -> VtkCameraParams:
    """Convert an OpenCV camera to VTK camera settings.

    Args:
        camera: Rig camera (its distortion is ignored).
        distance: Distance of the focal point from the camera, metres (any positive value: it only matters for
            VTK's interaction and clipping heuristics).

    Returns:
        The equivalent VTK settings, for a render window of ``camera.width`` x ``camera.height`` pixels.
    """
    R = np.asarray(camera.R, dtype=np.float64)
    position = camera.center
    forward = R[2]  # R^T e_z: the camera's +z axis in world coordinates
    up = -R[1]  # R^T (-e_y)
    w, h = camera.width, camera.height
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    s = fx / fy
    view_angle = math.degrees(2.0 * math.atan(h / (2.0 * fy)))
    window_center = ((w - 1.0 - 2.0 * cx) / (w * s), (2.0 * cy + 1.0 - h) / h)
    return VtkCameraParams(
        position=position,
        focal_point=position + distance * forward,
        view_up=up / np.linalg.norm(up),
        view_angle=view_angle,
        window_center=window_center,
        x_scale=s,
        width=w,
        height=h,
    )


def apply_camera(plotter: Any, camera: Camera, clipping: tuple[float, float] | None = None) -> VtkCameraParams:
    """Make ``plotter`` render exactly what ``camera`` sees (an undistorted pinhole).

    The plotter's window must be ``camera.width`` x ``camera.height`` pixels (use ``camera.scaled(w, h)`` for
    another size). PyVista will not reset this camera on the first render.

    Args:
        plotter: A ``pyvista.Plotter``.
        camera: Rig camera.
        clipping: ``(near, far)`` metres; None fits the clipping range to the visible actors (call again after
            adding actors, or call ``plotter.renderer.ResetCameraClippingRange()``).

    Returns:
        The parameters applied.

    Raises:
        ValueError: The window size differs from the camera's image size.
    """
    size = tuple(int(v) for v in plotter.window_size)
    if size != (camera.width, camera.height):
        raise ValueError(
            f"plotter window is {size[0]}x{size[1]} pixels but camera {camera.name!r} is "
            f"{camera.width}x{camera.height}; use camera.scaled(width, height)"
        )
    import vtk  # noqa: F401  (pyvista is imported by the caller; vtk comes with it)
    from vtkmodules.vtkCommonTransforms import vtkTransform

    p = vtk_camera_params(camera)
    cam = plotter.renderer.GetActiveCamera()
    cam.SetPosition(*p.position)
    cam.SetFocalPoint(*p.focal_point)
    cam.SetViewUp(*p.view_up)
    cam.SetParallelProjection(False)
    cam.SetUseHorizontalViewAngle(False)
    cam.SetViewAngle(p.view_angle)
    cam.SetWindowCenter(*p.window_center)
    if abs(p.x_scale - 1.0) > 1e-12:
        tf = vtkTransform()
        tf.Scale(p.x_scale, 1.0, 1.0)
        cam.SetUserTransform(tf)
    else:
        cam.SetUserTransform(None)
    plotter.renderer.camera_set = True  # keep PyVista from resetting the camera on the first render
    if clipping is not None:
        cam.SetClippingRange(*clipping)
    else:
        plotter.renderer.ResetCameraClippingRange()
    return p
