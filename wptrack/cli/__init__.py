"""``wptrack``: the command line (demo, synth, track, evaluate, report, masks, convergence, batch, bench).

User mistakes (bad rig field, missing video, out-of-range parameter, no CUDA, unwritable output) print one
line ``wptrack: error: ...`` on stderr and exit with code 2, without a traceback and before any output is
written. Ctrl-C exits with 130 and leaves valid partial outputs. The options of ``wptrack track`` are derived from
the trackers' declared configs (:mod:`wptrack.runs.spec`); :mod:`wptrack.cli.commands` holds the other commands.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence

from wptrack import __version__
from wptrack.batch import POOLS
from wptrack.batch.videos import VIDEO_OPTIONS
from wptrack.cli.commands import (
    cmd_batch,
    cmd_bench,
    cmd_convergence,
    cmd_demo,
    cmd_evaluate,
    cmd_masks,
    cmd_report,
    cmd_synth,
)
from wptrack.cli.common import Parser, add_device, positive_count, positive_int
from wptrack.cli.track import add_track_parsers
from wptrack.core.config import add_arguments
from wptrack.core.errors import ConfigError, WptrackError
from wptrack.motion.masks import MaskConfig
from wptrack.runs.spec import add_track_arguments, command, commands

__all__ = ["EXIT_INTERNAL", "build_parser", "main"]

log = logging.getLogger("wptrack")

EXIT_INTERNAL = 70
"""Exit code of an internal error (a bug, not a user mistake): sysexits' EX_SOFTWARE."""


