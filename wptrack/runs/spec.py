"""What a ``wptrack track`` run is made of, declared once for the command line, batch manifests and the Python API.

A run of a tracker is a few frozen configs (:mod:`wptrack.core.config`): the run's inputs (the tracker's
``Inputs``: rig, videos, ...), the tracker's config, for the image trackers the motion masks' config, and
:class:`RunControl` (output folder, device, resume, ...). A :class:`TrackCommand` names those parts and the job
function that runs them; ``wptrack track`` derives its options from the parts (:func:`add_track_arguments`),
``wptrack batch`` builds the same parts from a manifest's flat ``args`` (:func:`parts_from_options`), and both call
the same function (:func:`run_command`). Nothing goes through argv.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from wptrack.core.config import (
    REQUIRED,
    add_arguments,
    check,
    from_namespace,
    from_options,
    load_file,
    option_map,
    param,
)
from wptrack.core.errors import ConfigError

__all__ = [
    "COMMANDS", "Part", "RunControl", "TrackCommand", "options_from_namespace", "parts_from_options", "run_command",
]  # fmt: skip


@dataclass(frozen=True)
class RunControl:
    """Where a run writes and how it runs: the same for every tracker."""

    out: str = param(REQUIRED, help="output folder (run.json, tracks.csv, ...)")
    device: str = param(
        "auto", help="auto (the first CUDA device when there is one, else the CPU), cpu, cuda or cuda:N"
    )
    max_frames: int | None = param(None, help="track at most this many frames", lo=1)
    groundtruth: str | None = param(None, help="ground truth to score the run against when it completes")
    report: bool = param(False, help="render OUT/report when the run completes")
    resume: bool = param(False, help="continue the interrupted run in --out from its checkpoint (same inputs, options)")
    overwrite: bool = param(False, help="--out may hold a previous run: remove what it wrote first (else refused)")
    checkpoint_every: float = param(
        60.0, help="save the tracker state for --resume at most this often (0: only when interrupted)", units="s",
        lo=0.0,
    )  # fmt: skip

    def __post_init__(self) -> None:
        check(self)
        if self.resume and self.overwrite:
            raise ConfigError("--resume continues the run in --out and --overwrite replaces it: give one of them")


@dataclass(frozen=True)
class Part:
    """One config of a run: its keyword in the job function, its class, the prefix of its options on the command
    line, and the title of their group in ``--help``."""

    name: str
    cls: type
    prefix: str = ""
    title: str = ""


@dataclass(frozen=True)
class TrackCommand:
    """One ``wptrack track`` tracker.

    Attributes:
        name: The command (``color``, ``templates``, ``people``); run.json's ``tracker``.
        aliases: Other names of the command.
        help: One line for ``wptrack track --help``.
        description: The paragraph of ``wptrack track NAME --help``.
        parts: The configs of a run (:class:`Part`); ``config`` is the tracker's (``--config FILE`` loads it).
        job: ``module:function`` called with one keyword per part and ``progress``; returns the run summary.
        threshold: Match distance of ``--groundtruth`` scoring, metres.
        scores: The run is scored against ``--groundtruth`` when it completes (MOTA, IDF1, HOTA); the colour run
            reports its own error against it instead.
        sections: run.json ``config`` section of each part (for naming the options a resumed run changed).
    """

    name: str
    aliases: tuple[str, ...]
    help: str
    description: str
    parts: tuple[Part, ...]
    job: str
    threshold: float
    sections: Mapping[str, str]
    scores: bool = True

    def function(self) -> Callable[..., dict[str, Any]]:
        """The job function."""
        module, name = self.job.split(":")
        return getattr(importlib.import_module(module), name)

    def option_sections(self) -> dict[str, tuple[type, str]]:
        """run.json ``config`` section -> (config class, option prefix), for naming a changed value by its option."""
        by_part = {p.name: p for p in self.parts}
        return {section: (by_part[name].cls, by_part[name].prefix) for section, name in self.sections.items()}


def _lazy(module: str, name: str) -> type:
    return getattr(importlib.import_module(module), name)


def _commands() -> dict[str, TrackCommand]:
    colour = "wptrack.trackers.colour"
    templates = "wptrack.trackers.templates"
    people = "wptrack.trackers.people"
    masks = _lazy("wptrack.motion.masks", "MaskConfig")
    control = Part("control", RunControl, "", "run")
    return {
        "color": TrackCommand(
            name="color",
            aliases=("colour",),
            help="S1 colour particle filter (Barrera et al.)",
            description="One coloured object in 3D from two or more calibrated cameras: particles are 3D points, a "
            "gaussian walk, 5x5 window colour counts in HSI; the product over cameras in log space.",
            parts=(
                Part("inputs", _lazy(f"{colour}.run", "ColourInputs"), "", "inputs"),
                Part("target", _lazy(f"{colour}.tracker", "HSITarget"), "", "target colour (HSI)"),
                Part("config", _lazy(f"{colour}.tracker", "ColorConfig"), "", "tracker (ColorConfig)"),
                control,
            ),
            job=f"{colour}.run:run_colour_job",
            threshold=0.05,
            sections={"target": "target", "tracker": "config"},
            scores=False,
        ),
        "templates": TrackCommand(
            name="templates",
            aliases=(),
            help="humans and vehicles on a ground plane from one camera (S3, Juza et al.)",
            description="3D template particle filter: each particle a whole scene of human/vehicle templates, "
            "weighted by the XOR of its virtual image and the motion mask; new objects from the UOH.",
            parts=(
                Part("inputs", _lazy(f"{templates}.run", "TemplateInputs"), "", "inputs"),
                Part("config", _lazy(f"{templates}.config", "TemplateConfig"), "", "tracker (TemplateConfig)"),
                Part("masks", masks, "mask-", "motion masks (MaskConfig)"),
                control,
            ),
            job=f"{templates}.run:run_template_job",
            threshold=1.0,
            sections={"tracker": "config", "mask": "masks"},
        ),
        "people": TrackCommand(
            name="people",
            aliases=(),
            help="people in 3D from two or more overlapping cameras (S2: motion + multi-view colour)",
            description="One particle filter per person, particles are 3D points inside the person, weighted by the "
            "motion masks of every camera and a multi-view HSV colour descriptor; people are added where several "
            "cameras agree on unexplained motion.",
            parts=(
                Part("inputs", _lazy(f"{people}.run", "PeopleInputs"), "", "inputs"),
                Part("config", _lazy(f"{people}.config", "PeopleConfig"), "", "tracker (PeopleConfig)"),
                Part("masks", masks, "mask-", "motion masks (MaskConfig)"),
                control,
            ),
            job=f"{people}.run:run_people_job",
            threshold=0.5,
            sections={"tracker": "config", "mask": "masks"},
        ),
    }


_COMMANDS: dict[str, TrackCommand] | None = None


def commands() -> dict[str, TrackCommand]:
    """The track commands by name (built on first use: it imports the trackers' config modules)."""
    global _COMMANDS
    if _COMMANDS is None:
        _COMMANDS = _commands()
    return _COMMANDS


COMMANDS = ("color", "templates", "people")
"""The names of the track commands."""


def command(name: str) -> TrackCommand:
    """The track command ``name`` (or one of its aliases).

    Raises:
        ConfigError: no such tracker.
    """
    for c in commands().values():
        if name == c.name or name in c.aliases:
            return c
    raise ConfigError(f"tracker {name!r}: expected one of {', '.join(COMMANDS)}")


# --- the command line ----------------------------------------------------------------------------------------------
def add_track_arguments(parser: Any, cmd: TrackCommand, exclude: Sequence[str] = ()) -> None:
    """Add the options of every part of ``cmd`` to a ``wptrack track NAME`` parser, one group per part, and
    ``--config FILE`` (the tracker's config from YAML or JSON, e.g. a run.json's ``config.tracker``; options given
    on the command line apply on top of it). ``exclude``: flags (with their part's prefix) to leave out, those a
    command sets itself (``wptrack batch --videos``: ``out``, ``video``...)."""
    for part in cmd.parts:
        group = parser.add_argument_group(part.title or part.name)
        skip = [f[len(part.prefix) :] for f in exclude if f.startswith(part.prefix)]
        add_arguments(group, part.cls, prefix=part.prefix, exclude=skip)
        if part.name == "config":
            group.add_argument(
                "--config",
                dest="config_file",
                default=None,
                metavar="FILE",
                help="the tracker's config as YAML/JSON (its fields; nested ones as mappings); options given here "
                "apply on top",
            )


def parts_from_namespace(cmd: TrackCommand, args: Any) -> dict[str, Any]:
    """The parts of a run from parsed command-line options (:func:`add_track_arguments`)."""
    out = {}
    for part in cmd.parts:
        base = None
        if part.name == "config" and getattr(args, "config_file", None):
            base = load_file(part.cls, args.config_file)
        out[part.name] = from_namespace(part.cls, args, base=base, prefix=part.prefix)
    masks = next((p for p in cmd.parts if p.name == "masks"), None)
    if masks is not None:
        given = [f for f in option_map(masks.cls, masks.prefix) if getattr(args, f.replace("-", "_"), None) is not None]
        _check_mask_options(out, given, masks.prefix, "--")
    return out


def _check_mask_options(parts: Mapping[str, Any], flags: Sequence[str], prefix: str, dashes: str) -> None:
    """The mask options given (``flags``, with ``prefix``) are used by the run's mask method (the masks are given
    when the inputs name ``masks``): :func:`wptrack.motion.options.check_mask_options`."""
    from wptrack.motion.options import check_mask_options

    given_masks = bool(getattr(parts.get("inputs"), "masks", None))
    check_mask_options(parts["masks"], flags, prefix=prefix, dashes=dashes, given_masks=given_masks)


def options_from_namespace(cmd: TrackCommand, args: Any, exclude: Sequence[str] = ()) -> dict[str, Any]:
    """The options given on a command line parsed with :func:`add_track_arguments` (with the same ``exclude``), as
    a flat mapping by flag (what a batch manifest's ``args`` hold, :func:`parts_from_options`): only those given (an
    option left out keeps its default), ``config`` for ``--config FILE``."""
    out: dict[str, Any] = {}
    for part in cmd.parts:
        for flag in option_map(part.cls, part.prefix):
            v = None if flag in exclude else getattr(args, flag.replace("-", "_"), None)
            if v is not None:
                out[flag] = list(v) if isinstance(v, (list, tuple)) else v
    if getattr(args, "config_file", None):
        out["config"] = args.config_file
    return out


def parts_from_options(cmd: TrackCommand, values: Mapping[str, Any], where: str = "") -> dict[str, Any]:
    """The parts of a run from a flat mapping keyed by option names (with or without dashes), as a batch manifest's
    ``args`` hold them; ``config`` names a YAML/JSON file of the tracker's config (as ``--config``).

    Raises:
        ConfigError: an option no part has (named with ``where``), a missing required one, a bad value.
    """
    owner: dict[str, Part] = {}
    negatives: dict[str, str] = {}  # a boolean's opposite flag (no-virtual, joint) -> the flag
    for part in cmd.parts:
        for flag, opt in option_map(part.cls, part.prefix).items():
            owner[flag] = part
            if opt.type.base is bool and opt.type.size is None:
                negatives[f"no-{flag}"] = flag
                if opt.param is not None and opt.param.negative:
                    negatives[part.prefix + opt.param.negative] = flag
    split: dict[str, dict[str, Any]] = {p.name: {} for p in cmd.parts}
    config_file = None
    for key, value in values.items():
        flag = str(key).replace("_", "-")
        if flag == "config":
            config_file = value
            continue
        if flag in negatives and flag not in owner:
            if not isinstance(value, bool):
                raise ConfigError(f"{where}{key}: expected true or false, got {value!r}")
            flag, value = negatives[flag], not value
        if flag not in owner:
            raise ConfigError(f"{where}{key}: not an option of 'wptrack track {cmd.name}'")
        part = owner[flag]
        split[part.name][flag[len(part.prefix) :]] = value
    out = {}
    for part in cmd.parts:
        try:
            base = load_file(part.cls, str(config_file)) if part.name == "config" and config_file else None
            out[part.name] = from_options(part.cls, split[part.name], base=base, where=where)
        except ConfigError as e:
            text = str(e)
            raise ConfigError(text if text.startswith(where) else f"{where}{text}") from None
    masks = next((p for p in cmd.parts if p.name == "masks"), None)
    if masks is not None:
        try:
            _check_mask_options(out, [masks.prefix + k for k in split["masks"]], masks.prefix, "")
        except ConfigError as e:
            raise ConfigError(f"{where}{e}") from None
    return out


def run_command(cmd: TrackCommand, parts: Mapping[str, Any], progress: bool = False) -> dict[str, Any]:
    """Run a tracker: its job function with the parts (and ``progress`` bars); returns the run summary."""
    return cmd.function()(progress=progress, **parts)


EVALUATION_FILE = "evaluation.json"
"""Written into the run folder when a run is scored against its ``groundtruth`` (:func:`score_run`)."""


def check_scoring(cmd: TrackCommand, groundtruth: str | None) -> None:
    """Before a run given a ``groundtruth``: the file exists (for every tracker) and, for a run that is scored against
    it, the scoring package is importable, so the run does not end, minutes later, in an error that could have been
    said first, nor without the error report asked for.

    Raises:
        ConfigError: the file is missing, is a box annotation (.xml) of a scored run, or motmetrics cannot be
            imported.
    """
    from pathlib import Path

    if groundtruth is None:
        return
    if not Path(groundtruth).is_file():  # also for a tracker that reports its own error (colour): never skipped
        raise ConfigError(f"--groundtruth: ground-truth file not found: {groundtruth}")
    if not cmd.scores:
        return
    if str(groundtruth).lower().endswith(".xml"):  # image boxes need the boxes' image size: said before the run
        raise ConfigError(
            f"--groundtruth {groundtruth}: a run is scored against a frame,id,x,y[,z] table; score image boxes (.xml) "
            f"after the run with wptrack evaluate RUN --groundtruth {groundtruth} --rig RIG [--box-size WxH]"
        )
    from wptrack.evaluation.mot import _import_motmetrics

    _import_motmetrics()


def score_run(cmd: TrackCommand, parts: Mapping[str, Any]) -> Any:
    """Score a finished run's ``tracks.csv`` against the run's ``groundtruth`` (matching within the command's
    threshold), write ``evaluation.json`` into the run folder and return the evaluation; None when there is no ground
    truth or the tracker reports its own error (the colour tracker)."""
    from pathlib import Path

    control = parts["control"]
    if control.groundtruth is None or not cmd.scores:
        return None
    from wptrack.evaluation.mot import evaluate
    from wptrack.io.atomic import atomic_write_json
    from wptrack.io.tables import TRACKS_FILE

    ev = evaluate(control.groundtruth, Path(control.out) / TRACKS_FILE, threshold=cmd.threshold)
    atomic_write_json(Path(control.out) / EVALUATION_FILE, ev.to_dict())
    return ev


def option_names(cmd: TrackCommand) -> dict[str, str]:
    """run.json ``config`` paths of ``cmd``'s runs (``tracker.particles``, ``mask.window``, ``rig``) -> their
    command-line option (``--particles``, ``--mask-window``, ``--rig``), for saying which options a resumed run
    changed."""
    out = {}
    for section, (cls, prefix) in cmd.option_sections().items():
        for flag, opt in option_map(cls, prefix).items():
            out[".".join((section, *opt.path))] = f"--{flag}"
    inputs = next((p for p in cmd.parts if p.name == "inputs"), None)
    if inputs is not None:
        for flag, opt in option_map(inputs.cls, inputs.prefix).items():
            out[opt.path[-1]] = f"--{flag}"
        if "video" in out:
            out["videos"] = out["video"]
    return out


def replace_part(parts: Mapping[str, Any], name: str, **changes: Any) -> dict[str, Any]:
    """``parts`` with part ``name`` replaced by a copy with ``changes``."""
    return {**parts, name: dataclasses.replace(parts[name], **changes)}
