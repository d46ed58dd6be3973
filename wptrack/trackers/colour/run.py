"""Running the S1 colour tracker on synchronised videos (one per camera), writing the run folder as it goes.

Outputs::

    out_dir/tracks.csv     frame,id,x,y,z,sx,sy,sz,map_x,map_y,map_z,ess,loglik,detection,degenerate (metres)
    out_dir/particles.npz  a subsample of each frame's weighted particle cloud
    out_dir/run.json       configuration, inputs, device, versions, timings, summary (error vs ground truth)
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.config import REQUIRED, check, param
from wptrack.core.errors import ConfigError
from wptrack.runs.loop import TrackerRun, run_tracker

TRACK_COLUMNS = ["frame", "id", "x", "y", "z", "sx", "sy", "sz", "map_x", "map_y", "map_z", "ess", "loglik"]
COLOR_TRACK_COLUMNS = [*TRACK_COLUMNS, "detection", "degenerate"]
"""``detection``: 1 when the mixture proposal found detection candidates this frame (colour blobs that triangulate
across two cameras), 0 = none (the frame was tracked with the paper's walk alone), -1 with ``--proposal prior`` (no
detector). ``degenerate``: 1 when every
particle had zero likelihood (all log-weights -inf: the predicted cloud is kept with uniform weights, the prior)."""


class ColourRun(TrackerRun):
    """The colour tracker as a run-loop job. Everything the user gave is validated here (rig, videos, camera
    count, frame sizes, device, parameters), before the run loop touches the output folder.

    Args:
        rig_path: rig file (YAML/JSON).
        videos: one video / image folder / glob per camera, in rig order.
        target: ``HSITarget``.
        config: ``ColorConfig``.
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``.
        stop_at_shortest: track the common part of videos of unequal lengths.
        max_frames: stop after this many frames.
        groundtruth: groundtruth.csv (``frame,id,x,y,z``) to report the error against; ignored when missing.
    """

    name = "color"
    columns = COLOR_TRACK_COLUMNS

    def __init__(
        self,
        rig_path: str | Path,
        videos: Sequence,
        target: Any,
        config: Any,
        device: str = "auto",
        stop_at_shortest: bool = False,
        max_frames: int | None = None,
        groundtruth: str | Path | None = None,
    ) -> None:
        from wptrack.cameras.rig import Rig
        from wptrack.core.device import resolve_device
        from wptrack.io.frames import open_frames
        from wptrack.io.tables import read_tracks
        from wptrack.trackers.colour.tracker import ColorTracker

        rig = Rig.load(rig_path)
        if len(videos) != len(rig):
            raise ConfigError(
                f"{len(videos)} video(s) given for a rig of {len(rig)} camera(s) in {rig_path} ({', '.join(rig.names)})"
            )
        self._frames = open_frames(list(videos), stop_at_shortest=stop_at_shortest, max_frames=max_frames)
        rig = rig.at_sizes(self._frames.sizes, [str(n) for n in self._frames.names])  # a resized copy: K scaled
        device = resolve_device(device)
        self._truth = None
        if groundtruth is not None and Path(groundtruth).exists():
            gt = read_tracks(groundtruth, what="ground truth file")
            if "z" not in gt:  # the ball's error is 3D; a ground-plane table (frame,id,x,y) cannot give it
                raise ConfigError(
                    f"--groundtruth {groundtruth}: the colour tracker's error is 3D; expected the columns frame,id,"
                    f"x,y,z (as wptrack synth writes), got {','.join(gt)}"
                )
            self._truth = np.column_stack([gt["x"], gt["y"], gt["z"]])
        self.tracker = ColorTracker(rig, target, config=config, device=device)
        self.total = len(self._frames)
        self.particles_every = 1
        self.particles_max = max(1, config.keep_particles)
        self.config = {
            "rig": str(Path(rig_path).resolve()),
            "videos": [str(v) for v in videos],
            "target": {"hue": target.hue, "sat": target.sat, "intensity": target.intensity},
            "tracker": {**asdict(self.tracker.config), "score_mode_resolved": self.tracker.score_mode},
        }
        self._errors: list[float] = []
        self._k = 0

    def info(self) -> dict[str, Any]:
        return {"device": self.tracker.device, "seed": self.tracker.config.seed}

    def frames(self) -> Iterable[Any]:
        return self._frames

    def step(self, item: Any) -> Any:
        return self.tracker.step(item)

    def record(self, est: Any, out: Any) -> None:
        detection = -1 if est.detection < 0 else int(est.detection > 0)
        row = [est.frame, 0, *est.mean, *est.std, *est.map, est.ess, est.loglik, detection, int(est.degenerate)]
        out.add_rows([row])
        if est.particles is not None:
            out.add_particles(est.frame, est.particles, est.weights)
        if self._truth is not None and self._k < len(self._truth):
            self._errors.append(float(np.linalg.norm(est.mean - self._truth[self._k])))
        self._k += 1

    def state_dict(self) -> dict[str, Any]:
        errors = np.asarray(self._errors, dtype=np.float64)
        return {**self.tracker.state_dict(), "job.errors": errors, "job.k": np.int64(self._k)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        super().load_state_dict(state)
        self._errors = [float(e) for e in state["job.errors"]]
        self._k = int(state["job.k"])

    def summary(self) -> dict[str, Any]:
        from wptrack.evaluation.convergence import summarize

        tr = self.tracker
        summary: dict[str, Any] = {"frames": tr.frames_done, "device": tr.device, "score_mode": tr.score_mode}
        if self._truth is not None and self._errors:
            summary["error"] = summarize(np.asarray(self._errors)).as_dict()
        return summary


def run_color_tracking(
    rig_path: str | Path,
    videos: Sequence,
    target: Any,
    out_dir: str | Path,
    config: Any,
    device: str = "auto",
    stop_at_shortest: bool = False,
    max_frames: int | None = None,
    groundtruth: str | Path | None = None,
    progress: bool = False,
    resume: bool = False,
    checkpoint_seconds: float = 60.0,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Track a coloured object in synchronised videos and write ``tracks.csv``, ``run.json`` and
    ``particles.npz`` into ``out_dir`` as the run goes (see :class:`ColourRun` for the arguments).

    ``resume``, ``checkpoint_seconds`` and ``overwrite``: see :func:`wptrack.runs.run_tracker`.

    Returns:
        The run summary (also in run.json).
    """
    job = ColourRun(rig_path, videos, target, config, device, stop_at_shortest, max_frames, groundtruth)
    return run_tracker(
        job, out_dir, progress=progress, resume=resume, checkpoint_seconds=checkpoint_seconds, overwrite=overwrite
    )