# --- parser -------------------------------------------------------------------------------------------------
def build_parser(batch_tracker: str | None = None) -> argparse.ArgumentParser:
    """The ``wptrack`` parser; ``batch_tracker``: the ``--tracker`` of ``wptrack batch --videos``, whose track options
    the batch command then takes (:func:`_batch_tracker` finds it in argv)."""
    p = Parser(prog="wptrack", description="Particle-filter 3D object tracking from calibrated cameras (Warp).")
    p.add_argument("--version", action="version", version=f"wptrack {__version__}")
    p.add_argument("--debug", action="store_true", help="debug logging; show the traceback of errors")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
    common.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    common.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)  # none: main prints the usage

    d = sub.add_parser(
        "demo", parents=[common], help="synthesise the lab scene and track the ball (no GPU, display or download)"
    )
    d.add_argument("--out", default="wptrack-demo", help="output folder (default: ./wptrack-demo)")
    d.add_argument("--frames", type=positive_int, default=None, help="frames to render (scene default)")
    d.add_argument("--particles", type=positive_int, default=200)
    d.add_argument("--seed", type=int, default=0)
    add_device(d)
    d.add_argument(
        "--report", action=argparse.BooleanOptionalAction, default=True, help="render the report (default: on)"
    )
    d.set_defaults(func=cmd_demo)

    s = sub.add_parser("synth", parents=[common], help="render a synthetic calibrated scene with ground truth")
    s.add_argument("scene", help="scene name (e.g. s1-lab, s1-lab-jump)")
    s.add_argument("--out", required=True)
    s.add_argument("--frames", type=positive_int, default=None)
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
        help="comma-separated hard conditions, each alone measurable: s3 scenes static-start, stop-and-go, sun, "
        "light-change, noise, compression, dark-car, crowd, cyclists, clouds, exposure, short, or all; s2-office "
        "scenes clouds, exposure (default: none; see wptrack.synth.conditions)",
    )
    s.set_defaults(func=cmd_synth)

    add_track_parsers(sub, common)

    e = sub.add_parser(
        "evaluate",
        parents=[common],
        help="accuracy, MOTA, IDF1 and HOTA of tracks against ground truth (ground plane); MOTChallenge files",
        description="Scores one or more runs (e.g. seeds) against the ground truth on the ground plane: the paper's "
        "accuracy, MOTA and IDF1 (motmetrics) and HOTA (distance similarity, 0 at --threshold), the spread over the "
        "runs, and MOTChallenge files in each RUN/mot/ (world coordinates; image boxes for template runs).",
    )
    e.add_argument("tracks", nargs="+", help="tracks.csv or a run folder; several: the spread over them (seeds)")
    e.add_argument(
        "--groundtruth", required=True, help="groundtruth.csv (wptrack synth writes one) or a PETS box .xml (--rig)"
    )
    e.add_argument("--rig", default=None, help="rig to back-project .xml box feet onto the ground")
    e.add_argument(
        "--camera", default=None, help="rig camera (name or index) of .xml boxes (default 0) and of the image boxes"
    )
    e.add_argument("--box-size", default=None, help="WIDTHxHEIGHT of the boxes' image if not the camera's size")
    e.add_argument("--threshold", type=float, default=1.0, help="match distance on the ground plane, metres")
    e.add_argument("--out", default=None, help="write the evaluation as JSON here (several runs: each, and spread)")
    e.add_argument("--no-mot", action="store_true", help="do not write the MOTChallenge files (RUN/mot/)")
    e.set_defaults(func=cmd_evaluate)

    v = sub.add_parser(
        "convergence",
        aliases=["sweep"],
        parents=[common],
        help="filter dynamics with 3D observations, the sigma_m sweep (extended paper, section III.C, Fig. 7)",
    )
    v.add_argument("--sigma", type=float, action="append", help="sigma_m value(s); default: a sweep 0.001..0.3")
    v.add_argument("--steps", type=positive_int, default=12, help="sweep steps between 0.001 and 0.3 m")
    v.add_argument("--particles", type=positive_int, default=200)
    v.add_argument("--iterations", type=positive_int, default=100)
    v.add_argument("--jump-at", type=positive_int, default=30)
    v.add_argument("--jump", type=float, default=2.0, help="jump distance, metres")
    v.add_argument("--sigma-obs", type=float, default=0.05, help="3D observation deviation, metres")
    v.add_argument("--runs", type=positive_int, default=10, help="independent runs averaged per sigma_m")
    v.add_argument("--seed", type=int, default=0)
    v.add_argument("--out", required=True, help="output folder (errors.csv, summary.json, runs/)")
    v.add_argument("--address", default="inline", help="inline (default: here), or Ray: local, auto, ray://HOST:PORT")
    v.add_argument("--retries", type=int, default=None, help="retries of a failed run (default 2)")
    v.add_argument("--report", action="store_true", help="render OUT/report with the heatmap (S1 Fig. 7)")
    add_device(v)
    v.set_defaults(func=cmd_convergence)

    r = sub.add_parser(
        "report", parents=[common], help="render a run's report (3D views, overlays, plots, movie, index.html)"
    )
    r.add_argument("run_dir", help="run folder (run.json, tracks.csv, particles.npz) or a sweep folder (errors.csv)")
    r.add_argument("--out", default=None, help="report folder (default: RUN_DIR/report)")
    r.add_argument("--sweep", default=None, help="errors.csv (or its folder) of 'wptrack convergence' to add")
    r.add_argument("--frames", type=int, nargs="+", default=None, help="frames whose particle clouds are shown")
    r.add_argument("--movie-frames", type=positive_int, default=100, help="at most this many movie frames")
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
    mk.add_argument("--probability", action="store_true", help="also write probability.avi (P x 255)")
    mk.add_argument("--max-frames", type=positive_int, default=None)
    add_device(mk)
    add_arguments(mk.add_argument_group("motion masks (MaskConfig)"), MaskConfig)
    mk.set_defaults(func=cmd_masks)

    bt = sub.add_parser(
        "batch",
        parents=[common],
        help="many runs or a parameter grid from a YAML manifest, or one run per recording, on Ray (GPUs or CPUs)",
        description="Runs the manifest's runs (wptrack track options, or grids of them), or one run per video of "
        "--videos, on Ray workers that stay warm (one per GPU), each into OUT/<run-id>/, with OUT/summary.csv; "
        "completed runs are skipped when the batch is run again.",
    )
    bt.add_argument("manifest", nargs="?", help="batch manifest (YAML): runs, grids, retries (or --videos)")
    bt.add_argument("--out", required=True, help="batch folder: OUT/<run-id>/ per run and OUT/summary.csv")
    bt.add_argument(
        "--address",
        default="local",
        help="local (new local Ray instance, default), auto (running cluster), HOST:PORT, ray://HOST:PORT, or "
        "inline (no Ray: one run after another here; also the default without Ray installed)",
    )
    bt.add_argument("--gpus-per-task", type=float, default=None, help="GPUs per run (default 1 if the cluster has any)")
    bt.add_argument(
        "--cpus-per-task",
        type=float,
        default=None,
        help="CPU cores reserved per worker, its runs' decoding threads (default: GPU runs the cores per GPU worker, "
        "e.g. 4 on 16 cores and 4 GPUs; CPU runs 1)",
    )
    bt.add_argument("--retries", type=int, default=None, help="retries of a failed/killed run (default: manifest, 2)")
    bt.add_argument(
        "--pool",
        choices=POOLS,
        default="actors",
        help="actors (default): warm workers, one per GPU (per --gpus-per-task share), that take the runs from a "
        "queue; tasks: one Ray task in a fresh worker process per run",
    )
    bt.add_argument(
        "--pin-cores",
        action="store_true",
        help="actors: bind each worker to a block of --cpus-per-task cores of its own (Linux; default: the workers' "
        "threads may run on all of a node's cores)",
    )
    vg = bt.add_argument_group("a batch over recordings, without a manifest")
    vg.add_argument(
        "--videos",
        action="append",
        metavar="GLOB",
        help="one run per matching video, its id the file's stem (quote the pattern); trackers of several cameras: "
        "one --videos per camera in rig order, files paired by stem",
    )
    vg.add_argument(
        "--tracker",
        choices=[n for c in commands().values() for n in (c.name, *c.aliases)],
        help="the runs' tracker; the options of 'wptrack track TRACKER' then apply to every run "
        "('wptrack batch --tracker TRACKER --help' lists them; --groundtruth may hold {stem})",
    )
    if batch_tracker is not None:
        try:
            add_track_arguments(bt, command(batch_tracker), exclude=VIDEO_OPTIONS)
        except ConfigError:  # not a tracker: --tracker's choices say so
            pass
    bt.set_defaults(func=cmd_batch)

    b = sub.add_parser("bench", parents=[common], help="benchmark suites: stage times, NumPy baseline, equivalence")
    b.add_argument("--tracker", default="color", help="suite name (default: color)")
    b.add_argument("--particles", type=positive_count, nargs="+", help="particle counts (default: the suite's grid)")
    b.add_argument("--cameras", type=positive_int, nargs="+", help="camera counts (default: the suite's grid)")
    b.add_argument(
        "--objects",
        type=positive_int,
        nargs="+",
        help="object counts of the templates and people suites (default: their grids)",
    )
    b.add_argument(
        "--runs", type=positive_int, nargs="+", help="runs K per batch of the batch suite (default: its grid)"
    )
    b.add_argument(
        "--frames",
        type=positive_int,
        default=None,
        help="timed frames per case (default 50; soak 10000); masks: also the end-to-end video's length (default 600); "
        "pipeline: the video's frames (default 600 on a GPU, 400 on the CPU)",
    )
    b.add_argument("--numpy-max", type=int, default=100_000, help="largest N also run by the NumPy reference")
    b.add_argument("--out", default=None, help="write the results as JSON here")
    b.add_argument(
        "--weights",
        choices=("ordinary", "concentrated"),
        default=None,
        help="color suite: time resampling alone on synthetic log-weights, N(0, 1) or N(0, 5^2)",
    )
    b.add_argument(
        "--proposal",
        choices=("prior", "mixture"),
        default=None,
        help="color suite: the tracker's proposal (default prior, the paper's filter; mixture: detection jumps)",
    )
    b.add_argument(
        "--joint",
        action="store_true",
        help="templates suite: the paper's joint filter (one weight per particle) instead of the partitioned one",
    )
    b.add_argument(
        "--video", nargs="+", default=None, help="pipeline suite: time the commands on this video (default: its own); "
        "several: the cameras of a people run (with --rig)",
    )  # fmt: skip
    b.add_argument("--rig", default=None, help="pipeline suite: the rig of --video (default: the suite's camera)")
    b.add_argument(
        "--variant", action="append", default=None, metavar="ENV=N[,ENV=N]",
        help="pipeline suite: also run the commands with these environment settings (repeatable), e.g. "
        "WPTRACK_MASK_WORKERS=2",
    )  # fmt: skip
    b.add_argument("--size", default=None, help="pipeline suite: WIDTHxHEIGHT of its own video (default 1920x1080 "
                   "on a GPU, 480x360 on the CPU)")  # fmt: skip
    add_device(b)
    b.set_defaults(func=cmd_bench)
    return p


