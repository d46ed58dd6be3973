"""``wptrack bench``: run the benchmark suites of ``benchmarks/`` (a source checkout) and write a table."""

from __future__ import annotations

import importlib
import logging
import sys
from pathlib import Path

from .errors import ConfigError

log = logging.getLogger(__name__)


def load_suites() -> dict:
    """The ``benchmarks`` package's suite registry (it ships with the source checkout, not the wheel)."""
    root = Path(__file__).resolve().parents[1]
    if (root / "benchmarks" / "__init__.py").exists() and str(root) not in sys.path:
        sys.path.insert(0, str(root))
    try:
        return importlib.import_module("benchmarks").SUITES
    except ImportError as e:
        raise ConfigError(f"wptrack bench needs the benchmarks/ folder of a wptrack source checkout ({e})") from None


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
