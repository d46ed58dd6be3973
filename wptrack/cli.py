"""``wptrack`` command line: demo, synth, track, convergence.

User mistakes (bad rig field, missing video, out-of-range parameter, no CUDA, unwritable output) print one
line ``wptrack: error: ...`` on stderr and exit with code 2, without a traceback and before any output is
written. Ctrl-C exits with 130 and leaves valid partial outputs.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from . import __version__
from .errors import ConfigError, WptrackError
from .runs.colour import TRACK_COLUMNS, run_color_tracking  # noqa: F401  (re-exported API)

log = logging.getLogger("wptrack")


# --- argument helpers ---------------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors and exit code 2 (argparse's default code, but our message format)."""

    def error(self, message: str):  # noqa: D401
        self.exit(2, f"wptrack: error: {message}\n")


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def _add_run_control(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the interrupted run in --out from its checkpoint (same inputs and options)",
    )
    p.add_argument(
        "--checkpoint-every",
        type=float,
        default=60.0,
        metavar="SECONDS",
        help="save the tracker state for --resume at most this often (default 60; 0: only when interrupted)",
    )


def _add_device(p: argparse.ArgumentParser) -> None:
    p.add_argument("--device", default="auto", help="auto (CUDA when available), cpu, cuda or cuda:N")


# --- track color -----------------------------------------------------------------------------------------
def _target_from_args(args):
    from .trackers.colour import HSITarget

    return HSITarget(hue=tuple(args.hue), sat=tuple(args.sat), intensity=tuple(args.intensity))


def _color_config_from_args(args):
    from .trackers.colour import ColorConfig

    init = tuple(args.init) if args.init is not None else None
    init_box = None
    if args.init_random:
        init = None
        if args.volume is not None:
            init_box = (tuple(args.volume[:3]), tuple(args.volume[3:]))
    if not args.init_random and init is None:
        raise ConfigError("give --init X Y Z or --init-random")
    return ColorConfig(
        particles=args.particles,
        sigma=args.sigma,
        init=init,
        init_box=init_box,
        resampling=args.resampling,
        ess_threshold=args.ess_threshold,
        score_mode=args.score_mode,
        seed=args.seed,
        keep_particles=args.keep_particles,
        proposal=args.proposal,
        mixture=args.mixture,
    )


def cmd_track_color(args) -> int:
    config = _color_config_from_args(args)  # without an init box the tracker uses the rig's working volume
    summary = run_color_tracking(
        args.rig,
        args.video,
        _target_from_args(args),
        args.out,
        config,
        device=args.device,
        stop_at_shortest=args.stop_at_shortest,
        max_frames=args.max_frames,
        groundtruth=args.groundtruth,
        progress=not args.quiet,
        resume=args.resume,
        checkpoint_seconds=args.checkpoint_every,
    )
    _print_summary(summary, args.out)
    if args.report:
        _report_after_tracking(args.out)
    return 0


def _print_summary(summary: dict, out_dir) -> None:
    print(f"tracked {summary['frames']} frames on {summary['device']} ({summary['score_mode']} scoring)")
    err = summary.get("error")
    if err:
        if err["converged_at"] is None:
            print(f"did not converge (final error {100 * err['final_error']:.1f} cm)")
        else:
            print(
                f"converged at frame {err['converged_at']}; error after convergence: mean "
                f"{100 * err['mean_error_after']:.2f} cm, median {100 * err['median_error_after']:.2f} cm, "
                f"max {100 * err['max_error_after']:.2f} cm"
            )
    print(f"outputs: {out_dir}/tracks.csv, run.json, particles.npz")


# --- track templates -----------------------------------------------------------------------------------------
def _template_config_from_args(args, fps: float | None):
    from .trackers.templates import TemplateConfig

    kw = {
        "particles": args.particles,
        "max_objects": args.max_objects,
        "camera": int(args.camera) if args.camera.isdigit() else args.camera,
        "classes": tuple(args.classes),
        "seed": args.seed,
        "resampling": args.resampling,
        "partition": not args.joint,
    }
    for name in (
        "scale",
        "t_add",
        "t_del",
        "add_min_gain",
        "min_existence",
        "min_in_image",
        "candidate_step_px",
        "vehicle_entry_px",
        "human_entry_px",
        "min_track_frames",
        "backfill_seconds",
        "backfill_min_frames",
        "stitch_seconds",
        "stitch_distance",
    ):
        value = getattr(args, name)
        if value is not None:
            kw[name] = value
    if args.fps is not None:
        kw["fps"] = args.fps
    elif fps:
        kw["fps"] = fps
    return TemplateConfig(**kw)


def _mask_config_from_args(args):
    from .masks import MaskConfig

    return MaskConfig(
        method=args.mask_method,
        history=args.mask_history,
        var_threshold=args.mask_threshold if args.mask_method == "mog2" and args.mask_threshold else 16.0,
        dist2_threshold=args.mask_threshold if args.mask_method == "knn" and args.mask_threshold else 400.0,
        detect_shadows=not args.keep_shadows,
        open_px=args.open_px,
        close_px=args.close_px,
        min_area=args.min_area,
        device=args.device,
    )


