"""wptrack: particle-filter 3D object tracking from calibrated cameras on NVIDIA Warp (CPU and CUDA).

The public API (imported on first use, so ``import wptrack`` stays light):

* cameras: :class:`Rig` (``Rig.load("rig.yaml")``), :class:`Camera`, :class:`GroundPlane`;
* frames: :func:`open_frames` (videos, image folders or arrays, one per camera, synchronised);
* trackers, each with its frozen config: :class:`ColorTracker` / :class:`ColorConfig` / :class:`HSITarget` (S1,
  Barrera et al.), :class:`PeopleTracker` / :class:`PeopleConfig` (S2), :class:`TemplateTracker` /
  :class:`TemplateConfig` (S3, Juza et al.); every tracker has ``step(observation)``, ``track(observations)``,
  ``state_dict()`` / ``load_state_dict()`` (:class:`wptrack.core.filter.Tracker`);
* motion masks: :func:`open_masks` / :class:`MaskConfig`;
* scoring: :func:`evaluate` (accuracy, MOTA, IDF1, HOTA on the ground plane);
* errors: :class:`WptrackError` and its kinds (:mod:`wptrack.core.errors`).

>>> import wptrack
>>> rig = wptrack.Rig.load("lab/rig.yaml")  # doctest: +SKIP
>>> target = wptrack.HSITarget(hue=(312, 348), sat=(0.3, 0.8))
>>> tracker = wptrack.ColorTracker(rig, target, wptrack.ColorConfig(particles=1000))  # doctest: +SKIP
>>> for est in tracker.track(wptrack.open_frames(["cam1.avi", "cam2.avi"])):  # doctest: +SKIP
...     print(est.frame, est.mean)
"""

from __future__ import annotations

import importlib
import logging
from typing import Any

__version__ = "0.1.0"

logging.getLogger(__name__).addHandler(logging.NullHandler())

_API = {
    "Camera": "wptrack.cameras.camera",
    "GroundPlane": "wptrack.cameras.camera",
    "Rig": "wptrack.cameras.rig",
    "open_frames": "wptrack.io.frames",
    "ColorTracker": "wptrack.trackers.colour.tracker",
    "ColorConfig": "wptrack.trackers.colour.tracker",
    "HSITarget": "wptrack.trackers.colour.tracker",
    "PeopleTracker": "wptrack.trackers.people.tracker",
    "PeopleConfig": "wptrack.trackers.people.config",
    "TemplateTracker": "wptrack.trackers.templates.tracker",
    "TemplateConfig": "wptrack.trackers.templates.config",
    "open_masks": "wptrack.motion.masks",
    "MaskConfig": "wptrack.motion.masks",
    "evaluate": "wptrack.evaluation.mot",
    "WptrackError": "wptrack.core.errors",
    "ConfigError": "wptrack.core.errors",
}
"""Public name -> the module that defines it."""

__all__ = ["__version__", *_API]


def __getattr__(name: str) -> Any:
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'wptrack' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
