"""A batch over a folder of recordings, without a manifest: ``wptrack batch --videos 'recordings/*.avi' --rig
rig.yaml --tracker templates --out DIR [options of wptrack track templates]``.

One run per video, its id the file's stem (characters other than letters, digits, ``. _ + -`` become ``_``), with
the same options for every run (those of ``wptrack track TRACKER``, derived from the tracker's declared parts:
:func:`wptrack.runs.spec.add_track_arguments`). A tracker of several cameras takes one ``--videos`` pattern per
camera, in rig order; the runs pair the cameras' files by stem (``cam1/seq01.avi`` with ``cam2/seq01.avi``). A
``--groundtruth`` holding ``{stem}`` is filled per run (``--groundtruth 'truth/{stem}.csv'``). Relative paths are
taken from the current folder. The result is a :class:`~wptrack.batch.manifest.Manifest`: the runs are what a
manifest listing them would give (the same ids, arguments and hashes, so re-running skips completed runs).
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from wptrack.batch.manifest import Manifest, RunSpec, _resolve_paths
from wptrack.core.errors import ConfigError

VIDEO_OPTIONS = ("out", "video", "resume", "overwrite")
"""Track options that ``--videos`` mode sets itself (the run's folder and video) or that a batch does not take."""


def run_id(path: str | os.PathLike) -> str:
    """A run id from a file's stem: characters other than letters, digits, ``. _ + -`` become ``_``."""
    stem = re.sub(r"[^A-Za-z0-9._+-]", "_", Path(path).stem)
    return stem if re.match(r"^[A-Za-z0-9]", stem) else f"v{stem}"


def _matches(pattern: str) -> list[str]:
    if os.path.isdir(pattern):
        raise ConfigError(f"--videos {pattern}: a folder; give a pattern of its videos, e.g. '{pattern}/*.avi'")
    files = sorted(f for f in glob.glob(os.path.expanduser(pattern)) if os.path.isfile(f))
    if not files:
        raise ConfigError(f"--videos {pattern}: no file matches")
    return files


def videos_manifest(
    patterns: Sequence[str],
    tracker: str,
    options: Mapping[str, Any],
    base: str | os.PathLike | None = None,
    cameras: int | None = None,
) -> Manifest:
    """The runs of ``wptrack batch --videos``: one per video (or per stem shared by every camera's pattern).

    Args:
        patterns: one glob per camera (quote it for the shell).
        tracker: the ``wptrack track`` tracker.
        options: the runs' options by flag (:func:`wptrack.runs.spec.options_from_namespace`), ``video`` and
            ``out`` excluded.
        base: the folder relative paths are taken from (default: the current folder).
        cameras: the number of patterns the tracker needs, when known (1 for the template tracker).

    Raises:
        ConfigError: a pattern that matches nothing, cameras whose files do not pair up by stem, two videos with
            the same run id, the wrong number of patterns.
    """
    from wptrack.runs.spec import command

    cmd = command(tracker)
    if cameras is not None and len(patterns) != cameras:
        raise ConfigError(
            f"--videos: 'wptrack track {cmd.name}' takes {cameras} video(s) per run; give {cameras} --videos "
            f"pattern(s), got {len(patterns)}"
        )
    bad = sorted(set(options) & set(VIDEO_OPTIONS))
    if bad:
        raise ConfigError(f"--videos: {', '.join('--' + b for b in bad)} are set by the batch (OUT/<run-id>)")
    base = Path(base or Path.cwd())
    per_camera: list[dict[str, str]] = []
    for pattern in patterns:
        by_id: dict[str, str] = {}
        for f in _matches(pattern):
            rid = run_id(f)
            if rid in by_id:
                raise ConfigError(f"--videos {pattern}: {by_id[rid]} and {f} give the same run id {rid!r}")
            by_id[rid] = f
        per_camera.append(by_id)
    ids = sorted(per_camera[0])
    for pattern, by_id in zip(patterns[1:], per_camera[1:], strict=True):
        missing = sorted(set(ids) ^ set(by_id))
        if missing:
            raise ConfigError(
                f"--videos: the cameras' files do not pair up by name: {', '.join(missing[:5])} not in every pattern "
                f"(first: {patterns[0]}, then: {pattern})"
            )
    runs = []
    for rid in ids:
        args = dict(options)
        if isinstance(args.get("groundtruth"), str):
            args["groundtruth"] = args["groundtruth"].replace("{stem}", Path(per_camera[0][rid]).stem)
        if isinstance(args.get("config"), str):
            args["config"] = str((base / args["config"]).resolve())
        args["video"] = [by_id[rid] for by_id in per_camera]
        runs.append(RunSpec(rid, cmd.name, _resolve_paths(args, base), None, {}))
    return Manifest(base / patterns[0], tuple(runs), None)
