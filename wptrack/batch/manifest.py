"""A batch manifest (YAML): its runs, grids expanded, each a RunSpec (tracker, arguments, grid values), and the declared
parts of a tracker run built from a run's arguments (:func:`track_parts`), checked before any run starts."""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wptrack.core.errors import ConfigError

TRACKERS = ("color", "colour", "templates", "people", "function")
"""Run kinds of a manifest: the ``wptrack track`` trackers, and ``function`` (a Python callable)."""


PATH_ARGS = ("rig", "video", "masks", "groundtruth")
"""Arguments holding input paths: relative paths are taken from the manifest's folder."""


RESERVED_ARGS = ("out", "resume", "quiet", "verbose", "debug")
"""Options the batch layer sets itself."""


_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")


_MANIFEST_KEYS = {"tracker", "function", "args", "grid", "id", "runs", "retries"}


_RUN_KEYS = {"tracker", "function", "args", "grid", "id"}


@dataclass(frozen=True)
class RunSpec:
    """One run of a batch.

    Attributes:
        id: run id, the name of its folder in the batch's output.
        tracker: ``color``, ``templates``, ``people`` or ``function``.
        args: the run's options (``wptrack track TRACKER`` options without dashes, or the function's keywords),
            input paths absolute.
        function: ``module:name`` or ``/abs/file.py:name`` for ``tracker: function``.
        params: the grid values of this run (also in ``args``), the parameter columns of summary.csv.
    """

    id: str
    tracker: str
    args: dict[str, Any]
    function: str | None = None
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def hash(self) -> str:
        """Hash of what defines the run's outputs (tracker, function, arguments): a changed entry runs again."""
        text = json.dumps([self.tracker, self.function, self.args], sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class Manifest:
    """A loaded manifest: its runs (grids expanded) and retries (None: not given)."""

    path: Path
    runs: tuple[RunSpec, ...]
    retries: int | None = None


# ------------------------------------------------------------------------------------------------ manifest
def _id_value(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (list, tuple)):
        return "_".join(_id_value(v) for v in value)
    return str(value)


def _resolve_paths(args: dict[str, Any], base: Path) -> dict[str, Any]:
    def one(v: Any) -> Any:
        if isinstance(v, str) and v and not Path(v).expanduser().is_absolute():
            return str((base / v).resolve())
        return str(Path(v).expanduser()) if isinstance(v, str) else v

    out = dict(args)
    for key in PATH_ARGS:
        if key in out and out[key] is not None:
            out[key] = [one(v) for v in out[key]] if isinstance(out[key], list) else one(out[key])
    return out


def _mapping(value: Any, where: str) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a mapping, got {type(value).__name__}")
    return {str(k).replace("-", "_"): v for k, v in value.items()}


def _resolve_function(text: Any, base: Path, where: str) -> str:
    if not isinstance(text, str) or ":" not in text:
        raise ConfigError(f"{where}.function: expected 'module:name' or 'file.py:name', got {text!r}")
    target, name = text.rsplit(":", 1)
    if target.endswith(".py"):
        path = Path(target).expanduser()
        path = path if path.is_absolute() else (base / path).resolve()
        if not path.is_file():
            raise ConfigError(f"{where}.function: {path} not found")
        return f"{path}:{name}"
    return text


def load_manifest(path: str | os.PathLike) -> Manifest:
    """Read a batch manifest (YAML) and expand its grids.

    Raises:
        ConfigError: the file is missing or not YAML, an unknown key, a bad tracker, grid, id or duplicate id.
    """
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise ConfigError(f"manifest {path}: cannot read it ({e.strerror or e})") from None
    except yaml.YAMLError as e:
        raise ConfigError(f"manifest {path}: not valid YAML ({str(e).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"manifest {path}: expected a mapping with 'runs' and/or 'grid', got {type(data).__name__}")
    unknown = sorted(set(data) - _MANIFEST_KEYS)
    if unknown:
        raise ConfigError(f"manifest {path}: unknown key(s) {unknown}; expected some of {sorted(_MANIFEST_KEYS)}")
    retries = data.get("retries")
    if retries is not None and (isinstance(retries, bool) or not isinstance(retries, int) or retries < 0):
        raise ConfigError(f"manifest {path}: retries: expected an integer >= 0, got {retries!r}")
    base = path.resolve().parent
    defaults = {k: data[k] for k in ("tracker", "function", "args", "grid", "id") if k in data}
    entries = data.get("runs", [{}])
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"manifest {path}: runs: expected a non-empty list of runs")
    runs: list[RunSpec] = []
    for i, entry in enumerate(entries):
        where = f"manifest {path}: runs[{i}]"
        entry = _mapping(entry, where)
        unknown = sorted(set(entry) - _RUN_KEYS)
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {unknown}; expected some of {sorted(_RUN_KEYS)}")
        tracker = entry.get("tracker", defaults.get("tracker"))
        if tracker not in TRACKERS:
            raise ConfigError(f"{where}.tracker: expected one of {', '.join(TRACKERS)}, got {tracker!r}")
        tracker = "color" if tracker == "colour" else tracker
        function = None
        if tracker == "function":
            function = _resolve_function(entry.get("function", defaults.get("function")), base, where)
        args = {**_mapping(defaults.get("args"), f"manifest {path}: args"), **_mapping(entry.get("args"), where)}
        grid = {**_mapping(defaults.get("grid"), f"manifest {path}: grid"), **_mapping(entry.get("grid"), where)}
        for k, values in grid.items():
            if not isinstance(values, list) or not values:
                raise ConfigError(f"{where}.grid.{k}: expected a non-empty list of values, got {values!r}")
        bad = sorted(set(args) & set(RESERVED_ARGS))
        if bad:
            raise ConfigError(f"{where}.args: {bad} are set by the batch (the run's folder is OUT/<id>)")
        template = entry.get("id", defaults.get("id") if "runs" not in data else None)
        for combo in itertools.product(*grid.values()) if grid else [()]:
            params = dict(zip(grid, combo, strict=True))
            run_args = {**args, **params}
            if template is None:
                rid = f"run{i:03d}" + "".join(f"-{k}{_id_value(v)}" for k, v in params.items())
            else:
                try:
                    rid = str(template).format(**{k: _id_value(v) for k, v in run_args.items()})
                except (KeyError, IndexError, ValueError) as e:
                    raise ConfigError(f"{where}.id: cannot fill {template!r} ({e!r})") from None
                if params and rid == str(template):  # a grid without placeholders: add the values
                    rid += "".join(f"-{k}{_id_value(v)}" for k, v in params.items())
            if not _ID_RE.match(rid):
                raise ConfigError(f"{where}.id: {rid!r} is not a valid run id (letters, digits, . _ + -)")
            runs.append(RunSpec(rid, tracker, _resolve_paths(run_args, base), function, params))
    seen: set[str] = set()
    for r in runs:
        if r.id in seen:
            raise ConfigError(f"manifest {path}: run id {r.id!r} is used twice; give distinct ids")
        seen.add(r.id)
    return Manifest(path, tuple(runs), retries)


# ------------------------------------------------------------------------------------------ track arguments
def track_parts(spec: RunSpec, out_dir: str | os.PathLike) -> dict[str, Any]:
    """The declared parts of a tracker run (:mod:`wptrack.runs.spec`: inputs, the tracker's config, ...) from the
    run's ``args`` (keyed by ``wptrack track`` option names, with or without dashes), writing into ``out_dir``.

    Raises:
        ConfigError: an argument that is not an option of ``wptrack track TRACKER``, a missing required one or a bad
            value (the message names the run).
    """
    from wptrack.runs.spec import command, parts_from_options

    args = {k: v for k, v in spec.args.items() if v is not None}  # None: the option's default
    return parts_from_options(command(spec.tracker), {**args, "out": str(out_dir)}, where=f"run {spec.id}: args.")


def validate(spec: RunSpec) -> None:
    """Check a run's arguments without running it (the batch checks every run before starting any)."""
    if spec.tracker == "function":
        _load_function(spec.function)
    else:
        track_parts(spec, "OUT")


def _load_function(ref: str | None) -> Callable[..., Any]:
    import importlib
    import importlib.util

    target, name = str(ref).rsplit(":", 1)
    try:
        if target.endswith(".py"):
            mod_name = "wptrack_batch_" + hashlib.sha256(target.encode()).hexdigest()[:12]
            mod = sys.modules.get(mod_name)
            if mod is None:
                spec = importlib.util.spec_from_file_location(mod_name, target)
                mod = importlib.util.module_from_spec(spec)
                spec.loader.exec_module(mod)
                sys.modules[mod_name] = mod
        else:
            mod = importlib.import_module(target)
        fn = getattr(mod, name)
    except (ImportError, AttributeError, OSError) as e:
        raise ConfigError(f"function {ref}: cannot load it ({e})") from None
    if not callable(fn):
        raise ConfigError(f"function {ref}: not callable")
    return fn
