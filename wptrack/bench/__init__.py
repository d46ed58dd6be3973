"""``wptrack bench``: the benchmark suites (shipped in the package) and their table.

A suite is a module of this package defining a suite class with ``name``, ``default_grid(is_cuda)`` and
``run_case(case, device, frames=..., numpy_max=...)`` (optionally ``second``, ``HEADER`` and ``format_row``). It is
registered with one line in ``SUITES``: suite name -> ``"module:Class"``. Suites are imported only when run, so a
suite's dependencies cost nothing to the others. The NumPy references (``numpy_colour``, ``numpy_templates``) import
neither Warp nor ``wptrack.kernels``: they check the kernels, they do not reuse them.
"""

from __future__ import annotations

import importlib
import logging

from wptrack.core.errors import ConfigError

log = logging.getLogger(__name__)

SUITES: dict[str, str] = {
    "color": "wptrack.bench.colour:ColourSuite",
    "color-e2e": "wptrack.bench.endtoend:EndToEndSuite",
    "templates": "wptrack.bench.templates:TemplateSuite",
    "masks": "wptrack.bench.masks:MasksSuite",
    "pipeline": "wptrack.bench.pipeline:PipelineSuite",
    "people": "wptrack.bench.people:PeopleSuite",
    "batch": "wptrack.bench.batch:BatchSuite",
    "soak": "wptrack.bench.soak:SoakSuite",
    "soak-templates": "wptrack.bench.soak:TemplateSoakSuite",
}
"""Suite name (``wptrack bench --tracker NAME``) -> ``"module:Class"`` of its suite class."""


def load_suite(name: str):
    """The suite class registered as ``name`` in ``SUITES`` (imported now).

    Raises:
        ConfigError: ``name`` is not a registered suite.
    """
    if name not in SUITES:
        raise ConfigError(f"--tracker: unknown suite {name!r}; expected one of {', '.join(SUITES)}")
    module, cls = SUITES[name].split(":")
    suite = getattr(importlib.import_module(module), cls)
    if suite.name != name:
        raise RuntimeError(f"SUITES[{name!r}] points to suite {suite.name!r}")
    return suite


def format_row(r: dict) -> str:
    if "decode_s" in r:
        return (
            f"{r['tracker']:9s} {r['particles']:>10d} {r['cameras']:>4d} {r['frames']:>4d} frames: decode alone "
            f"{r['decode_s']:.3f} s, decode + track {r['total_s']:.3f} s ({100 * r['overhead_vs_decode']:+.1f} %)"
        )
    npy = f"{r['numpy_ms']:9.2f}" if "numpy_ms" in r else "        -"
    eq = {True: "yes", False: "NO"}.get(r.get("equivalent"), "-")
    st = " ".join(f"{k}={v:.3f}" for k, v in r["stages_ms"].items())
    off = r.get("offspring")
    if off and off.get("checked"):
        st += f"  offspring@{off['particles']:.0e}: {'ok' if off['ok'] else 'FAILED'} (max |z| {off['max_abs_z']:.2f})"
    return (
        f"{r['tracker']:6s} {r['particles']:>10d} {r['cameras']:>4d} {r['score_mode']:8s} {r['frame_ms']:9.3f} "
        f"{r['step_ms']:9.3f} {npy} {r['particles_per_s']:10.3g} {eq:>4s}  {st}"
    )


HEADER = (
    f"{'suite':6s} {'N':>10s} {'cams':>4s} {'mode':8s} {'frame ms':>9s} {'step ms':>9s} {'numpy ms':>9s} "
    f"{'part/s':>10s} {'eq':>4s}  stages (ms, median)"
)
