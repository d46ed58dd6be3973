"""Rig -> device: the ``kernels.core.camera.Camera`` structs of a rig, with offsets into flat per-frame buffers."""

from __future__ import annotations

import numpy as np
import warp as wp

from wptrack.cameras.rig import Camera, Rig
from wptrack.kernels.core.camera import CAMERA_SET_SIZE, CameraSet
from wptrack.kernels.core.camera import Camera as CameraStruct

R2_FOLD_MARGIN = 2.25
"""Points up to 1.5x the normalised radius of the image corners are projected; further ones are 'not seen'."""


def fold_radius2(dist: np.ndarray) -> float:
    """Squared normalised radius where r * (1 + k1 r^2 + k2 r^4 + k3 r^6) stops increasing (inf if never).

    Beyond it OpenCV's radial model folds far off-axis points back into the image; such points are treated
    as not seen. Tangential terms are small and ignored here.
    """
    k1, k2, _p1, _p2, k3 = (float(v) for v in dist)
    r = np.linspace(0.0, 20.0, 40001)
    r2 = r * r
    deriv = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2 + 7.0 * k3 * r2 * r2 * r2
    bad = np.nonzero(deriv <= 0.0)[0]
    return float(r2[bad[0]]) if bad.size else float("inf")


def corner_radius2(cam: Camera) -> float:
    """Largest squared normalised radius of the (undistorted) image corners and edge midpoints."""
    import cv2

    w, h = cam.width, cam.height
    pts = np.array(
        [
            [0, 0],
            [w - 1, 0],
            [0, h - 1],
            [w - 1, h - 1],
            [(w - 1) / 2, 0],
            [(w - 1) / 2, h - 1],
            [0, (h - 1) / 2],
            [w - 1, (h - 1) / 2],
        ],
        dtype=np.float64,
    ).reshape(-1, 1, 2)
    und = cv2.undistortPoints(pts, cam.K, cam.dist).reshape(-1, 2)
    return float(np.max(np.sum(und * und, axis=1)))


def camera_struct(cam: Camera, pixel_offset: int = 0, integral_offset: int = 0) -> CameraStruct:
    """One rig camera as the kernels' struct."""
    s = CameraStruct()
    s.R = wp.mat33(*cam.R.astype(np.float32).ravel())
    s.t = wp.vec3(*cam.t.astype(np.float32))
    s.f = wp.vec2(cam.fx, cam.fy)
    s.c = wp.vec2(cam.cx, cam.cy)
    k1, k2, p1, p2, k3 = (float(v) for v in cam.dist)
    s.k = wp.vec3(k1, k2, k3)
    s.p = wp.vec2(p1, p2)
    s.r2_max = float(min(R2_FOLD_MARGIN * corner_radius2(cam), fold_radius2(cam.dist), 1.0e6))
    s.width = int(cam.width)
    s.height = int(cam.height)
    s.pixel_offset = int(pixel_offset)
    s.integral_offset = int(integral_offset)
    return s


def camera_set(structs: list[CameraStruct]) -> CameraSet:
    """The cameras by value for kernels that read them as constants (``kernels.core.camera.CameraSet``); ``count`` is 0
    (the kernels then read the camera array) when there are more than ``CAMERA_SET_SIZE`` of them."""
    s = CameraSet()
    size = int(CAMERA_SET_SIZE)
    s.count = len(structs) if len(structs) <= size else 0
    for k in range(size):
        setattr(s, f"c{k}", structs[k] if s.count and k < len(structs) else CameraStruct())
    return s


class DeviceRig:
    """A rig on a device, with its cameras' images laid out back to back in flat buffers.

    Attributes:
        cams: (M,) ``wp.array`` of camera structs.
        cam_set: the same cameras by value (``kernels.core.camera.CameraSet``; ``count`` 0 beyond 8 cameras).
        pixel_offsets: (M + 1,) start of each camera's image in flat pixel buffers (last = total pixels).
        integral_offsets: (M + 1,) start of each (H+1) x (W+1) integral image (last = total size).
        max_pixels, max_width, max_height: launch bounds over cameras.
    """

    def __init__(self, rig: Rig, device: str) -> None:
        self.rig = rig
        sizes = [(c.width, c.height) for c in rig.cameras]
        self.pixel_offsets = np.concatenate([[0], np.cumsum([w * h for w, h in sizes])]).astype(np.int64)
        self.integral_offsets = np.concatenate([[0], np.cumsum([(w + 1) * (h + 1) for w, h in sizes])]).astype(np.int64)
        structs = [
            camera_struct(c, int(self.pixel_offsets[i]), int(self.integral_offsets[i]))
            for i, c in enumerate(rig.cameras)
        ]
        self.cams = wp.array(structs, dtype=CameraStruct, device=device)
        self.cam_set = camera_set(structs)
        self.total_pixels = int(self.pixel_offsets[-1])
        self.total_integral = int(self.integral_offsets[-1])
        self.max_pixels = max(w * h for w, h in sizes)
        self.max_width = max(w for w, _ in sizes)
        self.max_height = max(h for _, h in sizes)
        self.num_cameras = len(sizes)


