"""Synthetic scenes with ground truth: a tiny NumPy ray caster and a registry of scenes.

>>> from wptrack.synth import render_scene, scene_names
>>> scene_names()
['s1-lab', 's1-lab-jump']
>>> result = render_scene("s1-lab", "out/s1-lab", frames=50)  # doctest: +SKIP

See :mod:`wptrack.synth.base` for the files written and :mod:`wptrack.synth.lab` for the lab scene.
"""

from __future__ import annotations

from wptrack.synth import lab as _lab  # noqa: F401  (registers the lab scenes)
from wptrack.synth.base import (
    SCENES,
    Scene,
    SceneResult,
    SceneSpec,
    get_scene,
    register_scene,
    render_scene,
    scene_names,
)

__all__ = ["SCENES", "Scene", "SceneResult", "SceneSpec", "get_scene", "register_scene", "render_scene", "scene_names"]
