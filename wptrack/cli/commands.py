"""The ``wptrack`` commands other than ``track`` (:mod:`wptrack.cli.track`): demo, synth, evaluate, report,
convergence, batch, masks, bench."""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from wptrack.cli.common import evaluation_line, plural, report_after_tracking
from wptrack.core.errors import ConfigError

log = logging.getLogger("wptrack")


SPREAD_METRICS = ("hota", "deta", "assa", "mota", "idf1", "accuracy", "id_switches")
"""The metrics whose spread over runs ``wptrack evaluate RUN RUN ...`` prints (all are in its --out JSON)."""


def _run_camera(run_dir: Path, rig_path, camera_arg):
    """The rig camera (at the run's frame size) and ground plane of a run's image boxes, or ``(None, None)``: a
    template run's own rig and camera unless ``--rig`` / ``--camera`` name others."""
    import json

    from wptrack.cameras.rig import Rig
    from wptrack.io.run import RUN_FILE

    try:
        run = json.loads((run_dir / RUN_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        run = {}
    config = run.get("config") or {}
    if run.get("tracker") != "templates" and rig_path is None:
        return None, None
    path = rig_path or config.get("rig")
    if path is None or not Path(path).is_file():
        return None, None
    rig = Rig.load(path)
    name = camera_arg if camera_arg is not None else config.get("camera", 0)
    camera = rig[int(name) if str(name).lstrip("-").isdigit() else name]
    size = config.get("frame_size")
    if isinstance(size, list) and len(size) == 2 and tuple(size) != (camera.width, camera.height):
        camera = camera.scaled(int(size[0]), int(size[1]))
    return camera, rig.ground_plane


def _short_run_note(run_dir: Path, tracks: Path, groundtruth) -> str | None:
    """A run that stops before the ground truth does (``--max-frames``) is scored over all the ground truth's frames,
    its missing frames as misses: the note that says so, or None. The run's last frame is run.json's ``last_frame``
    (frames without a track count), else the tracks' last frame."""
    import json

    import numpy as np

    from wptrack.io.run import RUN_FILE
    from wptrack.io.tables import read_tracks

    try:
        last = json.loads((run_dir / RUN_FILE).read_text(encoding="utf-8")).get("last_frame")
    except (OSError, ValueError):
        last = None
    if last is None:
        frames = read_tracks(tracks)["frame"]
        last = int(np.max(frames)) if len(frames) else None
    gt = groundtruth if isinstance(groundtruth, dict) else read_tracks(groundtruth, what="ground truth file")
    if last is None or not len(gt["frame"]) or int(np.max(gt["frame"])) <= int(last):
        return None
    later = np.unique(np.asarray(gt["frame"])[np.asarray(gt["frame"]) > int(last)]).size
    return (
        f"{tracks}: the tracks end at frame {int(last)}, the ground truth at frame {int(np.max(gt['frame']))}: its "
        f"{later} later labelled frames are scored as misses (track the whole video to compare with published numbers)"
    )


def cmd_evaluate(args) -> int:
    from wptrack.evaluation.mot import average, evaluate
    from wptrack.evaluation.motfiles import MOT_DIR, write_mot_files
    from wptrack.io.atomic import atomic_write_json, ensure_writable_file

    if args.out:  # a bad --out is said before the scoring and the MOTChallenge files, not as a traceback after them
        ensure_writable_file(args.out)
    runs = []
    for given in args.tracks:
        tracks = Path(given)
        runs.append((tracks, tracks / "tracks.csv" if tracks.is_dir() else tracks))
    groundtruth = args.groundtruth
    if str(groundtruth).lower().endswith(".xml"):  # image boxes (PETS/Milan): feet back-projected with the rig
        from wptrack.evaluation.groundtruth import read_box_groundtruth

        if args.rig is None:
            raise ConfigError(f"--groundtruth {groundtruth}: box annotations need --rig to back-project the feet")
        size = None
        if args.box_size is not None:
            try:
                w, h = (int(x) for x in args.box_size.lower().split("x"))
            except ValueError:
                raise ConfigError(f"--box-size: expected WIDTHxHEIGHT, e.g. 768x576, got {args.box_size!r}") from None
            size = (w, h)
        camera = args.camera if args.camera is not None else 0
        camera = int(camera) if str(camera).lstrip("-").isdigit() else camera
        groundtruth = read_box_groundtruth(groundtruth, args.rig, camera=camera, box_size=size)
    evaluations = {}
    for given, tracks in runs:
        ev = evaluate(groundtruth, tracks, threshold=args.threshold)
        note = _short_run_note(tracks.parent, tracks, groundtruth)
        if note is not None:
            log.warning(note)
        evaluations[str(given)] = ev
        print((f"{given}: " if len(runs) > 1 else "") + evaluation_line(ev, args.threshold))
        if not args.no_mot:  # MOTChallenge files beside the tracks: RUN/mot/, the ground truth in RUN/mot/gt/
            folder = tracks.parent / MOT_DIR
            cam, plane = _run_camera(tracks.parent, args.rig, args.camera)
            written = write_mot_files(tracks, folder, cam, plane, "tracks")
            written += write_mot_files(groundtruth, folder / "gt", cam, plane, "ground truth")
            print(f"MOTChallenge files: {', '.join(str(w) for w in written)}")
    spread = None
    if len(runs) > 1:
        spread = average(list(evaluations.values()))
        print(f"over {len(runs)} runs: mean (min, max, std)")
        for name in SPREAD_METRICS:
            m = spread[name]
            if m["n"]:
                print(f"  {name:12s} {m['mean']:.3f} ({m['min']:.3f}, {m['max']:.3f}, {m['std']:.3f})")
    if args.out:
        if spread is None:
            atomic_write_json(args.out, next(iter(evaluations.values())).to_dict())
        else:
            atomic_write_json(args.out, {"runs": {k: v.to_dict() for k, v in evaluations.items()}, "spread": spread})
        print(f"evaluation: {args.out}")
    return 0


# --- synth --------------------------------------------------------------------------------------------------
def cmd_synth(args) -> int:
    from wptrack.synth import render_scene

    res = render_scene(
        args.scene, args.out, frames=args.frames, seed=args.seed, progress=not args.quiet, conditions=args.conditions
    )
    extra = f" under conditions {args.conditions}" if args.conditions not in (None, "", "none") else ""
    print(f"wrote scene '{args.scene}' ({res.frames} frames){extra} to {res.out_dir}")
    return 0


# --- demo ---------------------------------------------------------------------------------------------------
def cmd_demo(args) -> int:
    import json

    from wptrack.cli.track import colour_summary_lines
    from wptrack.core.device import resolve_device
    from wptrack.synth import render_scene
    from wptrack.trackers.colour.run import run_color_tracking
    from wptrack.trackers.colour.tracker import ColorConfig, HSITarget

    device = resolve_device(args.device)  # a missing GPU is said before the scene is rendered
    out = Path(args.out)
    scene_dir = out / "scene"
    print(f"rendering the synthetic lab scene 's1-lab' into {scene_dir} ...")
    res = render_scene("s1-lab", scene_dir, frames=args.frames, seed=args.seed, progress=not args.quiet)
    hints = json.loads(Path(res.scene_json).read_text())
    tgt = hints["target"]
    target = HSITarget(hue=tuple(tgt["hue"]), sat=tuple(tgt["sat"]), intensity=tuple(tgt["intensity"]))
    config = ColorConfig(
        particles=args.particles,
        sigma=hints.get("sigma", 0.03),
        init=tuple(hints["init"]),
        seed=args.seed,
        keep_particles=min(args.particles, 500),
        proposal="prior",  # the paper's filter from the paper's initialisation
    )
    print(f"tracking the pink ball with {config.particles} particles (sigma_m = {config.sigma} m) ...")
    summary = run_color_tracking(
        res.rig_path,
        res.videos,
        target,
        out / "track",
        config,
        device=device,
        groundtruth=res.groundtruth_path,
        progress=not args.quiet,
        overwrite=True,  # the demo's own folder: running it again replaces its run
    )
    for line in colour_summary_lines(summary, out / "track"):
        print(line)
    if args.report:
        report_after_tracking(out / "track")
    return 0


# --- report -------------------------------------------------------------------------------------------------
def cmd_report(args) -> int:
    from wptrack.report import ReportOptions, build_report

    options = ReportOptions(movie=not args.no_movie, movie_frames=args.movie_frames, groundtruth=args.groundtruth)
    path = build_report(args.run_dir, out_dir=args.out, sweep=args.sweep, frames=args.frames, options=options)
    print(f"report: {path}")
    return 0


# --- convergence (section III.C) ---------------------------------------------------------------------------
def convergence_words(row: dict, jump_at: int) -> str:
    """One sweep row's convergence in words: ``converges in 3 iterations; after the jump, in 5 iterations``."""
    c0, c1 = row["converge_initial"], row["converge_after_jump"]
    first = f"converges in {plural(c0, 'iteration')}" if c0 is not None else f"no convergence in {jump_at} iterations"
    after = f"in {plural(c1, 'iteration')}" if c1 is not None else "no convergence within the run"
    return f"{first}; after the jump, {after}"


def cmd_convergence(args) -> int:
    from wptrack.trackers.colour.experiments import default_sigmas, sweep_batch

    sigmas = args.sigma or list(default_sigmas(args.steps))
    table = sweep_batch(
        args.out,
        sigmas=sigmas,
        particles=args.particles,
        iterations=args.iterations,
        jump_at=args.jump_at,
        jump=args.jump,
        sigma_obs=args.sigma_obs,
        runs=args.runs,
        seed=args.seed,
        device=args.device,
        address=args.address,
        retries=args.retries,
    )
    path = Path(args.out) / "errors.csv"
    for row in table["summary"]:
        print(f"sigma_m = {row['sigma']:.4f} m: {convergence_words(row, args.jump_at)}")
    print(f"error-vs-iteration table: {path} (runs: {Path(args.out) / 'runs'})")
    if args.report:
        report_after_tracking(args.out)
    return 0


# --- batch (Ray) -----------------------------------------------------------------------------------------------
def _batch_manifest(args):
    """The manifest of ``wptrack batch``: the file given, or the runs of ``--videos`` (one per recording) with the
    track options given on the command line."""
    if args.manifest is not None and args.videos:
        raise ConfigError("give a manifest or --videos, not both")
    if args.manifest is None and not args.videos:
        raise ConfigError("give a manifest (YAML) or --videos 'PATTERN' --tracker TRACKER")
    if args.manifest is not None:
        if args.tracker is not None:
            raise ConfigError("--tracker and the track options go with --videos; a manifest names its tracker")
        return args.manifest
    if args.tracker is None:
        raise ConfigError("--videos: give the runs' --tracker (color, templates or people)")
    from wptrack.batch.videos import VIDEO_OPTIONS, videos_manifest
    from wptrack.runs.spec import command, options_from_namespace

    cmd = command(args.tracker)
    options = options_from_namespace(cmd, args, exclude=VIDEO_OPTIONS)
    return videos_manifest(args.videos, cmd.name, options, cameras=1 if cmd.name == "templates" else None)


def batch_table(results) -> str:
    """The table ``wptrack batch`` prints at the end: id, status, frames, seconds, frames/s per run."""
    rows = []
    for r in results:
        frames = (r.get("summary") or {}).get("frames")
        secs = r.get("seconds")
        ok = isinstance(frames, int) and isinstance(secs, (int, float)) and secs > 0
        status = r["status"] + (" (reused)" if r.get("reused") else "")
        rows.append(
            (
                str(r["id"]),
                status,
                str(frames) if isinstance(frames, int) else "-",
                f"{secs:.1f}" if isinstance(secs, (int, float)) else "-",
                f"{frames / secs:.1f}" if ok else "-",
            )
        )
    head = ("id", "status", "frames", "seconds", "frames/s")
    width = [max(len(x) for x in col) for col in zip(head, *rows, strict=True)]

    def line(cells: tuple[str, ...]) -> str:  # id and status to the left, numbers to the right
        cols = zip(cells, width, strict=True)
        return "  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(cols)).rstrip()

    return "\n".join([line(head), *(line(r) for r in rows)])


def cmd_batch(args) -> int:
    from tqdm import tqdm

    from wptrack.batch import run_batch

    manifest = _batch_manifest(args)
    bar = None

    def start(total: int, pending: int) -> None:
        nonlocal bar
        bar = tqdm(total=total, desc="runs", unit="run", disable=args.quiet, dynamic_ncols=True)

    def say(r: dict) -> None:
        if bar is not None:
            bar.update(1)
        if args.quiet:
            return
        how = "already complete" if r.get("reused") else r["status"]
        secs = f" in {r['seconds']:.1f} s" if isinstance(r.get("seconds"), (int, float)) and not r.get("reused") else ""
        tries = f" ({r['attempts']} attempts)" if (r.get("attempts") or 1) > 1 else ""
        err = f": {r['error']}" if r.get("error") else ""
        tqdm.write(f"{r['id']}: {how}{secs}{tries}{err}", file=sys.stdout)

    try:
        results = run_batch(
            manifest,
            args.out,
            address=args.address,
            gpus_per_task=args.gpus_per_task,
            cpus_per_task=args.cpus_per_task,
            retries=args.retries,
            on_result=say,
            pool=args.pool,
            on_start=start,
            pin_cores=args.pin_cores,
        )
    finally:
        if bar is not None:
            bar.close()
    failed = [r["id"] for r in results if r["status"] != "complete"]
    if not args.quiet:
        print(batch_table(results))
    print(f"{len(results) - len(failed)}/{len(results)} runs complete; summary: {Path(args.out) / 'summary.csv'}")
    if failed:
        print(f"wptrack: {len(failed)} run(s) failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


# --- masks ---------------------------------------------------------------------------------------------------
def cmd_masks(args) -> int:
    from wptrack.core.config import from_namespace, option_map
    from wptrack.motion.masks import MaskConfig
    from wptrack.motion.options import check_mask_options
    from wptrack.motion.writing import write_masks

    config = from_namespace(MaskConfig, args, base=MaskConfig(device=args.device))
    if config.method != "given":  # given: write_masks says there is nothing to make
        check_mask_options(
            config, [f for f in option_map(MaskConfig) if getattr(args, f.replace("-", "_")) is not None]
        )
        if config.method != "offline" and args.device != "auto":
            raise ConfigError(
                f"--device {args.device}: the offline background model's device; {config.method} runs on the CPU "
                "(OpenCV), so it has no effect: leave it out"
            )
    summary = write_masks(args.video, args.out, config, probability=args.probability, max_frames=args.max_frames)
    print(f"{summary['frames']} masks ({config.method}) in {summary['seconds']:.1f} s: " + ", ".join(
        f"{args.out}/{name}" for name in summary["outputs"]))  # fmt: skip
    return 0


# --- bench ---------------------------------------------------------------------------------------------------
def cmd_bench(args) -> int:
    import inspect

    from wptrack.bench import HEADER, format_row, load_suite
    from wptrack.core.device import resolve_device
    from wptrack.io.atomic import atomic_write_json, ensure_writable_file
    from wptrack.io.run import versions

    suite = load_suite(args.tracker)
    device = resolve_device(args.device)
    if args.out:  # said before the cases run, not as a traceback after the first
        ensure_writable_file(args.out)
    import warp as wp

    second = getattr(suite, "second", "cameras")  # the case's second field: cameras, or objects (templates)
    for flag in ("cameras", "objects", "runs"):
        if flag != second and getattr(args, flag):
            raise ConfigError(f"--{flag}: the {args.tracker!r} suite's cases are particles x {second}; use --{second}")
    own_grid = getattr(suite, "grid_from_args", None)  # a suite whose cases are not particles x second (pipeline)
    if own_grid is None:
        for flag in ("video", "rig", "size", "variant"):
            if getattr(args, flag, None) is not None:
                raise ConfigError(f"--{flag}: only the 'pipeline' suite takes it, not {args.tracker!r}")
    elif args.particles or getattr(args, second, None):
        raise ConfigError(f"--particles/--{second}: the {args.tracker!r} suite runs the commands with their defaults")
    is_cuda = wp.get_device(device).is_cuda
    grid = suite.default_grid(is_cuda) if own_grid is None else own_grid(args, is_cuda)
    # the product of the given values, the suite's defaults for the others
    if own_grid is None and (args.particles or getattr(args, second)):
        counts = [int(p) for p in args.particles] if args.particles else sorted({g.particles for g in grid})
        seconds = getattr(args, second) or sorted({getattr(g, second) for g in grid})
        grid = [type(grid[0])(p, c) for c in seconds for p in counts]
    extra = {}
    if args.weights:  # resampling alone on synthetic log-weights, once per particle count
        if args.tracker != "color":
            raise ConfigError(f"--weights: only the 'color' suite times resampling alone, not {args.tracker!r}")
        extra["weights"] = args.weights
        grid = list({case.particles: case for case in grid}.values())
    if args.proposal is not None:  # the colour tracker's detection jumps instead of the paper's prior
        if args.tracker != "color" or args.weights:
            raise ConfigError(f"--proposal: only the 'color' suite's tracker has proposals, not {args.tracker!r}")
        extra["proposal"] = args.proposal
    if args.joint:  # the template tracker's joint filter (one weight per particle) instead of the partitioned one
        if args.tracker != "templates":
            raise ConfigError(
                f"--joint: only the 'templates' suite has a joint and a partitioned filter, not {args.tracker!r}"
            )
        extra["partition"] = False
    if args.frames is not None and "e2e" in inspect.signature(suite.run_case).parameters:
        extra["e2e"] = args.frames  # --frames also bounds a suite's end-to-end pass (masks: 600 frames by default)
    if not (args.particles or getattr(args, second)):  # the default grid: say what it leaves out
        for note in getattr(suite, "notes", lambda is_cuda: [])(wp.get_device(device).is_cuda):
            print(note)
    results = []
    row = getattr(suite, "format_row", format_row)
    if args.weights:
        from wptrack.bench.resample_weights import WEIGHTS_HEADER

        print(WEIGHTS_HEADER)
    else:
        print(getattr(suite, "HEADER", HEADER))
    for i, case in enumerate(grid):
        frames = args.frames if args.frames is not None else getattr(suite, "default_frames", 50)
        if not args.quiet:  # a case can take a while: say which one runs
            describe = getattr(suite, "describe", None)
            what = (
                describe(case, frames, extra.get("e2e"))
                if describe
                else ", ".join(f"{k} {v}" for k, v in vars(case).items())
            )
            print(f"{args.tracker}: case {i + 1}/{len(grid)}: {what} ...", file=sys.stderr, flush=True)
        r = suite.run_case(case, device, frames=frames, numpy_max=args.numpy_max, **extra)
        results.append(r)
        print(row(r), flush=True)
        if args.out:
            atomic_write_json(args.out, {"device": device, "versions": versions(), "results": results})
    if args.out:
        print(f"results: {args.out}")
    bad = [r for r in results if r.get("equivalent") is False]
    if bad:
        print(f"wptrack: {len(bad)} case(s) disagree with the NumPy reference", file=sys.stderr)
        return 1
    failed = [r for r in results if r.get("passed") is False]  # e.g. the soak suite's memory criteria
    if failed:
        print(f"wptrack: {len(failed)} case(s) failed the suite's criteria", file=sys.stderr)
        return 1
    return 0
