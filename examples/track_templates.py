"""Track people walking on a plaza with the Python API (S3 template tracker, Juza et al.).

    python examples/track_templates.py --device cpu --frames 60
    python examples/track_templates.py --device cuda --frames 180 --particles 10000 --mog2

Renders the ``s3-people`` scene (one calibrated camera, ground truth) into a temporary folder, builds motion
masks (the scene's perfect masks, or OpenCV MOG2 background subtraction with ``--mog2``), tracks them with
:class:`wptrack.trackers.templates.tracker.TemplateTracker` frame by frame and prints the objects and the evaluation.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from wptrack.cameras.rig import Rig
from wptrack.core.device import quiet_warp, resolve_device
from wptrack.evaluation.mot import evaluate
from wptrack.motion.masks import open_masks
from wptrack.synth import render_scene
from wptrack.trackers.templates.run import TEMPLATE_COLUMNS, object_row
from wptrack.trackers.templates.tracker import TemplateConfig, TemplateTracker


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))  # the whole sentence
    ap.add_argument("--device", default="auto", help="auto, cpu, cuda or cuda:N")
    ap.add_argument("--frames", type=int, default=120, help="frames of the scene to render and track")
    ap.add_argument("--particles", type=int, default=1000)
    ap.add_argument("--mog2", action="store_true", help="background subtraction instead of the perfect masks")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    quiet_warp()
    device = resolve_device(args.device)

    with tempfile.TemporaryDirectory() as tmp:
        scene = render_scene("s3-people", Path(tmp) / "scene", frames=args.frames)
        rig = Rig.load(scene.rig_path)
        if args.mog2:
            masks = open_masks(video=scene.videos[0], camera=rig[0])
        else:
            masks = open_masks(masks=scene.mask_videos[0], camera=rig[0])
        tracker = TemplateTracker(rig, TemplateConfig(particles=args.particles, seed=args.seed), device=device)
        rows = []
        for mask in masks:
            est = tracker.step(mask)
            rows += [object_row(est.frame, o) for o in est.objects]
            if est.frame % 20 == 0:
                objs = ", ".join(f"#{o.id} {o.cls} at ({o.ground[0]:.2f}, {o.ground[1]:.2f}) m" for o in est.objects)
                print(f"frame {est.frame:4d}: {len(est.objects)} objects: {objs}; XOR penalty {est.penalty} px")
        table = {name: [row[k] for row in rows] for k, name in enumerate(TEMPLATE_COLUMNS)}
        tracks = {k: np.asarray(v) for k, v in table.items()}
        ev = evaluate(scene.groundtruth_path, tracks, threshold=1.0)
        print(
            f"accuracy {ev.accuracy:.3f} (tracking {ev.tracking_accuracy:.3f}), MOTA {ev.mota:.3f}, IDF1 {ev.idf1:.3f}"
        )
        return {"frames": tracker.frames_done, "evaluation": ev.to_dict(), "rows": len(rows)}


if __name__ == "__main__":
    main()