def cmd_track_templates(args) -> int:
    from .frames import open_source
    from .runs.templates import run_template_tracking

    fps = None
    if args.fps is None:  # the frame rate of the video, or of the given masks when they are a video
        source = args.video if args.video is not None else args.masks
        if source is not None:
            fps = open_source(source).fps
    config = _template_config_from_args(args, fps)
    summary = run_template_tracking(
        args.rig,
        args.out,
        config,
        video=args.video,
        masks=args.masks,
        mask_config=_mask_config_from_args(args),
        device=args.device,
        max_frames=args.max_frames,
        save_masks=args.save_masks,
        virtual=not args.no_virtual,
        progress=not args.quiet,
        resume=args.resume,
        checkpoint_seconds=args.checkpoint_every,
    )
    print(
        f"tracked {summary['frames']} frames on {summary['device']}: {summary['objects']} objects "
        f"({summary['classes']['human']} human, {summary['classes']['vehicle']} vehicle)"
    )
    print(f"outputs: {args.out}/tracks.csv, best.csv, run.json" + ("" if args.no_virtual else ", virtual.avi"))
    if args.groundtruth:
        _print_evaluation(args.groundtruth, Path(args.out) / "tracks.csv", 1.0)
    if args.report:
        _report_after_tracking(args.out)
    return 0


# --- track people -------------------------------------------------------------------------------------------
def _people_config_from_args(args):
    from dataclasses import replace

    from .trackers.people_model import PeopleConfig

    cfg = PeopleConfig(particles=args.particles, seed=args.seed)
    dyn = {
        k: v
        for k, v in (("sigma_pos", args.sigma_pos), ("sigma_vel", args.sigma_vel), ("alpha", args.alpha))
        if v is not None
    }
    mot = {"p_b": args.p_b} if args.p_b is not None else {}
    desc = {k: v for k, v in (("r_n", args.r_n), ("n_bins", args.bins)) if v is not None}
    birth = {"max_people": args.max_people} if args.max_people is not None else {}
    return replace(
        cfg,
        dynamics=replace(cfg.dynamics, **dyn),
        motion=replace(cfg.motion, **mot),
        descriptor=replace(cfg.descriptor, **desc),
        birth=replace(cfg.birth, **birth),
    )


def cmd_track_people(args) -> int:
    from .runs.people import run_people_tracking

    summary = run_people_tracking(
        args.rig,
        args.video,
        args.out,
        _people_config_from_args(args),
        mask_config=_mask_config_from_args(args),
        masks=args.masks,
        device=args.device,
        stop_at_shortest=args.stop_at_shortest,
        max_frames=args.max_frames,
        occupancy_every=args.occupancy_every,
        save_masks=args.save_masks,
        progress=not args.quiet,
        resume=args.resume,
        checkpoint_seconds=args.checkpoint_every,
    )
    print(f"tracked {summary['frames']} frames on {summary['device']}: {summary['people']} people")
    print(f"outputs: {args.out}/tracks.csv, hulls/, occupancy.npz, run.json")
    if args.groundtruth:
        _print_evaluation(args.groundtruth, Path(args.out) / "tracks.csv", 0.5)
    if args.report:
        _report_after_tracking(args.out)
    return 0


# --- evaluate ------------------------------------------------------------------------------------------------
def _print_evaluation(groundtruth, tracks, threshold: float, out: str | None = None) -> None:
    from .evaluation import evaluate
    from .io import atomic_write_json

    ev = evaluate(groundtruth, tracks, threshold=threshold)
    cls = "n/a" if ev.classification_accuracy is None else f"{ev.classification_accuracy:.3f}"
    print(
        f"accuracy {ev.accuracy:.3f} (tracking {ev.tracking_accuracy:.3f} x classification {cls}); "
        f"MOTA {ev.mota:.3f}, IDF1 {ev.idf1:.3f}, ID switches {ev.id_switches} at {threshold} m"
    )
    if out:
        atomic_write_json(out, ev.to_dict())
        print(f"evaluation: {out}")


def cmd_evaluate(args) -> int:
    tracks = Path(args.tracks)
    if tracks.is_dir():
        tracks = tracks / "tracks.csv"
    groundtruth = args.groundtruth
    if str(groundtruth).lower().endswith(".xml"):  # image boxes (PETS/Milan): feet back-projected with the rig
        from .groundtruth import read_box_groundtruth

        if args.rig is None:
            raise ConfigError(f"--groundtruth {groundtruth}: box annotations need --rig to back-project the feet")
        size = None
        if args.box_size is not None:
            try:
                w, h = (int(x) for x in args.box_size.lower().split("x"))
            except ValueError:
                raise ConfigError(f"--box-size: expected WIDTHxHEIGHT, e.g. 768x576, got {args.box_size!r}") from None
            size = (w, h)
        camera = int(args.camera) if str(args.camera).lstrip("-").isdigit() else args.camera
        groundtruth = read_box_groundtruth(groundtruth, args.rig, camera=camera, box_size=size)
    _print_evaluation(groundtruth, tracks, args.threshold, args.out)
    return 0


