"""``wptrack track color|templates|people``: the options of each tracker are derived from its declared configs
(:mod:`wptrack.runs.spec`); a run is the tracker's job function called with those configs, the same one
``wptrack batch`` calls."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from wptrack.cli.common import Parser, evaluation_line, plural, report_after_tracking
from wptrack.core.errors import WptrackError
from wptrack.runs.spec import (
    TrackCommand,
    add_track_arguments,
    check_scoring,
    commands,
    parts_from_namespace,
    run_command,
    score_run,
)


def add_track_parsers(sub: Any, common: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add ``wptrack track`` and one sub-command per tracker (options from the tracker's configs) to ``sub``."""
    t = sub.add_parser("track", parents=[common], help="track objects in calibrated videos")
    tsub = t.add_subparsers(dest="tracker", metavar="TRACKER", parser_class=Parser)
    for cmd in commands().values():
        p = tsub.add_parser(
            cmd.name, parents=[common], aliases=list(cmd.aliases), help=cmd.help, description=cmd.description
        )
        add_track_arguments(p, cmd)
        p.set_defaults(func=cmd_track, track_command=cmd.name)
    return t


def colour_summary_lines(summary: dict, out_dir: str | Path) -> list[str]:
    """What a colour run prints: frames, device, scoring mode, the convergence against ``--groundtruth``."""
    lines = [f"tracked {plural(summary['frames'], 'frame')} on {summary['device']} ({summary['score_mode']} scoring)"]
    err = summary.get("error")
    if err:
        if err["converged_at"] is None:
            lines.append(  # the criterion (evaluation.convergence.summarize's defaults): a short run can end below it
                f"did not converge (error below 5 cm for 10 frames in a row never reached; final error "
                f"{100 * err['final_error']:.1f} cm)"
            )
        else:
            lines.append(
                f"converged at frame {err['converged_at']}; error after convergence: mean "
                f"{100 * err['mean_error_after']:.2f} cm, median {100 * err['median_error_after']:.2f} cm, "
                f"max {100 * err['max_error_after']:.2f} cm"
            )
    lines.append(f"outputs: {out_dir}/tracks.csv, run.json, particles.npz")
    return lines


def speed_line(out_dir: str | Path, frames: int) -> str | None:
    """One line on where the run's time went, from run.json's stage timeline (``wptrack.io.timeline``): frames/s of
    the frame loop, each busy stage's wall time per frame (the stages of different threads overlap) and the wait of
    the filter for its input; None without a timeline."""
    import json

    from wptrack.io.timeline import WAIT_PREFIX, is_wait

    try:
        tl = json.loads((Path(out_dir) / "run.json").read_text(encoding="utf-8"))["timeline"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    stages, wall = tl.get("stages") or {}, float(tl.get("wall_s") or 0.0)
    if not stages or wall <= 0 or frames <= 0:
        return None
    busy = sorted(((k, v["total_s"]) for k, v in stages.items() if not is_wait(k)), key=lambda kv: -kv[1])
    parts = ", ".join(f"{k} {1000 * t / frames:.1f}" for k, t in busy if 1000 * t / frames >= 0.05)
    line = f"speed: {frames / wall:.1f} frames/s; ms per frame (threads overlap, x{tl.get('overlap', 0):.2f}): {parts}"
    source = tl.get("source")
    waited = stages.get(WAIT_PREFIX + source, {}).get("total_s", 0.0) if source else 0.0
    if waited > 0:
        line += f"; the filter waited for {source} {1000 * waited / frames:.1f}"
    return line


def summary_lines(cmd: TrackCommand, summary: dict, parts: dict[str, Any]) -> list[str]:
    """What ``wptrack track NAME`` prints when the run completes."""
    out = parts["control"].out
    if cmd.name == "color":
        return colour_summary_lines(summary, out)
    if cmd.name == "templates":
        virtual = summary.get("virtual", parts["inputs"].virtual)
        return [
            f"tracked {plural(summary['frames'], 'frame')} on {summary['device']}: "
            f"{plural(summary['objects'], 'object')} ("
            + ", ".join(f"{n} {c}" for c, n in summary["classes"].items() if n or c != "cyclist")
            + ")",
            f"outputs: {out}/tracks.csv, best.csv, run.json" + (", virtual.avi" if virtual else ""),
        ]
    return [
        f"tracked {plural(summary['frames'], 'frame')} on {summary['device']}: "
        f"{plural(summary['people'], 'person', 'people')}",
        f"outputs: {out}/tracks.csv, hulls/, occupancy.npz, run.json",
    ]


def cmd_track(args: argparse.Namespace) -> int:
    """Run ``wptrack track NAME`` from the parsed options."""
    cmd = commands()[args.track_command]
    parts = parts_from_namespace(cmd, args)
    control = parts["control"]
    check_scoring(cmd, control.groundtruth)
    summary = run_command(cmd, parts, progress=not args.quiet)
    for line in summary_lines(cmd, summary, parts):
        print(line)
    speed = speed_line(control.out, int(summary.get("frames") or 0))
    if speed is not None:
        print(speed)
    failure = None  # the report is written even when scoring fails (the scoring error is raised after it)
    try:
        ev = score_run(cmd, parts)
        if ev is not None:
            print(evaluation_line(ev, cmd.threshold))
    except WptrackError as e:
        failure = e
    if control.report:
        report_after_tracking(control.out)
    if failure is not None:
        raise failure
    return 0
