"""Running trackers over recordings: one run loop (:mod:`wptrack.runs.loop`) and one job per tracker.

>>> from wptrack.runs import run_tracker
>>> from wptrack.trackers.colour.run import ColourRun
>>> summary = run_tracker(ColourRun("lab/rig.yaml", ["cam1.avi", "cam2.avi"], target, config), "run1")  # doctest: +SKIP
"""

from __future__ import annotations

from wptrack.runs.loop import RunInterrupted, TrackerRun, interruptible, run_tracker

__all__ = ["RunInterrupted", "TrackerRun", "interruptible", "run_tracker"]
