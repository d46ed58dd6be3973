"""Synthetic scenes with ground truth: a tiny NumPy ray caster and a registry of scenes.

>>> from wptrack.synth import render_scene, scene_names
>>> scene_names()
['s1-clutter', 's1-clutter-2cam', 's1-clutter-4cam', 's1-clutter-6cam', 's1-lab', 's1-lab-jump', 's1-room', 's2-office',
 's2-office-twocolour', 's3-cars', 's3-groups', 's3-mixed', 's3-people']
>>> result = render_scene("s1-lab", "out/s1-lab", frames=50)  # doctest: +SKIP

Scenes:

- ``s1-lab``: Barrera et al.'s lab, a pink ball resting, looping (occluded in one camera) and resting; 2 webcams.
- ``s1-lab-jump``: the same lab, the ball jumps 2 m (the extended paper's section III.C).
- ``s1-clutter`` (and ``-2cam``, ``-4cam``, ``-6cam``): a room full of colours near the target's (issue 29), a pole
  hiding part of the ball in one camera, the ball leaving one camera's view, a light change, JPEG frames and an
  OpenCV FileStorage calibration with distortion; 3 cameras (2, 4, 6). Seeded: the seed draws the layout.
- ``s2-office``: the S2 paper's office, two people enter from opposite doors, meet, shake hands and leave; desk
  partitions hide their legs; 3 corner cameras (seeded: the seed also varies paths and clothing).
- ``s2-office-twocolour``: the same, one person in a red front and a blue back (the paper's Fig. 9 case).
- ``s3-people``: Juza et al., up to 5 people walking randomly on a plaza, entering and leaving, occluding each other.
- ``s3-cars``: Juza et al., 3 cars: two passing each other in opposite lanes (occlusion), one making a U-turn.
- ``s3-groups``: Juza et al., a group of 5-6 people walking together (0.6-1.2 m apart) and a straggler.
- ``s3-mixed``: Juza et al., 2 cars and 2 people, one person crossing the road between the cars.

(s3 scenes are seeded: seed 0 is the fixed sequence, another seed draws a new one of the same type.)

The s3 scenes have one high camera ``cam0`` over a plaza (ground plane z = 0), ground truth with class, size and
heading per object, and perfect foreground masks (``cam0_mask.avi``); see :mod:`wptrack.synth.plaza`.

See :mod:`wptrack.synth.base` for the files written, :mod:`wptrack.synth.lab` for the lab scenes,
:mod:`wptrack.synth.office` for the office scenes and :mod:`wptrack.synth.plaza` for the plaza scenes.
"""

from __future__ import annotations

from wptrack.synth import clutter as _clutter  # noqa: F401  (registers the clutter rooms)
from wptrack.synth import lab as _lab  # noqa: F401  (registers the lab scenes)
from wptrack.synth import office as _office  # noqa: F401  (registers the office scenes)
from wptrack.synth import plaza_scenes as _plaza  # noqa: F401  (registers the plaza scenes)
from wptrack.synth import room as _room  # noqa: F401  (registers the 4-camera room)
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
