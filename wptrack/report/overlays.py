"""Per-camera overlays on the real frames (S1 paper, Fig. 3): each particle projected through the calibrated
camera (distortion included, ``cv2.projectPoints``) and drawn as a dot coloured by weight, the estimate (orange
cross) and the ground truth (green circle)."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import numpy as np

from wptrack.io.atomic import atomic_imwrite
from wptrack.report.data import RunData
from wptrack.report.model import Figure, ReportContext, Section
from wptrack.report.scene3d import TRUTH_RGB, estimate_rgb, frames_for

log = logging.getLogger(__name__)

LABEL_HEIGHT = 22
"""Height of the label bar above each camera's image in a composite, pixels."""


def weight_colors(weights: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 BGR viridis colours of weights relative to their maximum."""
    import cv2

    w = np.asarray(weights, dtype=np.float64)
    wmax = float(np.max(w)) if len(w) and np.max(w) > 0 else 1.0
    levels = np.clip(np.round(255.0 * w / wmax), 0, 255).astype(np.uint8)
    return cv2.applyColorMap(levels.reshape(-1, 1), cv2.COLORMAP_VIRIDIS).reshape(-1, 3)


def _bgr(rgb: Sequence[int]) -> tuple[int, int, int]:
    return (int(rgb[2]), int(rgb[1]), int(rgb[0]))


def draw_overlay(
    image: np.ndarray,
    camera: Any,
    particles: np.ndarray | None,
    weights: np.ndarray | None,
    estimates: Sequence[np.ndarray] = (),
    truths: Sequence[np.ndarray] = (),
    scale: int = 2,
) -> np.ndarray:
    """Draw projected particles, estimates and ground truth on a frame.

    Args:
        image: (H, W, 3) uint8 BGR frame of ``camera``.
        camera: Rig camera.
        particles: (N, 3) world points or None.
        weights: (N,) weights or None.
        estimates: (3,) estimated positions (drawn as crosses in the estimate palette).
        truths: (3,) ground-truth positions (green circles).
        scale: The frame is upscaled by this integer factor first (pixel ``(u, v)`` is drawn at
            ``(scale u + (scale - 1) / 2, ...)``, the centre of the enlarged pixel).

    Returns:
        A new (scale H, scale W, 3) uint8 BGR image.
    """
    import cv2

    s = max(1, int(scale))
    out = cv2.resize(image, (image.shape[1] * s, image.shape[0] * s), interpolation=cv2.INTER_NEAREST)
    shift = 4  # sub-pixel drawing: coordinates in 1/16 pixel

    def to_px(uv: np.ndarray) -> np.ndarray:
        return np.round((uv * s + (s - 1) / 2.0) * (1 << shift)).astype(np.int64)

    def visible(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        uv, depth = camera.project(points)
        ok = (depth > 0) & np.all(np.isfinite(uv), axis=1)
        ok &= (uv[:, 0] > -1) & (uv[:, 0] < camera.width) & (uv[:, 1] > -1) & (uv[:, 1] < camera.height)
        return uv, ok

    if particles is not None and len(particles):
        w = weights if weights is not None else np.ones(len(particles))
        uv, ok = visible(np.asarray(particles, dtype=np.float64))
        colors = weight_colors(w)
        order = np.argsort(w, kind="stable")  # heaviest drawn last, on top
        px = to_px(uv)
        for i in order:
            if ok[i]:
                c = colors[i]
                cv2.circle(
                    out,
                    (int(px[i, 0]), int(px[i, 1])),
                    2 << shift,
                    (int(c[0]), int(c[1]), int(c[2])),
                    -1,
                    cv2.LINE_AA,
                    shift,
                )
    for p in truths:
        uv, ok = visible(np.asarray(p, dtype=np.float64).reshape(1, 3))
        if ok[0]:
            c = to_px(uv)[0]
            cv2.circle(out, (int(c[0]), int(c[1])), 7 << shift, _bgr(TRUTH_RGB), 2, cv2.LINE_AA, shift)
    for k, p in enumerate(estimates):
        uv, ok = visible(np.asarray(p, dtype=np.float64).reshape(1, 3))
        if ok[0]:
            c = to_px(uv)[0]
            r = 6 << shift
            col = _bgr(estimate_rgb(k))
            cv2.line(out, (int(c[0] - r), int(c[1])), (int(c[0] + r), int(c[1])), col, 2, cv2.LINE_AA, shift)
            cv2.line(out, (int(c[0]), int(c[1] - r)), (int(c[0]), int(c[1] + r)), col, 2, cv2.LINE_AA, shift)
    return out


def compose(images: Sequence[np.ndarray], labels: Sequence[str], gap: int = 6) -> tuple[np.ndarray, list[tuple]]:
    """Place images side by side (top-aligned) under label bars on a white canvas.

    Returns:
        The canvas and each image's ``(x0, y0)`` offset in it.
    """
    import cv2

    height = max(im.shape[0] for im in images) + LABEL_HEIGHT
    width = sum(im.shape[1] for im in images) + gap * (len(images) - 1)
    canvas = np.full((height, width, 3), 255, np.uint8)
    offsets = []
    x = 0
    for im, label in zip(images, labels, strict=True):
        canvas[LABEL_HEIGHT : LABEL_HEIGHT + im.shape[0], x : x + im.shape[1]] = im
        cv2.putText(canvas, label, (x + 4, LABEL_HEIGHT - 7), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        offsets.append((x, LABEL_HEIGHT))
        x += im.shape[1] + gap
    return canvas, offsets


def section_overlays(ctx: ReportContext) -> Section | None:
    """One composite image per chosen frame: every camera's frame with the particles projected on it."""
    data = ctx.data
    if data is None:
        return None
    sec = Section(
        "overlays",
        "Particles on the camera frames",
        text=(
            "Each particle projected into each camera through the calibration (lens distortion included), "
            "coloured by weight (viridis: yellow = heaviest); orange cross: the estimate (weighted mean); "
            "green circle: the ground truth."
        ),
    )
    if data.rig is None:
        sec.notes.append("no rig: overlays are left out")
        return sec
    if not data.videos:
        sec.notes.append("video frames not found: overlays are left out")
        return sec
    with ctx.timed("overlays"):
        sec.figures.extend(render_overlays(ctx, data))
    missing = [f for f in ctx.frames if f"overlay_frame{f:05d}.png" not in {fig.path for fig in sec.figures}]
    if missing:
        sec.notes.append(f"frames {missing} are beyond the end of the videos: left out")
    return sec


def render_overlays(ctx: ReportContext, data: RunData) -> list[Figure]:
    """Write ``overlay_frameNNNNN.png`` for each chosen frame; returns the figures."""

    frames = frames_for(ctx, data)
    figs = []
    for f in ctx.frames:
        images = frames.get(f)
        if images is None:
            continue
        pos = wt = None
        if data.particles is not None:
            pos, wt = data.particles.cloud(f)
        ests = [t.at(np.array([f]))[0] for t in data.estimates.values()]
        truths = [t.at(np.array([f]))[0] for t in (data.groundtruth or {}).values()]
        drawn = [
            draw_overlay(im, cam, pos, wt, ests, truths, scale=ctx.options.overlay_scale)
            for cam, im in zip(data.rig.cameras, images, strict=False)
        ]
        labels = [f"{cam.name}  frame {f}" for cam in data.rig.cameras][: len(drawn)]
        canvas, _ = compose(drawn, labels)
        path = ctx.out_dir / f"overlay_frame{f:05d}.png"
        atomic_imwrite(path, canvas)
        figs.append(
            Figure(
                path.name,
                f"Frame {f}: particles projected into each camera (dots coloured by weight, viridis: yellow = "
                "heaviest), the estimate (orange cross) and the ground truth (green circle)",
                wide=True,
            )
        )
    return figs