# --- synth --------------------------------------------------------------------------------------------------
def cmd_synth(args) -> int:
    from .synth import render_scene

    res = render_scene(
        args.scene, args.out, frames=args.frames, seed=args.seed, progress=not args.quiet, conditions=args.conditions
    )
    extra = f" under conditions {args.conditions}" if args.conditions not in (None, "", "none") else ""
    print(f"wrote scene '{args.scene}' ({res.frames} frames){extra} to {res.out_dir}")
    return 0


# --- demo ---------------------------------------------------------------------------------------------------
def cmd_demo(args) -> int:
    import json

    from .synth import render_scene
    from .trackers.colour import ColorConfig, HSITarget

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
    )
    print(f"tracking the pink ball with {config.particles} particles (sigma_m = {config.sigma} m) ...")
    summary = run_color_tracking(
        res.rig_path,
        res.videos,
        target,
        out / "track",
        config,
        device=args.device,
        groundtruth=res.groundtruth_path,
        progress=not args.quiet,
    )
    _print_summary(summary, out / "track")
    if args.report:
        _report_after_tracking(out / "track")
    return 0


# --- report -------------------------------------------------------------------------------------------------
def _report_after_tracking(run_dir) -> None:
    from .report import build_report

    print("rendering the report ...")
    print(f"report: {build_report(run_dir)}")


def cmd_report(args) -> int:
    from .report import ReportOptions, build_report

    options = ReportOptions(movie=not args.no_movie, movie_frames=args.movie_frames, groundtruth=args.groundtruth)
    path = build_report(args.run_dir, out_dir=args.out, sweep=args.sweep, frames=args.frames, options=options)
    print(f"report: {path}")
    return 0


# --- convergence (section III.C) ---------------------------------------------------------------------------
def cmd_convergence(args) -> int:
    from .experiments import default_sigmas, sweep_batch

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
        c0 = row["converge_initial"]
        c1 = row["converge_after_jump"]
        print(
            f"sigma_m = {row['sigma']:.4f} m: converges in {c0 if c0 is not None else '>' + str(args.jump_at)} "
            f"iterations, after the jump in {c1 if c1 is not None else 'not within the run'}"
        )
    print(f"error-vs-iteration table: {path} (runs: {Path(args.out) / 'runs'})")
    if args.report:
        _report_after_tracking(args.out)
    return 0


