"""Rendered reports of tracking runs: ``wptrack report RUN_DIR`` / :func:`build_report`.

A report is a folder (default ``RUN_DIR/report``) with PNG images, a movie and ``index.html``, one page that opens in
a browser with no network access. What goes into it depends on the tracker that wrote the run (run.json
``tracker``): each tracker registers its section builders with :func:`register_reporter` (see
:mod:`wptrack.report.model`); the built-in trackers' are in their packages (:mod:`wptrack.trackers.colour.report`,
:mod:`wptrack.trackers.people.report`, :mod:`wptrack.trackers.templates.report`), imported on first use. 3D views
are rendered off-screen with PyVista (EGL/OSMesa: no display, no GPU needed); PyVista, VTK and matplotlib are
imported only when a report is built.

Modules: :mod:`.data` (loading a run), :mod:`.vtkcam` (OpenCV -> VTK camera), :mod:`.scene3d` (3D stills, views
from the rig cameras, movie frames), :mod:`.overlays` (particles on the real frames), :mod:`.plots` (2D plots),
:mod:`.movie` (encoding), :mod:`.html` (the page).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from wptrack.core.errors import ConfigError, OutputError
from wptrack.io.atomic import ensure_writable_dir
from wptrack.io.run import RUN_FILE
from wptrack.report.data import GROUNDTRUTH_FILE, RunData, find_sweep, load_run, load_sweep, trajectories
from wptrack.report.model import (
    REPORTERS,
    Figure,
    ReportContext,
    ReporterSpec,
    ReportOptions,
    Section,
    register_reporter,
)

__all__ = [
    "REPORTERS",
    "Figure",
    "ReportContext",
    "ReportOptions",
    "ReporterSpec",
    "Section",
    "build_report",
    "choose_frames",
    "register_reporter",
    "use_groundtruth",
]

log = logging.getLogger(__name__)

REPORT_DIR = "report"
"""Default report folder name inside the run folder."""

_OWN_FILES = (
    "scene_*.png",
    "camview_*.png",
    "overlay_*.png",
    "birdseye.png",
    "error_vs_frame.png",
    "timings.png",
    "sweep_heatmap.png",
    "movie.mp4",
    "movie.webm",
    "movie.gif",
    "calibration.png",
    "fig5_*.png",
    "objects_vs_frame.png",
)


def choose_frames(data: RunData, requested: Sequence[int] | None, count: int = 4) -> list[int]:
    """Frames whose clouds and overlays are shown.

    Args:
        data: The run.
        requested: Frame numbers asked for (validated), or None to choose ``count`` evenly spaced frames among
            those with saved particles (else among the tracked frames), the first and last included.
        count: Number of frames chosen automatically.

    Raises:
        ConfigError: A requested frame is outside the tracked frames.
    """
    tracked = data.frames
    if requested:
        lo, hi = int(tracked.min()), int(tracked.max())
        bad = [int(f) for f in requested if not lo <= int(f) <= hi]
        if bad:
            raise ConfigError(f"report frames {bad} are outside the run's frames {lo}..{hi}")
        return sorted({int(f) for f in requested})
    pool = data.particles.frames if data.particles is not None else tracked
    idx = np.unique(np.round(np.linspace(0, len(pool) - 1, max(1, count))).astype(np.int64))
    return [int(pool[i]) for i in idx]


def use_groundtruth(data: RunData, path: str | Path) -> None:
    """Compare the run with the ground truth in ``path`` (a ``frame,id,x,y,z,...`` CSV) instead of the one found
    beside the run or the rig.

    Raises:
        ConfigError: The file is missing or unreadable.
    """
    from wptrack.core.errors import WptrackError
    from wptrack.io.tables import read_tracks

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"ground truth not found: {p}")
    try:
        data.groundtruth = trajectories(read_tracks(p), p)
    except WptrackError as e:
        raise ConfigError(f"cannot read ground truth {p}: {e}") from None
    data.groundtruth_path = p
    data.notes[:] = [n for n in data.notes if not n.startswith((f"no {GROUNDTRUTH_FILE}", "cannot read ground truth"))]


def _clean(out_dir: Path) -> None:
    """Remove files of a previous report in ``out_dir`` (only the names this package writes)."""
    for pattern in _OWN_FILES:
        for p in out_dir.glob(pattern):
            if p.is_file():
                p.unlink()


def build_report(
    run_dir: str | Path,
    out_dir: str | Path | None = None,
    sweep: str | Path | None = None,
    frames: Sequence[int] | None = None,
    options: ReportOptions | None = None,
) -> Path:
    """Render the report of a run (or of a sigma sweep) and return the path of its ``index.html``.

    Args:
        run_dir: A run folder written by ``wptrack track ...`` (run.json, tracks.csv, particles.npz), or a folder
            with the ``errors.csv`` of ``wptrack convergence`` (a sweep-only report).
        out_dir: Report folder (default ``run_dir/report``); created if needed.
        sweep: A sweep folder or ``errors.csv`` to add the sigma_m heatmap to a run's report.
        frames: Frames whose particle clouds and overlays are shown (default: a few evenly spaced).
        options: Rendering settings (sizes, movie length, ground truth...); ``frames`` overrides ``options.frames``.

    Returns:
        Path of ``index.html``.

    Raises:
        OutputError: ``run_dir`` is not a run folder (and holds no sweep), or the report cannot be written.
        ConfigError: The run's tracker has no report; bad frames; an unreadable sweep.
    """
    from wptrack.report.html import write_index
    from wptrack.report.plots import section_sweep

    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    options = options or ReportOptions()
    if frames is None:
        frames = options.frames
    sweep_data = load_sweep(sweep) if sweep is not None else None
    data: RunData | None = None
    spec: ReporterSpec | None = None
    if not (run_dir / RUN_FILE).is_file() and run_dir.is_dir() and find_sweep(run_dir) is not None:
        if sweep_data is None:
            sweep_data = load_sweep(run_dir)
    else:
        data = load_run(run_dir, known=list(REPORTERS))
        if options.groundtruth is not None:
            use_groundtruth(data, options.groundtruth)
        spec = REPORTERS[data.tracker]
    out = ensure_writable_dir(Path(out_dir) if out_dir is not None else run_dir / REPORT_DIR)
    if data is not None and out.resolve() == data.run_dir.resolve():
        raise OutputError(f"the report folder must differ from the run folder {run_dir} (use --out)")
    _clean(out)
    ctx = ReportContext(out_dir=out, data=data, sweep=sweep_data, options=options)
    if data is not None:
        ctx.frames = choose_frames(data, frames, options.auto_frames)
    sections: list[Section] = []
    for builder in spec.sections if spec is not None else ():
        sec = builder(ctx)
        if sec is not None:
            sections.append(sec)
    sec = section_sweep(ctx)
    if sec is not None:
        sections.append(sec)
    ctx.timings["total"] = time.perf_counter() - t0
    path = write_index(ctx, sections, spec.description if spec is not None else "")
    log.info("report written to %s in %.2f s", path, time.perf_counter() - t0)
    return path
