"""The report's building blocks: figures, sections, the rendering context and the per-tracker registry.

A tracker's report is a list of *section builders*, functions ``(ReportContext) -> Section | None`` registered
under the tracker's name (the ``tracker`` field of run.json) with :func:`register_reporter`. Builders that find
their input missing return a section whose notes say so (or None to leave the section out). New trackers (S2
people, S3 templates) register their own list, reusing the generic builders (3D scene, plots, movie) and adding
their own (e.g. people boxes, template patches)::

    register_reporter("people", "S2 multi-camera people tracker", (scene3d.section_scene, my_section, ...))
"""

from __future__ import annotations

import importlib
import logging
import time
from collections.abc import Callable, Iterator, MutableMapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wptrack.report.data import RunData

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Figure:
    """A file shown in the page.

    Attributes:
        path: Path relative to the report folder (POSIX separators).
        caption: One-line caption.
        kind: ``"image"`` (PNG/GIF shown with <img>) or ``"video"`` (shown with <video>).
        alternates: Further files of the same content, e.g. ``("movie.mp4",)`` offered as downloads.
        wide: Show at full page width (e.g. several cameras side by side) rather than two per row.
    """

    path: str
    caption: str
    kind: str = "image"
    alternates: tuple[str, ...] = ()
    wide: bool = False


@dataclass
class Section:
    """One part of the page.

    Attributes:
        key: Anchor id (``[a-z0-9-]``).
        title: Heading.
        figures: Images / movies, in order.
        notes: Remarks shown under the heading (e.g. what was left out and why).
        text: A short paragraph explaining what is shown.
        table: Optional rows ``[(label, value), ...]`` shown as a two-column table.
    """

    key: str
    title: str
    figures: list[Figure] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    text: str = ""
    table: list[tuple[str, str]] = field(default_factory=list)


@dataclass(frozen=True)
class ReportOptions:
    """Rendering settings (display only: nothing here changes tracking results).

    Attributes:
        frames: Frames whose particle clouds and overlays are shown (None: chosen automatically).
        auto_frames: How many frames to choose when ``frames`` is None.
        still_size: (width, height) of the 3D stills, pixels.
        movie: Whether to render the movie.
        movie_size: (width, height) of the movie, pixels (even numbers for the encoders).
        movie_frames: At most this many movie frames (evenly spaced over the run).
        movie_fps: Movie frames per second.
        max_points: At most this many particles drawn per cloud in 3D (display subsample).
        overlay_scale: Overlays are drawn on frames upscaled by this factor (finer markers).
        groundtruth: A ground-truth CSV (``frame,id,x,y,z,...``) to compare with; None looks for
            ``groundtruth.csv`` in the run folder and beside the rig (template runs also in ``../scene``).
    """

    frames: tuple[int, ...] | None = None
    auto_frames: int = 4
    still_size: tuple[int, int] = (800, 600)
    movie: bool = True
    movie_size: tuple[int, int] = (480, 360)
    movie_frames: int = 100
    movie_fps: float = 10.0
    max_points: int = 1000
    overlay_scale: int = 2
    groundtruth: str | Path | None = None


@dataclass
class ReportContext:
    """What every section builder gets.

    Attributes:
        out_dir: The report folder (files are written here; figure paths are relative to it).
        data: The run, or None for a sweep-only report.
        sweep: A loaded sigma sweep (see :func:`wptrack.report.data.load_sweep`), or None.
        options: Rendering settings.
        frames: The frames chosen for clouds and overlays.
        notes: Page-level notes.
        timings: Seconds spent per section (filled by :func:`timed`).
        renderer: The VTK render window class used, once known.
        cache: Data shared between section builders (e.g. the chosen frames' images).
    """

    out_dir: Path
    data: RunData | None
    sweep: dict[str, Any] | None
    options: ReportOptions
    frames: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    renderer: str | None = None
    cache: dict[str, Any] = field(default_factory=dict)

    @contextmanager
    def timed(self, name: str) -> Iterator[None]:
        """Accumulate the wall time of the block under ``name`` in :attr:`timings`."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.timings[name] = self.timings.get(name, 0.0) + time.perf_counter() - t0


SectionBuilder = Callable[[ReportContext], "Section | None"]


@dataclass(frozen=True)
class ReporterSpec:
    """A tracker's report: its section builders, in page order.

    Attributes:
        tracker: The run.json ``tracker`` name.
        description: One line shown in the page header.
        sections: Section builders, in page order.
    """

    tracker: str
    description: str
    sections: tuple[SectionBuilder, ...]


BUILTIN_REPORTERS: dict[str, str] = {
    "color": "wptrack.trackers.colour.report",
    "people": "wptrack.trackers.people.report",
    "templates": "wptrack.trackers.templates.report",
}
"""The trackers' own report modules by run.json ``tracker`` name: each registers its sections when imported. They are
imported on first use of :data:`REPORTERS`, so that a tracker's report module can use this package without an
import cycle."""


class _Registry(MutableMapping[str, ReporterSpec]):
    """Reporters by tracker name: the built-in trackers' (imported on first access) and any registered later."""

    def __init__(self) -> None:
        self._specs: dict[str, ReporterSpec] = {}
        self._loaded = False

    def _load(self) -> dict[str, ReporterSpec]:
        if not self._loaded:
            self._loaded = True
            for module in BUILTIN_REPORTERS.values():
                importlib.import_module(module)
        return self._specs

    def __getitem__(self, key: str) -> ReporterSpec:
        return self._load()[key]

    def __setitem__(self, key: str, value: ReporterSpec) -> None:
        self._specs[key] = value

    def __delitem__(self, key: str) -> None:
        del self._load()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._load())

    def __len__(self) -> int:
        return len(self._load())


REPORTERS: MutableMapping[str, ReporterSpec] = _Registry()
"""Reporters by tracker name (filled by :func:`register_reporter`; the built-in trackers' on first access)."""


def register_reporter(tracker: str, description: str, sections: tuple[SectionBuilder, ...]) -> ReporterSpec:
    """Register (or replace) the report of a tracker.

    Args:
        tracker: The name written to run.json by the tracker's RunWriter (e.g. ``"color"``).
        description: One line for the page header.
        sections: Section builders, in page order.

    Returns:
        The registered spec.
    """
    spec = ReporterSpec(tracker, description, tuple(sections))
    REPORTERS[tracker] = spec
    return spec