@dataclass(frozen=True)
class ColourInputs:
    """The inputs of a colour run (``wptrack track color``)."""

    rig: str = param(REQUIRED, help="rig file (YAML/JSON)")
    video: tuple[str, ...] = param(
        REQUIRED, help="video file, image folder or glob, one per camera in rig order (repeat --video)"
    )
    init_random: bool = param(False, help="start the particles uniformly in --volume or the rig's working volume")
    stop_at_shortest: bool = param(False, help="track the common part of videos of unequal lengths")

    def __post_init__(self) -> None:
        check(self)


def run_colour_job(
    inputs: ColourInputs, target: Any, config: Any, control: Any, progress: bool = False
) -> dict[str, Any]:
    """``wptrack track color``: the run of :func:`run_color_tracking` from its declared parts (inputs, the target
    colour, the tracker's config, the run control); the CLI and ``wptrack batch`` call this.

    Raises:
        ConfigError: neither or both of ``init`` and ``init_random``.
    """
    if inputs.init_random and config.init is not None:
        raise ConfigError("give --init X Y Z or --init-random, not both")
    if not inputs.init_random:
        if config.init is None:
            raise ConfigError("give --init X Y Z or --init-random")
        if config.init_box is not None:
            raise ConfigError("--volume: only with --init-random (the box the particles start in)")
    elif config.init_box is None:
        config = replace(config, init=None)  # the tracker uses the rig's working volume
    return run_color_tracking(
        inputs.rig,
        list(inputs.video),
        target,
        control.out,
        config,
        device=control.device,
        stop_at_shortest=inputs.stop_at_shortest,
        max_frames=control.max_frames,
        groundtruth=control.groundtruth,
        progress=progress,
        resume=control.resume,
        checkpoint_seconds=control.checkpoint_every,
        overwrite=control.overwrite,
    )
