"""Track the pink ball of the synthetic lab scene with the Python API (S1 colour particle filter).

    python examples/track_colour.py --device cpu --frames 60
    python examples/track_colour.py --device cuda --frames 200 --particles 100000

Renders the ``s1-lab`` scene (two calibrated webcams, ground truth) into a temporary folder, tracks it with
:class:`wptrack.trackers.colour.tracker.ColorTracker` and prints the 3D error against the ground truth.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from wptrack.cameras.rig import Rig
from wptrack.core.device import quiet_warp
from wptrack.evaluation.convergence import summarize
from wptrack.io.frames import open_frames
from wptrack.io.tables import read_tracks
from wptrack.synth import render_scene
from wptrack.trackers.colour.tracker import ColorTracker, HSITarget


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))  # the whole sentence
    ap.add_argument("--device", default="auto", help="auto, cpu, cuda or cuda:N")
    ap.add_argument("--frames", type=int, default=200, help="frames of the scene to render and track")
    ap.add_argument("--particles", type=int, default=200)
    ap.add_argument("--sigma", type=float, default=0.03, help="sigma_m, metres")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    quiet_warp()

    with tempfile.TemporaryDirectory() as tmp:
        scene = render_scene("s1-lab", Path(tmp) / "scene", frames=args.frames, seed=args.seed)
        hints = json.loads(Path(scene.scene_json).read_text())["target"]
        rig = Rig.load(scene.rig_path)
        target = HSITarget(hue=tuple(hints["hue"]), sat=tuple(hints["sat"]), intensity=tuple(hints["intensity"]))
        tracker = ColorTracker(
            rig,
            target,
            particles=args.particles,
            sigma=args.sigma,
            init=(0.4, 0.1, 0.2),
            device=args.device,
            seed=args.seed,
        )
        truth = read_tracks(scene.groundtruth_path)
        truth = np.column_stack([truth["x"], truth["y"], truth["z"]])
        errors = []
        for est in tracker.track(open_frames([str(v) for v in scene.videos])):
            errors.append(float(np.linalg.norm(est.mean - truth[est.frame])))
            if est.frame % 20 == 0:
                print(
                    f"frame {est.frame:4d}: estimate {np.round(est.mean, 3)} m, error {100 * errors[-1]:6.2f} cm,"
                    f" spread {np.round(100 * est.std, 1)} cm"
                )
    summary = summarize(np.asarray(errors)).as_dict()
    if summary["converged_at"] is None:
        result = f"did not converge to 5 cm (final error {100 * summary['final_error']:.1f} cm)"
    else:
        result = (
            f"converged at frame {summary['converged_at']}; error after it: mean "
            f"{100 * summary['mean_error_after']:.2f} cm, median {100 * summary['median_error_after']:.2f} cm, "
            f"max {100 * summary['max_error_after']:.2f} cm"
        )
    print(f"device {tracker.device}, {tracker.score_mode} scoring, {summary['frames']} frames: {result}")
    return summary


if __name__ == "__main__":
    main()
