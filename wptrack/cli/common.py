"""Pieces every ``wptrack`` command shares: the parser class (one-line errors), argument types, the device
option, words, and the evaluation and report steps that end a run."""

from __future__ import annotations

import argparse


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors and exit code 2 (argparse's default code, but our message format)."""

    def error(self, message: str):  # noqa: D401
        self.exit(2, f"wptrack: error: {message}\n")


def positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def positive_count(text: str) -> int:
    """A whole positive count that may be written as a float (``1e6``, ``2000``): bench's particle counts."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive whole number (e.g. 1000 or 1e6), got {text!r}") from None
    if not (v >= 1 and v.is_integer()):
        raise argparse.ArgumentTypeError(f"expected a positive whole number (e.g. 1000 or 1e6), got {text!r}")
    return int(v)


def add_device(p: argparse.ArgumentParser) -> None:
    p.add_argument("--device", default="auto", help="auto (CUDA when available), cpu, cuda or cuda:N")


# --- evaluate ------------------------------------------------------------------------------------------------
def evaluation_line(ev, threshold: float) -> str:
    cls = "n/a" if ev.classification_accuracy is None else f"{ev.classification_accuracy:.3f}"
    return (
        f"accuracy {ev.accuracy:.3f} (tracking {ev.tracking_accuracy:.3f} x classification {cls}); "
        f"MOTA {ev.mota:.3f}, IDF1 {ev.idf1:.3f}, ID switches {ev.id_switches}, HOTA {ev.hota:.3f} "
        f"(DetA {ev.deta:.3f}, AssA {ev.assa:.3f}, LocA {ev.loca:.3f}) at {threshold:g} m"
    )


def report_after_tracking(run_dir) -> None:
    from wptrack.report import build_report

    print("rendering the report ...")
    print(f"report: {build_report(run_dir)}")


def plural(n: int, word: str, many: str | None = None) -> str:
    """``1 object``, ``2 objects`` (``many``: an irregular plural, e.g. ``people``)."""
    return f"{n} {word if n == 1 else many or word + 's'}"