# --- batch (Ray) -----------------------------------------------------------------------------------------------
def cmd_batch(args) -> int:
    from .batch import run_batch

    def say(r: dict) -> None:
        if args.quiet:
            return
        how = "already complete" if r.get("reused") else r["status"]
        secs = f" in {r['seconds']:.1f} s" if isinstance(r.get("seconds"), (int, float)) and not r.get("reused") else ""
        tries = f" ({r['attempts']} attempts)" if (r.get("attempts") or 1) > 1 else ""
        err = f": {r['error']}" if r.get("error") else ""
        print(f"{r['id']}: {how}{secs}{tries}{err}", flush=True)

    results = run_batch(
        args.manifest,
        args.out,
        address=args.address,
        gpus_per_task=args.gpus_per_task,
        cpus_per_task=args.cpus_per_task,
        retries=args.retries,
        on_result=say,
    )
    failed = [r["id"] for r in results if r["status"] != "complete"]
    print(f"{len(results) - len(failed)}/{len(results)} runs complete; summary: {Path(args.out) / 'summary.csv'}")
    if failed:
        print(f"wptrack: {len(failed)} run(s) failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


# --- masks ---------------------------------------------------------------------------------------------------
def cmd_masks(args) -> int:
    from .masks import MaskConfig, write_masks

    kw = {"method": args.method, "device": args.device, "detect_shadows": not args.keep_shadows}
    for name in ("window", "samples", "fg_threshold", "noise_floor", "shadow_lo", "shadow_hi", "shadow_chroma",
                 "soft_scale", "history", "open_px", "close_px", "min_area", "fg_low", "spread_cap", "shadow_band",
                 "neighbourhood", "illum_tiles", "illum_radius", "illum_veto", "illum_grad", "mode_band"):  # fmt: skip
        if getattr(args, name) is not None:
            kw[name] = getattr(args, name)
    summary = write_masks(
        args.video, args.out, MaskConfig(**kw), probability=args.probability, max_frames=args.max_frames
    )
    print(f"{summary['frames']} masks ({args.method}) in {summary['seconds']:.1f} s: " + ", ".join(
        f"{args.out}/{name}" for name in summary["outputs"]))  # fmt: skip
    return 0


# --- bench ---------------------------------------------------------------------------------------------------
def cmd_bench(args) -> int:
    from .bench import HEADER, format_row, load_suite
    from .device import resolve_device
    from .io import atomic_write_json, versions

    suite = load_suite(args.tracker)
    device = resolve_device(args.device)
    import warp as wp

    second = getattr(suite, "second", "cameras")  # the case's second field: cameras, or objects (templates)
    for flag in ("cameras", "objects", "runs"):
        if flag != second and getattr(args, flag):
            raise ConfigError(f"--{flag}: the {args.tracker!r} suite's cases are particles x {second}; use --{second}")
    grid = suite.default_grid(wp.get_device(device).is_cuda)
    if args.particles or getattr(args, second):  # the product of the given values, the suite's defaults for the others
        counts = [int(p) for p in args.particles] if args.particles else sorted({g.particles for g in grid})
        seconds = getattr(args, second) or sorted({getattr(g, second) for g in grid})
        grid = [type(grid[0])(p, c) for c in seconds for p in counts]
    extra = {}
    if args.weights:  # resampling alone on synthetic log-weights, once per particle count
        if args.tracker != "color":
            raise ConfigError(f"--weights: only the 'color' suite times resampling alone, not {args.tracker!r}")
        extra["weights"] = args.weights
        grid = list({case.particles: case for case in grid}.values())
    if args.joint:  # the template tracker's joint filter (one weight per particle) instead of the partitioned one
        if args.tracker != "templates":
            raise ConfigError(
                f"--joint: only the 'templates' suite has a joint and a partitioned filter, not {args.tracker!r}"
            )
        extra["partition"] = False
    results = []
    row = getattr(suite, "format_row", format_row)
    print(getattr(suite, "HEADER", HEADER))
    for case in grid:
        frames = args.frames if args.frames is not None else getattr(suite, "default_frames", 50)
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


# --- parser -------------------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="wptrack", description="Particle-filter 3D object tracking from calibrated cameras (Warp).")
    p.add_argument("--version", action="version", version=f"wptrack {__version__}")
    p.add_argument("--debug", action="store_true", help="debug logging; show the traceback of errors")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
    common.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    common.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    d = sub.add_parser(
        "demo", parents=[common], help="synthesise the lab scene and track the ball (no GPU, display or download)"
    )
    d.add_argument("--out", default="wptrack-demo", help="output folder (default: ./wptrack-demo)")
    d.add_argument("--frames", type=_positive_int, default=None, help="frames to render (scene default)")
    d.add_argument("--particles", type=_positive_int, default=200)
    d.add_argument("--seed", type=int, default=0)
    _add_device(d)
    d.add_argument(
        "--report", action=argparse.BooleanOptionalAction, default=True, help="render the report (default: on)"
    )
    d.set_defaults(func=cmd_demo)

    s = sub.add_parser("synth", parents=[common], help="render a synthetic calibrated scene with ground truth")
    s.add_argument("scene", help="scene name (e.g. s1-lab, s1-lab-jump)")
    s.add_argument("--out", required=True)
    s.add_argument("--frames", type=_positive_int, default=None)
    s.add_argument(
        "--seed",
        type=int,
        default=0,
        help="scene seed: the sensor noise; s2 and s3 scenes also draw their people/cars from it "
        "(s3: 0 = the fixed sequence, others new sequences of the same type)",
    )
    s.add_argument(
        "--conditions",
        default=None,
        help="s3 scenes only: comma-separated hard conditions, each alone measurable: static-start, stop-and-go, sun, "
        "light-change, noise, compression, dark-car, clouds, exposure, short; or all (default: none; see "
        "wptrack.synth.conditions)",
    )
    s.set_defaults(func=cmd_synth)

    t = sub.add_parser("track", parents=[common], help="track objects in calibrated videos")
    tsub = t.add_subparsers(dest="tracker", required=True, parser_class=_Parser)
    c = tsub.add_parser(
        "color", parents=[common], aliases=["colour"], help="S1 colour particle filter (Barrera et al.)"
    )
    c.add_argument("--rig", required=True, help="rig file (YAML/JSON)")
    c.add_argument(
        "--video", action="append", required=True, help="video file, image folder or glob; one per camera, in rig order"
    )
    c.add_argument(
        "--hue",
        type=float,
        nargs=2,
        required=True,
        metavar=("HMIN", "HMAX"),
        help="hue range in degrees [0, 360]; HMIN > HMAX wraps through 0",
    )
    c.add_argument("--sat", type=float, nargs=2, required=True, metavar=("SMIN", "SMAX"), help="saturation [0, 1]")
    c.add_argument(
        "--intensity",
        type=float,
        nargs=2,
        default=(20.0, 240.0),
        metavar=("IMIN", "IMAX"),
        help="intensity range [0, 255] (default 20 240)",
    )
    c.add_argument("--particles", type=int, default=200, help="N (default 200)")
    c.add_argument("--sigma", type=float, default=0.03, help="sigma_m of the gaussian walk, metres (default 0.03)")
    g = c.add_mutually_exclusive_group()
    g.add_argument("--init", type=float, nargs=3, metavar=("X", "Y", "Z"), help="initial point, metres")
    g.add_argument("--init-random", action="store_true", help="uniform in --volume or the rig's working volume")
    c.add_argument("--volume", type=float, nargs=6, metavar=("XMIN", "YMIN", "ZMIN", "XMAX", "YMAX", "ZMAX"))
    c.add_argument("--resampling", default="systematic", help="systematic, stratified, multinomial or residual")
    c.add_argument("--ess-threshold", type=float, default=1.0, help="resample when ESS <= this * N (1 = always)")
    c.add_argument("--score-mode", default="auto", help="auto, direct or integral")
    c.add_argument("--seed", type=int, default=0)
    c.add_argument(
        "--proposal",
        choices=("mixture", "prior"),
        default="mixture",
        help="mixture: motion prior + detection proposal from the colour masks (default); prior: the paper's filter",
    )
    c.add_argument("--mixture", type=float, default=0.25, help="fraction of particles from the detection proposal")
    c.add_argument("--keep-particles", type=int, default=1000, help="particles per frame saved for reports")
    c.add_argument("--max-frames", type=_positive_int, default=None)
    c.add_argument("--stop-at-shortest", action="store_true", help="track the common part of unequal videos")
    c.add_argument("--groundtruth", default=None, help="groundtruth.csv to report the error against")
    c.add_argument("--out", required=True, help="output folder")
    _add_device(c)
    c.add_argument(
        "--report", action=argparse.BooleanOptionalAction, default=False, help="render OUT/report (default: off)"
    )
    _add_run_control(c)
    c.set_defaults(func=cmd_track_color)

    tt = tsub.add_parser(
        "templates",
        parents=[common],
        help="humans and vehicles on a ground plane from one camera (S3, Juza et al.)",
        description="3D template particle filter: each particle a whole scene of human/vehicle templates, "
        "weighted by the XOR of its virtual image and the motion mask; new objects from the UOH.",
    )
    tt.add_argument("--rig", required=True, help="rig file (YAML/JSON) with the camera and optional 'ground' plane")
    tt.add_argument("--video", default=None, help="the camera's video or image folder (background subtraction)")
    tt.add_argument("--masks", default=None, help="binary motion masks (video or image folder) instead of --video")
    tt.add_argument("--camera", default="0", help="rig camera name or index (default 0)")
    tt.add_argument("--particles", type=_positive_int, default=1000, help="N (default 1000)")
    tt.add_argument("--max-objects", type=int, default=8, help="R_max objects per particle, 1..16 (default 8)")
    tt.add_argument("--classes", nargs="+", default=["human", "vehicle"], help="classes to add (human vehicle)")
    tt.add_argument("--fps", type=float, default=None, help="frame rate (default: the video's or masks', else 15)")
    tt.add_argument("--scale", type=float, default=None, help="s of eq. 6 (default 5000)")
    tt.add_argument("--t-add", type=float, default=None, help="T_add of eq. 12 (default 0.3)")
    tt.add_argument("--t-del", type=float, default=None, help="T_del of eq. 13 (default 0.02)")
    tt.add_argument("--add-min-gain", type=float, default=None, help="candidate gain / area to add (default 0.2)")
    tt.add_argument("--min-existence", type=float, default=None, help="report objects above this (default 0.5)")
    tt.add_argument(
        "--min-in-image",
        type=float,
        default=None,
        help="report objects with at least this fraction of their image box inside the image (default 0.25; 0: all)",
    )
    tt.add_argument("--candidate-step-px", type=int, default=None, help="addition grid pitch, pixels (default 8)")
    tt.add_argument(
        "--vehicle-entry-px",
        type=int,
        default=None,
        help="vehicle addition candidates also this far beyond the image border, pixels (cars entering the view)",
    )
    tt.add_argument(
        "--human-entry-px",
        type=int,
        default=None,
        help="human addition candidates also this far beyond the image border, pixels (people walking in; default 64)",
    )
    tt.add_argument(
        "--min-track-frames",
        type=int,
        default=None,
        help="leave tracks shorter than this out of tracks.csv when the run completes (default 8; 1: keep all; "
        "tracks_all.csv keeps every track)",
    )
    tt.add_argument(
        "--backfill-seconds",
        type=float,
        default=None,
        help="when the run completes, extend each lasting track back over up to this long before it was first "
        "reported, while in view (default 1.35; 0: off; rows with existence 0)",
    )
    tt.add_argument(
        "--backfill-min-frames",
        type=int,
        default=None,
        help="backfill only tracks with at least this many rows (default 15)",
    )
    tt.add_argument(
        "--stitch-seconds",
        type=float,
        default=None,
        help="when the run completes, give a track that starts up to this long after another ended, where that one "
        "was heading, the other's id (default 2; 0: off)",
    )
    tt.add_argument(
        "--stitch-distance", type=float, default=None, help="metres from where the ended track was heading (default 2)"
    )
    tt.add_argument("--resampling", default="systematic", help="systematic, stratified, multinomial or residual")
    tt.add_argument(
        "--joint",
        action="store_true",
        help="the paper's joint filter: one weight per particle for all its objects (default: objects whose image "
        "boxes are apart are resampled in independent groups)",
    )
    tt.add_argument(
        "--mask-method",
        default="offline",
        choices=["offline", "mog2", "knn"],
        help="background model: offline (whole-recording median, default), mog2 or knn (online)",
    )
    tt.add_argument("--mask-history", type=_positive_int, default=200, help="background model history, frames")
    tt.add_argument("--mask-threshold", type=float, default=None, help="MOG2 varThreshold / KNN dist2Threshold")
    tt.add_argument("--keep-shadows", action="store_true", help="count shadow pixels as foreground")
    tt.add_argument("--open-px", type=int, default=3, help="morphological opening, pixels (0: off)")
    tt.add_argument("--close-px", type=int, default=5, help="morphological closing, pixels (0: off)")
    tt.add_argument("--min-area", type=int, default=0, help="drop foreground blobs smaller than this, pixels")
    tt.add_argument("--seed", type=int, default=0)
    tt.add_argument("--max-frames", type=_positive_int, default=None)
    tt.add_argument("--save-masks", action="store_true", help="write the masks used to masks.avi")
    tt.add_argument("--no-virtual", action="store_true", help="do not write virtual.avi")
    tt.add_argument("--groundtruth", default=None, help="groundtruth.csv: print accuracy, MOTA and IDF1")
    tt.add_argument("--out", required=True, help="output folder")
    tt.add_argument("--report", action="store_true", help="render the HTML report afterwards")
    _add_device(tt)
    _add_run_control(tt)
    tt.set_defaults(func=cmd_track_templates)

    tp = tsub.add_parser(
        "people",
        parents=[common],
        help="people in 3D from two or more overlapping cameras (S2: motion + multi-view colour)",
        description="One particle filter per person, particles are 3D points inside the person, weighted by the "
        "motion masks of every camera and a multi-view HSV colour descriptor; people are added where several "
        "cameras agree on unexplained motion.",
    )
    tp.add_argument("--rig", required=True, help="rig file (YAML/JSON) with two or more cameras")
    tp.add_argument("--video", action="append", required=True, help="video per camera, in rig order")
    tp.add_argument("--masks", action="append", default=None, help="given motion masks per camera (rig order)")
    tp.add_argument("--particles", type=_positive_int, default=500, help="particles per person N_S (default 500)")
    tp.add_argument("--max-people", type=_positive_int, default=None, help="people tracked at once (default 8)")
    tp.add_argument("--sigma-pos", type=float, default=None, help="position noise, metres/frame (default 0.03)")
    tp.add_argument("--sigma-vel", type=float, default=None, help="velocity noise, metres/frame^2 (default 0.01)")
    tp.add_argument("--alpha", type=float, default=None, help="appearance forgetting factor of eq. 6 (default 0.05)")
    tp.add_argument("--p-b", type=float, default=None, help="background probability p_B of eq. 10 (default 0.05)")
    tp.add_argument("--r-n", type=float, default=None, help="descriptor neighbourhood radius r_N, metres (0.1)")
    tp.add_argument("--bins", type=int, default=None, help="histogram bins N_b (default 8)")
    tp.add_argument("--occupancy-every", type=int, default=10, help="occupancy grids every N frames (0: none)")
    tp.add_argument(
        "--mask-method", default="offline", choices=["offline", "mog2", "knn"], help="motion masks (default: offline)"
    )
    tp.add_argument("--mask-history", type=_positive_int, default=200, help="background model history, frames")
    tp.add_argument("--mask-threshold", type=float, default=None, help="MOG2 varThreshold / KNN dist2Threshold")
    tp.add_argument("--keep-shadows", action="store_true", help="count shadow pixels as foreground")
    tp.add_argument("--open-px", type=int, default=3, help="morphological opening, pixels (0: off)")
    tp.add_argument("--close-px", type=int, default=5, help="morphological closing, pixels (0: off)")
    tp.add_argument("--min-area", type=int, default=0, help="drop foreground blobs smaller than this, pixels")
    tp.add_argument("--save-masks", action="store_true", help="write the masks used to masks_<camera>.avi")
    tp.add_argument("--seed", type=int, default=0)
    tp.add_argument("--max-frames", type=_positive_int, default=None)
    tp.add_argument("--stop-at-shortest", action="store_true", help="track the common part of unequal videos")
    tp.add_argument("--groundtruth", default=None, help="groundtruth.csv: print MOTA and IDF1 at 0.5 m")
    tp.add_argument("--out", required=True, help="output folder")
    tp.add_argument("--report", action="store_true", help="render the HTML report afterwards")
    _add_device(tp)
    _add_run_control(tp)
    tp.set_defaults(func=cmd_track_people)

    e = sub.add_parser(
        "evaluate", parents=[common], help="accuracy, MOTA and IDF1 of tracks against ground truth (ground plane)"
    )
    e.add_argument("tracks", help="tracks.csv or a run folder")
    e.add_argument(
        "--groundtruth", required=True, help="groundtruth.csv (wptrack synth writes one) or a PETS box .xml (--rig)"
    )
    e.add_argument("--rig", default=None, help="rig to back-project .xml box feet onto the ground")
    e.add_argument("--camera", default=0, help="annotated camera of the rig (name or index; default 0)")
    e.add_argument("--box-size", default=None, help="WIDTHxHEIGHT of the boxes' image if not the camera's size")
    e.add_argument("--threshold", type=float, default=1.0, help="match distance on the ground plane, metres")
    e.add_argument("--out", default=None, help="write the evaluation as JSON here")
    e.set_defaults(func=cmd_evaluate)

    v = sub.add_parser(
        "convergence",
        aliases=["sweep"],
        parents=[common],
        help="filter dynamics with 3D observations, the sigma_m sweep (extended paper, section III.C, Fig. 7)",
    )
    v.add_argument("--sigma", type=float, action="append", help="sigma_m value(s); default: a sweep 0.001..0.3")
    v.add_argument("--steps", type=_positive_int, default=12, help="sweep steps between 0.001 and 0.3 m")
    v.add_argument("--particles", type=_positive_int, default=200)
    v.add_argument("--iterations", type=_positive_int, default=100)
    v.add_argument("--jump-at", type=_positive_int, default=30)
    v.add_argument("--jump", type=float, default=2.0, help="jump distance, metres")
    v.add_argument("--sigma-obs", type=float, default=0.05, help="3D observation deviation, metres")
    v.add_argument("--runs", type=_positive_int, default=10, help="independent runs averaged per sigma_m")
    v.add_argument("--seed", type=int, default=0)
    v.add_argument("--out", required=True, help="output folder (errors.csv, summary.json, runs/)")
    v.add_argument("--address", default="inline", help="inline (default: here), or Ray: local, auto, ray://HOST:PORT")
    v.add_argument("--retries", type=int, default=None, help="retries of a failed run (default 2)")
    v.add_argument("--report", action="store_true", help="render OUT/report with the heatmap (S1 Fig. 7)")
    _add_device(v)
    v.set_defaults(func=cmd_convergence)

    r = sub.add_parser(
        "report", parents=[common], help="render a run's report (3D views, overlays, plots, movie, index.html)"
    )
    r.add_argument("run_dir", help="run folder (run.json, tracks.csv, particles.npz) or a sweep folder (errors.csv)")
    r.add_argument("--out", default=None, help="report folder (default: RUN_DIR/report)")
    r.add_argument("--sweep", default=None, help="errors.csv (or its folder) of 'wptrack convergence' to add")
    r.add_argument("--frames", type=int, nargs="+", default=None, help="frames whose particle clouds are shown")
    r.add_argument("--movie-frames", type=_positive_int, default=100, help="at most this many movie frames")
    r.add_argument("--no-movie", action="store_true", help="skip the movie")
    r.add_argument("--groundtruth", default=None, help="groundtruth.csv drawn beside the tracks (template runs)")
    r.set_defaults(func=cmd_report)

    mk = sub.add_parser(
        "masks",
        parents=[common],
        help="motion masks of a video (offline background model, MOG2 or KNN) written as a video",
    )
    mk.add_argument("--video", required=True, help="the camera's video or image folder")
    mk.add_argument("--out", required=True, help="output folder (masks.avi, background.png, masks.json)")
    mk.add_argument("--method", default="offline", choices=["offline", "mog2", "knn"], help="default: offline")
    mk.add_argument("--window", type=int, default=None, help="offline: background window, frames (default 300)")
    mk.add_argument("--samples", type=int, default=None, help="offline: frames sampled per window (default 25)")
    mk.add_argument("--threshold", dest="fg_threshold", type=float, default=None, help="offline: robust sigmas (4)")
    mk.add_argument("--noise-floor", type=float, default=None, help="offline: noise floor, 8-bit units (3)")
    mk.add_argument("--shadow-lo", type=float, default=None, help="offline: shadow brightness ratio min (0.4)")
    mk.add_argument("--shadow-hi", type=float, default=None, help="offline: shadow brightness ratio max (0.95)")
    mk.add_argument("--shadow-chroma", type=float, default=None, help="offline: shadow chromaticity bound (0.1)")
    mk.add_argument("--soft-scale", type=float, default=None, help="offline: probability scale, sigmas (1)")
    mk.add_argument("--fg-low", type=float, default=None, help="offline: hysteresis low threshold, sigmas (3; 0: off)")
    mk.add_argument("--spread-cap", type=float, default=None, help="offline: noise scale cap, x median (1.5; 0: off)")
    mk.add_argument("--shadow-band", type=float, default=None, help="offline: learnt shadow band (0.08; 0: off)")
    mk.add_argument("--neighbourhood", type=int, default=None, help="offline: neighbourhood radius, px (1; 0: off)")
    mk.add_argument("--illum-tiles", type=int, default=None,
                    help="offline: local light field, tiles along the short side (30; 0: off)")  # fmt: skip
    mk.add_argument("--illum-radius", type=int, default=None, help="offline: light field smoothing, tiles (2)")
    mk.add_argument("--illum-veto", type=float, default=None, help="offline: patch NCC of a light change (0.7; 0: off)")
    mk.add_argument("--illum-grad", type=float, default=None, help="offline: gradient correlation veto (0: off)")
    mk.add_argument("--mode-band", type=float, default=None,
                    help="offline: background of the densest samples, noise scales (3; 0: median)")  # fmt: skip
    mk.add_argument("--history", type=int, default=None, help="mog2/knn: history, frames (200)")
    mk.add_argument("--keep-shadows", action="store_true", help="count shadow pixels as foreground")
    mk.add_argument("--open-px", type=int, default=None, help="morphological opening, pixels (3; 0: off)")
    mk.add_argument("--close-px", type=int, default=None, help="morphological closing, pixels (5; 0: off)")
    mk.add_argument("--min-area", type=int, default=None, help="drop foreground blobs smaller than this, pixels")
    mk.add_argument("--probability", action="store_true", help="also write probability.avi (P x 255)")
    mk.add_argument("--max-frames", type=_positive_int, default=None)
    _add_device(mk)
    mk.set_defaults(func=cmd_masks)

    bt = sub.add_parser(
        "batch",
        parents=[common],
        help="many runs or a parameter grid from a YAML manifest, one Ray task per run (GPU or CPU)",
        description="Runs the manifest's runs (wptrack track options, or grids of them) as Ray tasks, each into "
        "OUT/<run-id>/, with OUT/summary.csv; completed runs are skipped when the manifest is run again.",
    )
    bt.add_argument("manifest", help="batch manifest (YAML): runs, grids, retries")
    bt.add_argument("--out", required=True, help="batch folder: OUT/<run-id>/ per run and OUT/summary.csv")
    bt.add_argument(
        "--address",
        default="local",
        help="local (new local Ray instance, default), auto (running cluster), HOST:PORT, ray://HOST:PORT, or "
        "inline (no Ray: one run after another here; also the default without Ray installed)",
    )
    bt.add_argument("--gpus-per-task", type=float, default=None, help="GPUs per run (default 1 if the cluster has any)")
    bt.add_argument("--cpus-per-task", type=float, default=1.0, help="CPU cores reserved per run (default 1)")
    bt.add_argument("--retries", type=int, default=None, help="retries of a failed/killed run (default: manifest, 2)")
    bt.set_defaults(func=cmd_batch)

    b = sub.add_parser("bench", parents=[common], help="benchmark suites: stage times, NumPy baseline, equivalence")
    b.add_argument("--tracker", default="color", help="suite name (default: color)")
    b.add_argument("--particles", type=float, nargs="+", help="particle counts (default: the suite's grid)")
    b.add_argument("--cameras", type=int, nargs="+", help="camera counts (default: the suite's grid)")
    b.add_argument("--objects", type=int, nargs="+", help="object counts of the templates suite (default: its grid)")
    b.add_argument("--runs", type=int, nargs="+", help="runs K per batch of the batch suite (default: its grid)")
    b.add_argument("--frames", type=_positive_int, default=None, help="timed frames per case (default 50; soak 10000)")
    b.add_argument("--numpy-max", type=int, default=100_000, help="largest N also run by the NumPy reference")
    b.add_argument("--out", default=None, help="write the results as JSON here")
    b.add_argument(
        "--weights",
        choices=("ordinary", "concentrated"),
        default=None,
        help="color suite: time resampling alone on synthetic log-weights, N(0, 1) or N(0, 5^2)",
    )
    b.add_argument(
        "--joint",
        action="store_true",
        help="templates suite: the paper's joint filter (one weight per particle) instead of the partitioned one",
    )
    _add_device(b)
    b.set_defaults(func=cmd_bench)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``wptrack`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = bool(getattr(args, "debug", False))
    level = logging.DEBUG if debug else logging.INFO if args.verbose else logging.WARNING
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    from .device import quiet_warp

    quiet_warp(not (args.verbose or debug))  # Warp's banner and kernel-cache messages only with --verbose
    try:
        return int(args.func(args) or 0)
    except WptrackError as e:
        if debug:  # a user mistake is one line; --debug adds where it was raised
            import traceback

            traceback.print_exc(file=sys.stderr)
        print(f"wptrack: error: {e}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM during a run (RunInterrupted)
        print("wptrack: interrupted; partial results were kept", file=sys.stderr)
        return int(getattr(e, "exit_code", 130))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