class ColourMaps:
    """Per-frame colour maps of a rig on a device, built by kernels from the uploaded BGR frames.

    Two forms, chosen at construction:
    - ``window=False`` (integral scoring): the target mask and its integral image per camera (four parallel
      segmented-scan passes).
    - ``window=True`` (map scoring): the target mask and the 5x5 window-count map (one byte per pixel). On a GPU
      two per-pixel launches (mask, then 25 cached mask reads per pixel); on the CPU, where a Warp kernel runs on one
      core, two sliding-sum launches (mask and horizontal sums per row, then vertical sums per column).

    Buffers (flat over cameras, allocated once):
        mask: (sum W*H,) uint8, 1 where the pixel matches the target.
        integral: (sum (W+1)*(H+1),) int32 integral images (row 0 and column 0 zero); integral form only.
        window: (sum W*H,) uint8 target pixels in the 5x5 window around each pixel; window form only.
        hsum: (sum W*H,) uint8 horizontal 5-pixel sums of the mask; window form on the CPU only.
    """

    def __init__(self, drig: DeviceRig, device: str, window: bool = False) -> None:
        from wptrack.kernels.colour import hsi as kcolour

        self.k = kcolour
        self.drig = drig
        self.device = device
        self.has_window = window
        self.by_rows = window and wp.get_device(device).is_cpu
        seg = int(kcolour.SEGMENT)
        m = drig.num_cameras
        self.mask = wp.zeros(drig.total_pixels, dtype=wp.uint8, device=device)
        self.row_segments = (drig.max_width + seg - 1) // seg
        self.col_segments = (drig.max_height + seg - 1) // seg
        if window:
            self.integral = wp.zeros(1, dtype=wp.int32, device=device)
            self.window = wp.zeros(drig.total_pixels, dtype=wp.uint8, device=device)
        else:
            self.integral = wp.zeros(drig.total_integral, dtype=wp.int32, device=device)
            self.window = wp.zeros(1, dtype=wp.uint8, device=device)
            self.row_seg = wp.zeros((m, drig.max_height, self.row_segments), dtype=wp.int32, device=device)
            self.col_seg = wp.zeros((m, drig.max_width + 1, self.col_segments), dtype=wp.int32, device=device)
        self.hsum = wp.zeros(drig.total_pixels if self.by_rows else 1, dtype=wp.uint8, device=device)

    def launch(self, target, bgr: wp.array) -> None:
        """Build the maps of the current frame (``target``: a ``kernels.colour.hsi.ColourTarget`` struct)."""
        k, dr, d = self.k, self.drig, self.device
        m = dr.num_cameras
        if self.by_rows:
            rows = (m, dr.max_height)
            wp.launch(
                k.mask_rows_kernel, dim=rows, inputs=[dr.cams, target, bgr], outputs=[self.mask, self.hsum], device=d
            )
            cols = (m, dr.max_width)
            wp.launch(k.window_cols_kernel, dim=cols, inputs=[dr.cams, self.hsum], outputs=[self.window], device=d)
            return
        if self.has_window:  # mask and window map in one pass (warp shuffles: CUDA only)
            strips = (dr.max_height + int(k.WINDOW_STRIP) - 1) // int(k.WINDOW_STRIP)
            cols = 32 * ((dr.max_width + int(k.WARP_COLUMNS) - 1) // int(k.WARP_COLUMNS))
            wp.launch(
                k.observe_map_kernel,
                dim=(m, strips, cols),
                inputs=[dr.cams, target, bgr],
                outputs=[self.mask, self.window],
                device=d,
            )
            return
        wp.launch(
            k.target_mask_kernel,
            dim=(dr.total_pixels + int(k.MASK_PIXELS_PER_THREAD) - 1) // int(k.MASK_PIXELS_PER_THREAD),
            inputs=[target, bgr, dr.total_pixels],
            outputs=[self.mask],
            device=d,
        )
        rows = (m, dr.max_height, self.row_segments)
        cols = (m, dr.max_width + 1, self.col_segments)
        wp.launch(k.row_segment_sums_kernel, dim=rows, inputs=[dr.cams, self.mask], outputs=[self.row_seg], device=d)
        wp.launch(
            k.row_scan_kernel, dim=rows, inputs=[dr.cams, self.mask, self.row_seg], outputs=[self.integral], device=d
        )
        wp.launch(
            k.col_segment_sums_kernel, dim=cols, inputs=[dr.cams, self.integral], outputs=[self.col_seg], device=d
        )
        wp.launch(k.col_scan_kernel, dim=cols, inputs=[dr.cams, self.col_seg], outputs=[self.integral], device=d)
