"""Track two people in 3D from three cameras with the Python API (S2 multi-camera people tracker).

    python examples/track_people.py --device cpu --frames 120
    python examples/track_people.py --device cuda --frames 300 --size 640 480 --particles 2000

Renders the ``s2-office`` scene (two people enter from opposite doors, meet, shake hands and leave; furniture hides
their legs) in memory at the chosen size, makes motion masks from the rendered frames with the offline background
model (the default motion pipeline, not the scene's perfect masks), tracks with
:class:`wptrack.trackers.people.tracker.PeopleTracker` frame by frame and prints the people and the evaluation (MOTA and
IDF1 at 0.5 m on the ground, mean 3D centroid error).
"""

from __future__ import annotations

import argparse

import numpy as np

from wptrack.core.device import quiet_warp, resolve_device
from wptrack.evaluation.mot import evaluate
from wptrack.motion.masks import MaskConfig, open_masks
from wptrack.synth.office import OfficeConfig, OfficeScene
from wptrack.trackers.people.config import PeopleConfig
from wptrack.trackers.people.tracker import PeopleTracker


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))  # the whole sentence
    ap.add_argument("--device", default="auto", help="auto, cpu, cuda or cuda:N")
    ap.add_argument("--frames", type=int, default=120, help="frames of the scene to render and track")
    ap.add_argument("--size", type=int, nargs=2, default=(320, 240), metavar=("W", "H"), help="image size, pixels")
    ap.add_argument("--particles", type=int, default=500, help="particles per person")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    quiet_warp()
    device = resolve_device(args.device)

    scene = OfficeScene(OfficeConfig(width=args.size[0], height=args.size[1], frames=args.frames))
    truth = scene.trajectories(args.frames)
    rngs = [np.random.default_rng([0, k]) for k in range(len(scene.rig))]
    videos = [[] for _ in scene.rig.cameras]
    for f in range(args.frames):
        images, _ = scene.render_frame(f, {}, rngs)
        for k, img in enumerate(images):
            videos[k].append(img)
    cams = [np.stack(v) for v in videos]  # (T, H, W, 3) per camera
    masks = [open_masks(video=c, config=MaskConfig(device=device)) for c in cams]

    tracker = PeopleTracker(scene.rig, PeopleConfig(particles=args.particles, seed=args.seed), device=device)
    rows, errors = [], []
    for f, person_masks in enumerate(zip(*masks, strict=True)):
        est = tracker.step([c[f] for c in cams], list(person_masks))
        for p in est.people:
            rows.append((est.frame, p.id, *p.centroid))
            here = [traj[f] for traj in truth.values() if np.all(np.isfinite(traj[f]))]
            if here:
                d = [np.linalg.norm(p.centroid - t) for t in here]
                errors.append(min(d))
        if f % 30 == 0:
            where = ", ".join(
                f"#{p.id} at ({p.centroid[0]:.2f}, {p.centroid[1]:.2f}, {p.centroid[2]:.2f}) m" for p in est.people
            )
            print(f"frame {f:4d}: {len(est.people)} people {where}")
    tracks = {k: np.asarray([r[j] for r in rows]) for j, k in enumerate(("frame", "id", "x", "y", "z"))}
    gt = [(f, oid, *traj[f]) for oid, traj in truth.items() for f in range(args.frames) if np.all(np.isfinite(traj[f]))]
    groundtruth = {k: np.asarray([r[j] for r in gt]) for j, k in enumerate(("frame", "id", "x", "y", "z"))}
    ev = evaluate(groundtruth, tracks, threshold=0.5)
    mean_error = float(np.mean(errors)) if errors else float("nan")
    print(f"MOTA {ev.mota:.3f}, IDF1 {ev.idf1:.3f} at 0.5 m; mean 3D centroid error {100 * mean_error:.1f} cm")
    return {"frames": tracker.frames_done, "evaluation": ev.to_dict(), "mean_error": mean_error, "rows": len(rows)}


if __name__ == "__main__":
    main()
