"""The systematic drift of the colour particle filter along camera 1's optical ray (Barrera et al., section III,
Figs. 4-5): the likelihood along the ray, and two runs initialised nearer and further than the ball.

    python examples/drift.py --device cpu --frames 100
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from wptrack.cameras.rig import Rig
from wptrack.core.device import quiet_warp
from wptrack.io.frames import open_frames
from wptrack.io.tables import read_tracks
from wptrack.synth import render_scene
from wptrack.trackers.colour.experiments import drift_study
from wptrack.trackers.colour.tracker import ColorTracker, HSITarget


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))  # the whole sentence
    ap.add_argument("--device", default="auto")
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--particles", type=int, default=200)
    ap.add_argument("--offset", type=float, default=0.5, help="initial point this far beyond/before the ball, m")
    args = ap.parse_args(argv)
    quiet_warp()
    with tempfile.TemporaryDirectory() as tmp:
        scene = render_scene("s1-lab", Path(tmp) / "scene", frames=args.frames)
        rows = drift_study(scene.out_dir, device=args.device)
        print(
            "depth beyond the ball along cam1's ray [m] | log p cam1, cam2 | moves staying on the ball in cam1:"
            " further / closer | mean depth change of those [mm]"
        )
        for r in rows:
            print(
                f"  {r['depth']:+.2f} | {r['loglik'][0]:+.2f} {r['loglik'][1]:+.2f} | {r['keep_further']:.3f} / "
                f"{r['keep_closer']:.3f} | {1000 * r['bias']:+.1f}"
            )
        rig = Rig.load(scene.rig_path)
        hints = json.loads(Path(scene.scene_json).read_text())["target"]
        target = HSITarget(hue=tuple(hints["hue"]), sat=tuple(hints["sat"]), intensity=tuple(hints["intensity"]))
        gt = read_tracks(scene.groundtruth_path)
        ball = np.array([gt["x"][0], gt["y"][0], gt["z"][0]])
        ray = (ball - rig[0].center) / np.linalg.norm(ball - rig[0].center)
        runs = {}
        for name, sign in (("nearer", -1.0), ("further", 1.0)):
            init = ball + sign * args.offset * ray
            tracker = ColorTracker(
                rig,
                target,
                particles=args.particles,
                sigma=0.03,
                init=tuple(init),
                device=args.device,
                proposal="prior",
            )
            depth = [float((e.mean - ball) @ ray) for e in tracker.track(open_frames([str(v) for v in scene.videos]))]
            runs[name] = depth
            print(
                f"init {args.offset:.2f} m {name} than the ball: depth beyond the ball every 10 frames [m]: "
                + " ".join(f"{d:+.2f}" for d in depth[::10])
            )
    return {"profile": rows, "runs": runs}


if __name__ == "__main__":
    main()
