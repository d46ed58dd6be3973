"""S2: one person's particle filter and the estimates of a frame (Lopez-Cifuentes et al., multi-camera 3D
particle filters with motion and colour). A :class:`PersonFilter` is a slot of the tracker's pool
(:class:`wptrack.trackers.people.tracker.PeopleTracker`): its particles are 3D points inside the person, moved by
eq. 5 with the frame interval dt in seconds, weighted by the motion masks of all cameras, a multi-view HSV colour
descriptor (eqs. 7-26) and, beyond the paper (ours, after the Probabilistic Occupancy Map of Fleuret, Berclaz,
Lengagne and Fua, PAMI 2008), the rectangle of a person standing at the particle's ground position
(``kernels/people/coverage.py``); a gate stops the weighting when the frame's masks do not show the person.

Units: metres, seconds, pixels.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import warp as wp

from wptrack.core.filter import BLOCK, ParticleFilter
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.people import coverage as kcov
from wptrack.kernels.people import descriptor as kdesc
from wptrack.kernels.people import filter as kpeople
from wptrack.kernels.people import occupancy as kocc
from wptrack.trackers.people.config import GATE_USES

_GOLDEN = 0x9E3779B97F4A7C15
DESCRIPTOR_BLOCK = 64
"""Lanes per particle of the GPU descriptor (they share the disc pixels)."""
GATE_BLOCK = 64
"""Lanes of the GPU gate (``kernels.people.coverage.gate_kernel``): they share its grid points (49 at 25 frames/s)."""
GATE_SPACING = 0.125
"""Spacing of the points the gate tries around a person's last position, metres
(``kernels.people.coverage.gate_kernel``)."""
WALK_SPEED = 1.5
"""Walking speed, metres per second: how far a person may have gone while unseen (the gate, re-identification)."""


def person_seed(seed: int, slot: int) -> int:
    """The 64-bit seed of pool slot ``slot``: the run seed mixed with the slot (splitmix64), so that the people's
    random streams differ and the same run seed gives the same streams."""
    z = (int(seed) + _GOLDEN * (slot + 1)) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    return z ^ (z >> 31)


@dataclass
class PersonEstimate:
    """One tracked person in one frame.

    Attributes:
        id: persistent id (never reused in a run).
        centroid: (3,) the person's 3D centroid, metres: the particles' mean, its height from the standing-person
            model unless ``BodyConfig.centroid == "particles"`` (see
            :class:`~wptrack.trackers.people.config.BodyConfig`).
        top: top of the person's silhouette column, metres (NaN when not found).
        mean: (3,) weighted mean of the particles (the paper's estimate), metres.
        std: (3,) weighted standard deviation per axis, metres.
        map: (3,) best particle, metres.
        ess: effective sample size of the frame's weights.
        loglik: log of the mean weight (eq. 11 averaged over the particles).
        age: frames since the person was added.
        support: how much of its rectangle (what the other people's rectangles leave of it) the masks cover near the
            person's last position (``kernels.people.coverage.gate_kernel``), a fraction; <= ``PersonConfig.gate``:
            not seen this frame.
        particles: (K, 3) subsample of the particles (before resampling), metres, or None.
        weights: (K,) their weights relative to the best particle, or None.
        occupancy: ``(origin (3,), grid (nx, ny, nz) float32)``: the occupancy pdf of this frame's particles (see
            :meth:`PeopleTracker.occupancy`), when the frame was stepped with ``occupancy=True``, else None. It is
            computed before the population update, so every person of the estimate has one, also a person removed
            after this frame.
        degenerate: every particle's log-weight was -inf/NaN this frame (floored to ``kernels.core.reduce.LOGW_FLOOR``):
            the person's predicted particles were kept with uniform weights (the prior), the estimate is finite.
    """

    id: int
    centroid: np.ndarray
    top: float
    mean: np.ndarray
    std: np.ndarray
    map: np.ndarray
    ess: float
    loglik: float
    age: int
    support: float = 0.0
    particles: np.ndarray | None = None
    weights: np.ndarray | None = None
    occupancy: tuple[np.ndarray, np.ndarray] | None = None
    degenerate: bool = False


@dataclass
class PeopleEstimate:
    """The tracker's output for one frame.

    Attributes:
        frame: 0-based frame number.
        people: the tracked people (added this frame: from the next frame on).
        sigma_n: image noise sigma_n of eq. 18 (V units, [0, 1]).
        added, removed: ids added / removed after this frame.
        timings: seconds per stage.
    """

    frame: int
    people: list[PersonEstimate]
    sigma_n: float
    added: list[int] = field(default_factory=list)
    removed: list[int] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)


class PersonFilter(ParticleFilter):
    """One person's particle set (a slot of the tracker's pool): positions and log-weights from
    :class:`ParticleFilter`, plus, as (N, ...) ping-pong pairs: ``vel`` (metres/second), ``model`` (appearance C,
    (N, 3 N_b)), ``desc`` (descriptor A at the particle, (N, 3 N_b)), ``mass`` (its total weight); ``rgb`` (N,)
    the patch's mean colour (eq. 17)."""

    def __init__(self, tracker: Any, slot: int) -> None:
        cfg = tracker.config
        super().__init__(
            cfg.particles,
            tracker.frame_dynamics[0],
            tracker.device,
            seed=person_seed(cfg.seed, slot),
            resampling="systematic",
            ess_threshold=1.0,  # section 2.1: resample every frame
            keep_particles=tracker.keep_particles,
            use_graph=tracker.use_graph,
        )
        n, cols, d = self.n, 3 * cfg.descriptor.n_bins, self.device
        self.tracker = tracker
        self.slot = slot
        self.vel = [wp.zeros(n, dtype=wp.vec3, device=d) for _ in range(2)]
        self.model = [wp.zeros((n, cols), dtype=wp.float32, device=d) for _ in range(2)]
        self.desc = [wp.zeros((n, cols), dtype=wp.float32, device=d) for _ in range(2)]
        self.mass = [wp.zeros(n, dtype=wp.float32, device=d) for _ in range(2)]
        self.rgb = wp.zeros(n, dtype=wp.vec3, device=d)
        self.observe = wp.ones(2, dtype=wp.int32, device=d)  # [0] this frame's masks show the person, [1] the last
        self.support = wp.zeros(1, dtype=wp.float32, device=d)  # [0] the gate's best rectangle term, nats
        self.support_host = wp.zeros(1, dtype=wp.float32, device="cpu", pinned=tracker.is_cuda)
        oc = cfg.occupancy
        self.grid_dims = tuple(int(v) for v in np.maximum(np.round(np.asarray(oc.extent) / oc.voxel), 1))
        self.grid = wp.zeros(self.grid_dims, dtype=wp.float32, device=d)  # occupancy pdf around the person, 1/m^3
        self.grid_host = wp.zeros(self.grid_dims, dtype=wp.float32, device="cpu", pinned=tracker.is_cuda)
        self.log_norm = wp.zeros(1, dtype=wp.float64, device=d)
        self._occupancy_cmds: dict[int, tuple[wp.Launch, wp.Launch]] = {}  # recorded launches per parity

    def state_arrays(self) -> dict[str, wp.array]:
        """:meth:`ParticleFilter.state_arrays` and the person's other particle fields, both buffers of each (velocity,
        appearance model C, descriptor A, mass), the patch colours and whether the last frame's masks showed the
        person (the gate). The occupancy grid is recomputed when asked for."""
        arrays = super().state_arrays()
        for name in ("vel", "model", "desc", "mass"):
            for k, arr in enumerate(getattr(self, name)):
                arrays[f"{name}.{k}"] = arr
        arrays.update(rgb=self.rgb, observe=self.observe)
        return arrays

    def launch_occupancy(self, origin: np.ndarray) -> None:
        """Launch the occupancy grid of the current particles with its corner at ``origin`` (metres) into
        :attr:`grid` and its asynchronous copy into :attr:`grid_host` (recorded launches: a few microseconds of
        host time each instead of a full ``wp.launch``)."""
        cur = self.parity
        if cur not in self._occupancy_cmds:
            oc, d = self.tracker.config.occupancy, self.device
            norm = wp.launch(
                kocc.log_norm_kernel,
                dim=1,
                inputs=[self.est, int(kreduce.EST_LOGLIK), self.n],
                outputs=[self.log_norm],
                device=d,
                record_cmd=True,
            )
            grid = wp.launch(
                kocc.occupancy_kernel,
                dim=self.grid_dims,
                inputs=[self.x[cur], self.logw[cur], self.log_norm, oc.sigma, oc.cutoff, wp.vec3(0.0), oc.voxel],
                outputs=[self.grid],
                device=d,
                record_cmd=True,
            )
            self._occupancy_cmds[cur] = (norm, grid)
        norm, grid = self._occupancy_cmds[cur]
        grid.set_param_by_name("origin", wp.vec3(*(float(v) for v in origin)))
        norm.launch()
        grid.launch()
        wp.copy(self.grid_host, self.grid)  # asynchronous on CUDA (pinned)

    def _launch_observation(self) -> None:
        """Whether this frame's masks show the person (``kernels.people.coverage.gate_kernel``, into
        :attr:`observe`)."""
        tr, pc = self.tracker, self.tracker.config.person
        wp.launch_tiled(
            kcov.gate_kernel,
            dim=[1],
            inputs=[tr.sdrig.cams, tr.integral, tr.boxes, tr.slot_xy, self.slot, tr.terms]
            + [pc.gate_reach, WALK_SPEED, tr.dt, GATE_SPACING, pc.gate, pc.gate_left, pc.gate_cameras]
            + [GATE_USES.index(pc.gate_cameras_use)],
            outputs=[self.observe, self.support],
            block_dim=GATE_BLOCK,
            device=self.device,
        )

    def _readback(self) -> None:
        super()._readback()
        wp.copy(self.support_host, self.support)

    def _launch_position(self) -> None:
        """The ground position of this frame's estimate into the tracker's ``slot_xy[slot]`` (the next people's gate
        and person terms, the rectangles and the column tops read it), in the frame chain: on CUDA it is part of the
        person's graph instead of a launch of its own."""
        tr = self.tracker
        wp.launch(
            kpeople.person_xy_kernel,
            dim=1,
            inputs=[self.est, int(kreduce.EST_MEAN), self.slot],
            outputs=[tr.slot_xy],
            device=self.device,
        )

    def stages(self, src: int, dst: int) -> list[tuple[str, Callable[[], None]]]:
        """:meth:`ParticleFilter.stages` and the estimate's ground position into the tracker's ``slot_xy``."""
        return [*super().stages(src, dst), ("position", self._launch_position)]

    def spawn(self, xy: np.ndarray, frame: int) -> None:
        """Start the filter on a new person standing at ``xy`` (ground, metres): particles uniform in the
        configured cylinder, with random horizontal velocities (``BirthConfig.init_speed``), each with the
        descriptor at its position as appearance model C_0."""
        tr, b = self.tracker, self.tracker.config.birth
        cur, d = self.parity, self.device
        wp.launch(
            kpeople.init_cylinder_kernel,
            dim=self.n,
            inputs=[
                wp.vec3(float(xy[0]), float(xy[1]), 0.0),
                b.init_radius,
                b.init_z[0],
                b.init_z[1],
                b.init_speed,
                self.seed,
                frame,
            ],
            outputs=[self.x[cur], self.vel[cur]],
            device=d,
        )
        dc = tr.config.descriptor
        wp.launch(
            kdesc.descriptor_kernel,
            dim=self.n,
            inputs=[
                tr.drig.cams,
                tr.bgr,
                self.x[cur],
                dc.r_n,
                dc.n_bins,
                dc.r_min,
                dc.r_max,
                dc.step,
            ],
            outputs=[self.desc[cur], self.mass[cur], self.rgb],
            device=d,
        )
        wp.copy(self.model[cur], self.desc[cur])  # C_0 = A_0
        self.observe.fill_(1)
        self._reset_weights()

    def _launch_predict_score(self, src: int, dst: int) -> None:
        """One frame's particle work. CPU: the fused ``step_kernel`` (one pass per particle). CUDA: the same in three
        launches (predict, descriptor with one block per particle, score + block moments): the descriptor's ~300 disc
        pixels per particle are shared by a block's lanes instead of looping in one thread (a few thousand threads
        leave a GPU idle)."""
        tr, cfg = self.tracker, self.tracker.config
        dc, mo = cfg.descriptor, cfg.motion
        d = self.device
        if not self.is_cuda:
            wp.launch_tiled(
                kpeople.step_kernel,
                dim=[self.blocks],
                inputs=[
                    tr.drig.cams,
                    tr.mask,
                    mo.p_b,
                    mo.log_outside,
                    int(mo.drop_worst),
                    tr.bgr,
                    dc.r_n,
                    dc.n_bins,
                    dc.r_min,
                    dc.r_max,
                    dc.step,
                    self.x[src],
                    self.vel[src],
                    self.model[src],
                    self.desc[src],
                    self.mass[src],
                    self.ancestors,
                    self.logw[src],
                    self.resampled,
                    self.sigma,
                    tr.sigma_vel,
                    tr.dt,
                    tr.alpha,
                    self.observe,
                    tr.decay,
                    tr.sigma_n,
                    dc.sigma_p,
                    self.seed,
                    self.frame,
                    tr.sdrig.cams,
                    tr.integral,
                    tr.slot_xy,
                    tr.slot_alive,
                    tr.boxes,
                    self.slot,
                    tr.terms,
                    self.n,
                    self.chunk,
                    cfg.dynamics.jump,
                    cfg.dynamics.jump_span,
                    cfg.dynamics.jump_clear,
                ],
                outputs=[
                    self.x[dst],
                    self.vel[dst],
                    self.model[dst],
                    self.desc[dst],
                    self.mass[dst],
                    self.rgb,
                    self.logw[dst],
                    self.part_max,
                    self.part_arg,
                    self.part,
                ],
                block_dim=BLOCK,
                device=d,
            )
            return
        wp.launch(
            kpeople.predict_kernel,
            dim=self.n,
            inputs=[
                self.x[src],
                self.vel[src],
                self.model[src],
                self.desc[src],
                self.mass[src],
                self.ancestors,
                self.sigma,
                tr.sigma_vel,
                tr.dt,
                tr.alpha,
                self.observe,
                tr.decay,
                self.seed,
                self.frame,
                tr.sdrig.cams,
                cfg.dynamics.jump,
                cfg.dynamics.jump_span,
                tr.slot_xy,
                tr.slot_alive,
                self.slot,
                cfg.dynamics.jump_clear,
            ],
            outputs=[self.x[dst], self.vel[dst], self.model[dst]],
            device=d,
        )
        wp.launch_tiled(
            kdesc.descriptor_block_kernel,
            dim=[self.n],
            inputs=[tr.drig.cams, tr.bgr, self.x[dst], dc.r_n, dc.n_bins, dc.r_min, dc.r_max, dc.step],
            outputs=[self.desc[dst], self.mass[dst], self.rgb],
            block_dim=DESCRIPTOR_BLOCK,
            device=d,
        )
        wp.launch_tiled(
            kpeople.score_moments_kernel,
            dim=[self.blocks],
            inputs=[
                tr.drig.cams,
                tr.mask,
                mo.p_b,
                mo.log_outside,
                int(mo.drop_worst),
                self.x[dst],
                self.model[dst],
                self.desc[dst],
                self.mass[dst],
                self.rgb,
                dc.n_bins,
                self.logw[src],
                self.resampled,
                tr.sigma_n,
                dc.sigma_p,
                tr.sdrig.cams,
                tr.integral,
                tr.slot_xy,
                tr.slot_alive,
                tr.boxes,
                self.slot,
                tr.terms,
                self.observe,
                self.n,
                self.chunk,
            ],
            outputs=[self.logw[dst], self.part_max, self.part_arg, self.part],
            block_dim=BLOCK,
            device=d,
        )

    def estimate_from_host(self, person_id: int, age: int) -> PersonEstimate:
        """The estimate of the last frame from the host copies (after the device synchronised)."""
        e = self.est_host.numpy()
        mean = e[kreduce.EST_MEAN : kreduce.EST_MEAN + 3].copy()
        est = PersonEstimate(
            id=person_id,
            centroid=mean.copy(),
            top=float("nan"),
            mean=mean,
            std=e[kreduce.EST_STD : kreduce.EST_STD + 3].copy(),
            map=e[kreduce.EST_MAP : kreduce.EST_MAP + 3].copy(),
            ess=float(e[kreduce.EST_ESS]),
            loglik=float(e[kreduce.EST_LOGLIK]),
            age=age,
            support=float(self.support_host.numpy()[0]),
            degenerate=bool(e[kreduce.EST_DEGENERATE]),
        )
        if self.keep:
            est.particles = self.sub_x_host.numpy().copy()
            est.weights = self.sub_w_host.numpy().copy()
        return est
