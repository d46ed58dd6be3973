"""Pinhole camera with OpenCV distortion as a Warp struct, and the projection every kernel uses.

World-to-camera: ``X_c = R X_w + t`` (metres, OpenCV axes: x right, y down, z forward). Distortion follows
OpenCV's model with (k1, k2, p1, p2, k3), so ``project`` agrees with ``cv2.projectPoints``.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

MIN_DEPTH = wp.constant(1.0e-6)


@wp.struct
class Camera:
    """One calibrated camera (a rig is a ``wp.array(dtype=Camera)``)."""

    R: wp.mat33  # world-to-camera rotation
    t: wp.vec3  # world-to-camera translation, metres
    f: wp.vec2  # focal lengths (fx, fy), pixels
    c: wp.vec2  # principal point (cx, cy), pixels
    k: wp.vec3  # radial distortion (k1, k2, k3)
    p: wp.vec2  # tangential distortion (p1, p2)
    r2_max: float  # squared normalised radius beyond which the distortion polynomial folds back: "not seen"
    width: int  # image width, pixels
    height: int  # image height, pixels
    pixel_offset: int  # start of this camera's image in flat per-frame pixel buffers (pixels)
    integral_offset: int  # start of this camera's (H+1) x (W+1) integral image in flat buffers


CAMERA_SET_SIZE = wp.constant(8)
"""Most cameras a :class:`CameraSet` holds."""


@wp.struct
class CameraSet:
    """Up to ``CAMERA_SET_SIZE`` cameras by value: a kernel argument of this type lives in the launch's constant
    parameter memory, so every thread reads the camera parameters as constants instead of loading them from a
    ``wp.array(dtype=Camera)`` for every particle and camera (the compiler cannot hoist those loads out of a particle
    loop that also stores). Cameras ``c0 .. c{count-1}`` are used; ``count = 0`` means "use the array instead" (rigs of
    more than ``CAMERA_SET_SIZE`` cameras)."""

    count: int
    c0: Camera
    c1: Camera
    c2: Camera
    c3: Camera
    c4: Camera
    c5: Camera
    c6: Camera
    c7: Camera


@wp.func
def project(cam: Camera, x: wp.vec3):
    """Project a world point into the image.

    Returns ``vec3(u, v, depth)`` in pixels and metres. ``depth <= 0`` means the point is not seen: behind
    the camera, or so far off-axis that OpenCV's distortion polynomial would fold it back into the image.
    """
    xc = cam.R * x + cam.t
    z = xc[2]
    if z <= MIN_DEPTH:
        return wp.vec3(0.0, 0.0, -1.0)
    a = xc[0] / z
    b = xc[1] / z
    r2 = a * a + b * b
    if r2 > cam.r2_max:
        return wp.vec3(0.0, 0.0, -1.0)
    radial = 1.0 + r2 * (cam.k[0] + r2 * (cam.k[1] + r2 * cam.k[2]))
    ad = a * radial + 2.0 * cam.p[0] * a * b + cam.p[1] * (r2 + 2.0 * a * a)
    bd = b * radial + cam.p[0] * (r2 + 2.0 * b * b) + 2.0 * cam.p[1] * a * b
    return wp.vec3(cam.f[0] * ad + cam.c[0], cam.f[1] * bd + cam.c[1], z)


@wp.func
def pixel_of(uv: float):
    """Index of the pixel whose centre is nearest to image coordinate ``uv`` (pixel centres at integers)."""
    return int(wp.floor(uv + 0.5))


@wp.func
def pixel_index(cam: Camera, x: wp.vec3):
    """Index in flat per-frame pixel buffers (``cam.pixel_offset + row * width + column``) of the pixel whose centre
    is nearest to the projection of world point ``x``, or -1 when the camera does not see it (behind it, or outside
    the image)."""
    uvz = project(cam, x)
    if uvz[2] <= 0.0:
        return -1
    px = pixel_of(uvz[0])
    py = pixel_of(uvz[1])
    if px < 0 or py < 0 or px >= cam.width or py >= cam.height:
        return -1
    return cam.pixel_offset + py * cam.width + px