def _subparser(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            return a.choices[name]
    raise KeyError(name)


def _missing_command(parser: argparse.ArgumentParser, args) -> tuple[argparse.ArgumentParser, str] | None:
    """The parser to show and what is missing when no command (or no tracker after ``track``) was given."""
    if getattr(args, "command", None) is None:
        return parser, "command"
    if args.command == "track" and getattr(args, "tracker", None) is None:
        return _subparser(parser, "track"), "tracker"
    return None


def _batch_tracker(argv: Sequence[str]) -> str | None:
    """The ``--tracker`` of a ``wptrack batch`` command line (None for other commands or without one)."""
    argv = list(argv)
    command_at = next((i for i, a in enumerate(argv) if not a.startswith("-")), None)
    if command_at is None or argv[command_at] != "batch":
        return None
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--tracker", default=None)
    return pre.parse_known_args(argv[command_at + 1 :])[0].tracker


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``wptrack`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(_batch_tracker(argv))
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse: --help, --version (0) or a usage error (2, its message already printed)
        return int(e.code or 0)
    missing = _missing_command(parser, args)
    if missing is not None:  # `wptrack` or `wptrack track` alone: the usage with the list of commands / trackers
        sub, what = missing
        sub.print_help(sys.stderr)
        print(f"\nwptrack: error: give a {what} ({sub.prog} {what.upper()} --help for its options)", file=sys.stderr)
        return 2
    debug = bool(getattr(args, "debug", False))
    if not (args.verbose or debug):  # FFmpeg's own lines ("[ffv1 @ 0x...] ...") beside wptrack's: only with -v
        import os

        os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET; read when OpenCV first opens a video
        # OpenCV's own "[ WARN:0@...] global cap.cpp:..." lines before wptrack's error about the same file
        os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
    level = logging.DEBUG if debug else logging.INFO if args.verbose else logging.WARNING
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    from wptrack.core.device import quiet_warp

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
        print(f"wptrack: {_interrupted_message(e)}", file=sys.stderr)
        return int(getattr(e, "exit_code", 130))
    except Exception as e:  # a bug: never a user mistake (exit 2); the run loop has closed its outputs ("failed")
        import traceback

        traceback.print_exc(file=sys.stderr)
        run_dir = getattr(e, "run_dir", None)  # set by the run loop: the run keeps its outputs, marked failed
        kept = f"; the run in {run_dir} keeps its outputs so far and its run.json says 'failed'" if run_dir else ""
        print(
            f"wptrack: internal error: {type(e).__name__}: {e} (a bug in wptrack, not in the input; please report "
            f"it with the traceback above{kept})",
            file=sys.stderr,
        )
        return EXIT_INTERNAL


def _interrupted_message(e: BaseException) -> str:
    """What an interruption left (the run loop tags the exception with ``run_dir``, ``resumable``,
    ``nothing_written``): a checkpoint to resume from, nothing at all, or outputs without a checkpoint."""
    run_dir = getattr(e, "run_dir", None)
    if run_dir is None:  # not inside a run (before it started, or another command)
        return "interrupted"
    if getattr(e, "resumable", False):
        return f"interrupted; the outputs so far are in {run_dir}: the same command with --resume continues the run"
    if getattr(e, "nothing_written", False):
        return "interrupted before the first frame was tracked; nothing was written (run the command again)"
    return (
        f"interrupted; the outputs so far are in {run_dir} but no checkpoint was saved, so --resume cannot continue "
        "it: run the command again with --overwrite"
    )


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
