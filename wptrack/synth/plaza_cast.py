"""The plaza scenes' looks and fixed routes: clothing, skin and hair colours, people drawn with them (some in
ground-like clothes), the road's asphalt colour and the ``dark-car`` condition, the U-turn route of ``s3-cars`` and
cars of given sizes. The lowest layer of the plaza scenes: :mod:`wptrack.synth.plaza` (the scene),
:mod:`wptrack.synth.plaza_seeds` (drawn casts) and :mod:`wptrack.synth.plaza_scenes` (the fixed casts and the scene
registry) use it."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from wptrack.synth.actors import Car, Person, PlazaActor, _Rgb
from wptrack.synth.plaza_background import ROAD_LANES

log = logging.getLogger(__name__)

_SHIRTS: tuple[_Rgb, ...] = (
    (0.6, 0.1, 0.1),
    (0.1, 0.18, 0.45),
    (0.82, 0.82, 0.78),
    (0.2, 0.42, 0.2),
    (0.75, 0.58, 0.2),
    (0.42, 0.28, 0.48),
    (0.12, 0.12, 0.13),
    (0.2, 0.5, 0.6),
)
_TROUSERS: tuple[_Rgb, ...] = ((0.14, 0.17, 0.3), (0.08, 0.08, 0.09), (0.35, 0.28, 0.22), (0.25, 0.25, 0.26))
_SKINS: tuple[_Rgb, ...] = ((0.75, 0.55, 0.45), (0.55, 0.38, 0.28), (0.35, 0.24, 0.18), (0.8, 0.64, 0.55))
_HAIRS: tuple[_Rgb, ...] = ((0.08, 0.06, 0.05), (0.3, 0.2, 0.1), (0.6, 0.5, 0.3), (0.4, 0.4, 0.4))
_PAVING_LIKE: _Rgb = (0.52, 0.49, 0.44)
"""Clothing close to the paving colour (hard for background subtraction)."""
_ASPHALT_LIKE: _Rgb = (0.2, 0.2, 0.21)
"""Clothing or paint close to the asphalt colour."""
ASPHALT_RGB: _Rgb = (0.21, 0.21, 0.22)
"""Mean albedo of the road's asphalt (see ``plaza_background._ground_texture``): the ``dark-car`` paint."""


def _dark_car(actors: list[PlazaActor]) -> list[PlazaActor]:
    """``dark-car``: the first car (lowest id) painted in the asphalt's colour; no car: unchanged (a warning)."""
    cars = [a for a in actors if isinstance(a.shape, Car)]
    if not cars:
        log.warning("condition dark-car: the scene has no car; nothing changed")
        return actors
    first = min(cars, key=lambda a: a.oid)
    return [replace(a, shape=replace(a.shape, body=ASPHALT_RGB)) if a is first else a for a in actors]


def _people(count: int, seed: int, camouflage: Sequence[int] = ()) -> list[Person]:
    """``count`` people of varied height, build and clothing; those in ``camouflage`` wear ground-like colours."""
    rng = np.random.default_rng(seed)
    shirts = rng.permutation(len(_SHIRTS))
    trousers_order = rng.permutation(len(_TROUSERS))
    out = []
    for i in range(count):
        shirt = _SHIRTS[int(shirts[i % len(shirts)])]
        trousers = _TROUSERS[int(trousers_order[i % len(trousers_order)])]
        if i in camouflage:
            shirt, trousers = (_PAVING_LIKE, _ASPHALT_LIKE) if i % 2 == 0 else (_ASPHALT_LIKE, _PAVING_LIKE)
        out.append(
            Person(
                height=float(rng.uniform(1.6, 1.9)),
                girth=float(rng.uniform(0.9, 1.12)),
                shirt=shirt,
                trousers=trousers,
                skin=_SKINS[int(rng.integers(len(_SKINS)))],
                hair=_HAIRS[int(rng.integers(len(_HAIRS)))],
            )
        )
    return out


U_TURN: tuple[tuple[float, float], ...] = (
    (15.5, ROAD_LANES[1]),
    (9.0, ROAD_LANES[1]),
    (4.0, ROAD_LANES[1] + 0.5),
    (0.8, 18.0),
    (-2.2, 17.3),
    (-3.2, 15.2),
    (-2.4, 12.9),
    (0.4, 11.9),
    (4.5, 12.2),
    (9.0, ROAD_LANES[0]),
    (17.0, ROAD_LANES[0]),
)
"""Waypoints of the U-turn of ``s3-cars`` (seed 0): in the far lane towards -x, a wide left turn, out along +x."""
U_TURN_SPEEDS: tuple[float, ...] = (5.0, 4.5, 3.2, 2.3, 2.2, 2.2, 2.3, 2.8, 3.5, 4.5, 5.0)
"""Speeds at the :data:`U_TURN` waypoints, m/s."""


def _car(length: float, width: float, height: float, rgb: _Rgb) -> Car:
    return Car(length=length, width=width, height=height, body=rgb)
