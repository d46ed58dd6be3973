"""The filter-dynamics experiment of the extended Barrera et al. paper (section III.C): the S1 particle filter
(gaussian walk, eqs. 1-3) driven by 3D point observations of the object through a 3D gaussian observation
model, to study convergence speed against sigma_m without the image likelihood.

``log p(obs | x) = -|x - obs|^2 / (2 sigma_obs^2)`` (constants dropped: they cancel when normalising).
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from wptrack.core.device import resolve_device
from wptrack.core.errors import ConfigError
from wptrack.core.filter import Estimate, ParticleFilter
from wptrack.kernels.colour import scoring as kscoring


class Gaussian3DTracker(ParticleFilter):
    """Point particle filter with 3D gaussian observations.

    Args:
        particles: N.
        sigma: sigma_m of the gaussian walk, metres.
        sigma_obs: deviation of the 3D observation model, metres.
        init: initial point (all particles there) or None for ``init_box``.
        init_box: (min, max) metres for a uniform start.
        device, seed, resampling, ess_threshold, use_graph: as :class:`wptrack.core.filter.ParticleFilter`.
    """

    def __init__(
        self,
        particles: int = 200,
        sigma: float = 0.03,
        sigma_obs: float = 0.05,
        init=(0.0, 0.0, 0.0),
        init_box=None,
        device: str | None = "auto",
        seed: int = 0,
        resampling: str = "systematic",
        ess_threshold: float = 1.0,
        use_graph: bool | None = None,
    ) -> None:
        if not (isinstance(sigma_obs, (int, float)) and math.isfinite(sigma_obs) and sigma_obs > 0):
            raise ConfigError(f"sigma_obs: expected a deviation > 0 metres, got {sigma_obs!r}")
        super().__init__(
            particles,
            sigma,
            resolve_device(device),
            seed=seed,
            resampling=resampling,
            ess_threshold=ess_threshold,
            use_graph=use_graph,
        )
        self.sigma_obs = wp.array([sigma_obs], dtype=wp.float32, device=self.device)
        self.observation = wp.zeros(1, dtype=wp.vec3, device=self.device)
        self._obs_host = wp.zeros(1, dtype=wp.vec3, device="cpu", pinned=self.is_cuda)
        if init is not None:
            self.init_point(init)
        elif init_box is not None:
            self.init_box(*init_box)
        else:
            raise ConfigError("init: give a point or init_box")

    def _launch_predict_score(self, src: int, dst: int) -> None:
        kernel = kscoring.gaussian3d_predict_score_kernel
        self._launch_fused(kernel, [self.observation, self.sigma_obs], src, dst)

    def step(self, observation) -> Estimate:
        """One iteration with a 3D observation (3,) metres."""
        obs = np.asarray(observation, dtype=np.float32).reshape(3)
        self._obs_host.numpy()[0] = obs
        wp.copy(self.observation, self._obs_host)
        return self.advance()
