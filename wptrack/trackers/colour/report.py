"""The report of the S1 colour particle filter (``tracker: color`` in run.json)."""

from __future__ import annotations

from wptrack.report import overlays, plots, scene3d, scene_movie
from wptrack.report.model import register_reporter

COLOR_SECTIONS = (
    scene3d.section_scene,
    overlays.section_overlays,
    plots.section_birdseye,
    plots.section_errors,
    scene_movie.section_movie,
    plots.section_timings,
)
"""Section builders of the colour tracker's report, in page order."""

register_reporter("color", "S1 colour particle filter (Barrera et al.)", COLOR_SECTIONS)
