"""Configuration declared once: each field of a frozen config dataclass is a :func:`param` with its type, default,
help, units, the paper's symbol, its range and its command-line flag; everything else is derived from that one
declaration:

* validation (:func:`check`, called by each config's ``__post_init__``): type and range, with an error that names
  the field, the expected value and what was given;
* the command line (:func:`add_arguments`, :func:`from_namespace`): one option per field (nested configs too),
  with the help text, units, symbol and default;
* YAML and JSON (:func:`to_dict`, :func:`from_dict`): run specs for ``wptrack batch`` and the ``config`` of
  ``run.json``; :func:`from_options` reads a flat mapping keyed by option names, as a batch manifest writes them;
* documentation (:func:`describe`): a Markdown table of the fields.

A config class::

    @dataclass(frozen=True)
    class WalkConfig:
        sigma: float = param(0.03, help="deviation of the gaussian walk", units="m", symbol="sigma_m", lo=0.0,
                             lo_open=True)
        proposal: str = param("mixture", help="proposal distribution", choices=("prior", "mixture"))

        def __post_init__(self) -> None:
            check(self)
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import MISSING, Field, dataclass
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError

__all__ = [
    "Param",
    "add_arguments",
    "check",
    "describe",
    "env_count",
    "fields_of",
    "from_dict",
    "from_namespace",
    "from_options",
    "load_file",
    "option_map",
    "param",
    "to_dict",
]

_KEY = "wptrack"


@dataclass(frozen=True)
class Param:
    """What a config field declares besides its type and default.

    Attributes:
        help: One sentence for ``--help`` and the docs (no trailing period needed).
        units: Units of the value (``m``, ``m/s``, ``px``, ``frames`` ...), or None for plain numbers and names.
        symbol: The paper's symbol and equation (``sigma_m``, ``T_add, eq. 12``), or None.
        choices: The allowed values (strings), or None.
        lo, hi: Range of a number (or of every element of a tuple of numbers); None for unbounded.
        lo_open, hi_open: Whether ``lo`` / ``hi`` themselves are excluded.
        flag: The command-line option without the dashes (default: the field's name with ``-`` for ``_``, after the
            nested config's prefix); ``""`` keeps the field off the command line (YAML and ``--set`` only).
        metavar: Names of a tuple's elements on the command line, or None.
        negative: For a boolean: the flag that sets it False (default ``no-<flag>``), e.g. ``joint`` for
            ``partition``.
    """

    help: str
    units: str | None = None
    symbol: str | None = None
    choices: tuple[str, ...] | None = None
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    flag: str | None = None
    metavar: tuple[str, ...] | None = None
    negative: str | None = None


def param(
    default: Any = MISSING,
    *,
    help: str,  # noqa: A002 - the word users read
    units: str | None = None,
    symbol: str | None = None,
    choices: Sequence[str] | None = None,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    flag: str | None = None,
    metavar: Sequence[str] | None = None,
    negative: str | None = None,
    default_factory: Any = MISSING,
) -> Any:
    """A dataclass field with its :class:`Param` (see the module docstring)."""
    info = Param(
        help=help.rstrip("."),
        units=units,
        symbol=symbol,
        choices=tuple(choices) if choices is not None else None,
        lo=lo,
        hi=hi,
        lo_open=lo_open,
        hi_open=hi_open,
        flag=flag,
        metavar=tuple(metavar) if metavar is not None else None,
        negative=negative,
    )
    if default_factory is not MISSING:
        return dataclasses.field(default_factory=default_factory, metadata={_KEY: info})
    return dataclasses.field(default=default, metadata={_KEY: info})


# --- types ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Type:
    """A field's type, resolved: ``base`` (int, float, bool, str or a config class), ``size`` (None: a scalar,
    -1: a tuple of any length, n: a tuple of n), ``optional`` (None allowed)."""

    base: Any
    size: int | None
    optional: bool


_TYPES: dict[type, dict[str, _Type]] = {}


def _resolve(cls: type) -> dict[str, _Type]:
    if cls not in _TYPES:
        hints = typing.get_type_hints(cls)
        out = {}
        for f in dataclasses.fields(cls):
            out[f.name] = _parse_type(hints[f.name], f"{cls.__name__}.{f.name}")
        _TYPES[cls] = out
    return _TYPES[cls]


def _parse_type(tp: Any, where: str) -> _Type:
    optional = False
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        optional = len(args) < len(typing.get_args(tp))
        if len(args) != 1:
            raise TypeError(f"{where}: unsupported union {tp}")
        tp, origin = args[0], typing.get_origin(args[0])
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return _Type(args[0], -1, optional)
        if len(set(args)) != 1:
            raise TypeError(f"{where}: tuples of one element type only, got {tp}")
        return _Type(args[0], len(args), optional)
    if tp in (int, float, bool, str) or dataclasses.is_dataclass(tp):
        return _Type(tp, None, optional)
    raise TypeError(f"{where}: unsupported type {tp}")


def fields_of(cls_or_config: Any) -> list[tuple[Field, Param | None, _Type]]:
    """The fields of a config class (or instance): ``(field, its Param or None, its resolved type)``."""
    cls = cls_or_config if isinstance(cls_or_config, type) else type(cls_or_config)
    types_ = _resolve(cls)
    return [(f, f.metadata.get(_KEY), types_[f.name]) for f in dataclasses.fields(cls)]


# --- validation --------------------------------------------------------------------------------------------------
def _is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _is_real(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e18 else f"{x:g}"


def _range_text(p: Param, skip_lo: bool = False) -> str:
    lo = None if p.lo is None or skip_lo else f"{'>' if p.lo_open else '>='} {_num(p.lo)}"
    hi = None if p.hi is None else f"{'<' if p.hi_open else '<='} {_num(p.hi)}"
    return " and ".join(x for x in (lo, hi) if x)


def _expected(p: Param | None, t: _Type) -> str:
    name = {int: "an integer", float: "a number", bool: "true or false", str: "a name"}.get(t.base, "a value")
    positive = t.base is int and p is not None and p.lo == 1 and not p.lo_open
    if positive:
        name = "a positive integer"
    if t.size is not None:
        name = f"{t.size if t.size > 0 else 'a list of'} {name.split(' ', 1)[1]}s"
    if p is not None:
        if p.choices:
            name = f"one of {', '.join(p.choices)}"
        rng = _range_text(p, skip_lo=positive)
        if rng:
            name += f" {rng}"
        if p.units:
            name += f" ({p.units})"
    if t.optional:
        name += " or null"
    return name


def _coerce_scalar(value: Any, base: type) -> Any:
    """``value`` as ``base`` if it is one already (an int is a float), else raise ValueError."""
    if base is bool:
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
    elif base is int:
        if _is_int(value):
            return int(value)
    elif base is float:
        if _is_real(value) and math.isfinite(float(value)):
            return float(value)
    elif base is str:
        if isinstance(value, str):
            return value
    raise ValueError


def _in_range(v: float, p: Param) -> bool:
    if p.lo is not None and (v <= p.lo if p.lo_open else v < p.lo):
        return False
    return not (p.hi is not None and (v >= p.hi if p.hi_open else v > p.hi))


def check(config: Any, where: str = "") -> None:
    """Check every declared field of a (frozen) config against its type, choices and range, normalising it in place
    (a list becomes a tuple, an integer a float where a float is declared).

    Args:
        config: The config dataclass instance (call from its ``__post_init__``).
        where: Prefix of field names in messages (e.g. ``"human."``).

    Raises:
        ConfigError: ``<where><field>: expected <what>, got <value>``.
    """
    for f, p, t in fields_of(config):
        if dataclasses.is_dataclass(t.base):
            continue  # a nested config checked itself when it was built
        value = getattr(config, f.name)
        name = f"{where}{f.name}"
        if value is None and t.optional:
            continue
        try:
            if t.size is None:
                value = _coerce_scalar(value, t.base)
                items = [value]
            else:
                if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
                    raise ValueError
                items = [_coerce_scalar(v, t.base) for v in value]
                if t.size > 0 and len(items) != t.size:
                    raise ValueError
                value = tuple(items)
            if p is not None:
                if p.choices is not None and any(v not in p.choices for v in items):
                    raise ValueError
                if t.base in (int, float) and not all(_in_range(v, p) for v in items):
                    raise ValueError
        except ValueError:
            raise ConfigError(f"{name}: expected {_expected(p, t)}, got {getattr(config, f.name)!r}") from None
        object.__setattr__(config, f.name, value)


# --- dicts (YAML, JSON, run.json) ----------------------------------------------------------------------------------
def to_dict(config: Any) -> dict[str, Any]:
    """The config as plain data (nested configs as dicts, tuples as lists): what run.json and YAML hold."""

    def plain(v: Any) -> Any:
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
        if isinstance(v, (tuple, list)):
            return [plain(x) for x in v]
        if isinstance(v, np.generic):
            return v.item()
        return v

    return plain(config)


def from_dict(cls: type, data: Mapping[str, Any] | None, where: str = "", base: Any = None) -> Any:
    """Build a config from plain data (:func:`to_dict`'s output, a YAML mapping); keys left out keep ``base``'s value
    (default: the class defaults). Nested configs are mappings too.

    Raises:
        ConfigError: an unknown key (the message lists the known ones), a value of the wrong type or range.
    """
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where.rstrip('.') or cls.__name__}: expected a mapping of fields, got {data!r}")
    known = {f.name: (f, t) for f, _, t in fields_of(cls)}
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise ConfigError(f"{where}{unknown[0]}: unknown field; expected one of {', '.join(sorted(known))}")
    kw = {}
    for key, value in data.items():
        f, t = known[key]
        if dataclasses.is_dataclass(t.base):
            inner = getattr(base, key) if base is not None else None
            value = from_dict(t.base, value, f"{where}{key}.", inner)
        elif isinstance(value, list):
            value = tuple(value)
        kw[key] = value
    if base is not None:
        return dataclasses.replace(base, **kw)
    missing = [f.name for f in dataclasses.fields(cls) if _default(f) is MISSING and f.name not in kw]
    if missing:
        raise ConfigError(f"{where}{missing[0]}: required")
    return cls(**kw)


# --- options (the command line, flat manifests) --------------------------------------------------------------------
@dataclass(frozen=True)
class Option:
    """One command-line option of a config: its flag (without dashes), the field path in the config, its Param and
    type, and the default."""

    flag: str
    path: tuple[str, ...]
    param: Param | None
    type: _Type
    default: Any


REQUIRED = MISSING
"""The default of a field that has none (an input that must be given)."""


def _default(f: Field) -> Any:
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:  # type: ignore[misc]
        return f.default_factory()  # type: ignore[misc]
    return MISSING


def option_map(cls: type, prefix: str = "", path: tuple[str, ...] = ()) -> dict[str, Option]:
    """Every command-line option of a config class (nested configs included), by flag, after ``prefix``. A nested
    config's fields get the nested field's flag as a further prefix (``human-cost-a``; a nested field with flag
    ``""`` keeps its fields off the command line); a field whose Param names a flag has that flag after ``prefix``
    alone. Fields without a default are required (their Option's default is ``MISSING``)."""
    out: dict[str, Option] = {}
    for f, p, t in fields_of(cls):
        if p is not None and p.flag == "":
            continue
        if dataclasses.is_dataclass(t.base):
            sub = (p.flag if p is not None and p.flag else f.name.replace("_", "-")) + "-"
            default = _default(f)
            for flag, opt in option_map(t.base, prefix, (*path, f.name)).items():
                inner = opt.path[len(path) + 1 :]
                named = opt.param is not None and bool(opt.param.flag)
                key = flag if named else prefix + sub + flag[len(prefix) :]
                out[key] = dataclasses.replace(opt, flag=key, default=_get(default, inner))
            continue
        flag = prefix + (p.flag if p is not None and p.flag else f.name.replace("_", "-"))
        if flag in out:
            raise TypeError(f"{cls.__name__}: two fields give the option --{flag}")
        out[flag] = Option(flag, (*path, f.name), p, t, _default(f))
    return out


def _get(obj: Any, path: Sequence[str]) -> Any:
    for k in path:
        obj = getattr(obj, k)
    return obj


def _set(config: Any, path: Sequence[str], value: Any) -> Any:
    if len(path) == 1:
        return dataclasses.replace(config, **{path[0]: value})
    return dataclasses.replace(config, **{path[0]: _set(getattr(config, path[0]), path[1:], value)})


def _help(opt: Option) -> str:
    p = opt.param
    text = p.help if p is not None else opt.path[-1].replace("_", " ")
    bits = [b for b in ((p.units if p else None), (p.symbol if p else None)) if b]
    d = opt.default
    if d is MISSING:
        pass
    elif isinstance(d, bool):
        bits.append(f"default: {'on' if d else 'off'}")
    elif d is not None and d != ():
        bits.append("default: " + (" ".join(str(x) for x in d) if isinstance(d, tuple) else str(d)))
    return f"{text} ({'; '.join(bits)})" if bits else text


def add_arguments(
    parser: argparse.ArgumentParser | Any,
    cls: type,
    *,
    prefix: str = "",
    exclude: Sequence[str] = (),
    only: Sequence[str] | None = None,
) -> dict[str, Option]:
    """Add one option per field of ``cls`` (:func:`option_map`) to an argparse parser or group. Every option
    defaults to None (unset: the config's default applies), so :func:`from_namespace` applies only what was given;
    a field without a default is a required option. A boolean is two flags, ``--flag`` and ``--no-flag`` (or the
    Param's ``negative``).

    Args:
        parser: The parser or argument group.
        cls: The config class.
        prefix: Put before every flag (a command that embeds the config, e.g. ``mask-``).
        exclude: Flags (without the prefix) to leave out: the command adds them itself.
        only: Flags (without the prefix) to add (default: all).

    Returns:
        The options added, by flag (with the prefix).
    """
    added = {}
    for flag, opt in option_map(cls, prefix).items():
        bare = flag[len(prefix) :]
        if bare in exclude or (only is not None and bare not in only):
            continue
        t, p = opt.type, opt.param
        kw: dict[str, Any] = {"default": None, "help": _help(opt), "dest": _dest(flag)}
        if opt.default is MISSING:
            kw["required"] = True
        if t.base is bool and t.size is None:
            negative = prefix + p.negative if p is not None and p.negative else None
            if negative is None:
                kw["action"] = argparse.BooleanOptionalAction
                parser.add_argument(f"--{flag}", **kw)
            else:
                parser.add_argument(f"--{flag}", action="store_const", const=True, **kw)
                parser.add_argument(
                    f"--{negative}", action="store_const", const=False, dest=kw["dest"], default=None,
                    help=f"the opposite of --{flag}",
                )  # fmt: skip
            added[flag] = opt
            continue
        kw["type"] = {int: int, float: float, str: str}[t.base]
        if t.size is not None:
            kw["nargs"] = "+" if t.size < 0 else t.size
            if t.size < 0:  # a list: --video a.avi b.avi or --video a.avi --video b.avi
                kw["action"] = "extend"
            if p is not None and p.metavar:
                kw["metavar"] = p.metavar
        if p is not None and p.choices:
            kw["choices"] = p.choices
        parser.add_argument(f"--{flag}", **kw)
        added[flag] = opt
    return added


def _dest(flag: str) -> str:
    return flag.replace("-", "_")


def from_namespace(cls: type, args: argparse.Namespace, base: Any = None, prefix: str = "") -> Any:
    """The config ``base`` (default: the class defaults) with every option of ``cls`` given on the command line
    applied (options added by :func:`add_arguments` with the same ``prefix``)."""
    values = {}
    for flag in option_map(cls, prefix):
        v = getattr(args, _dest(flag), None)
        if v is not None:
            values[flag[len(prefix) :]] = v
    return from_options(cls, values, base=base)


def from_options(cls: type, values: Mapping[str, Any], base: Any = None, where: str = "") -> Any:
    """The config ``base`` (default: built from the options and the class defaults) with options applied, keyed by
    flag (``max-objects``) or by the same name with underscores (``max_objects``), as a batch manifest's ``args``
    write them. Required fields (no default) must be among the options when there is no ``base``.

    Raises:
        ConfigError: an unknown option (naming it and ``where``), a missing required one, or a value of the wrong type
            or range.
    """
    opts = option_map(cls)
    by_path: dict[tuple[str, ...], Any] = {}
    for key, value in values.items():
        flag = str(key).replace("_", "-")
        if flag not in opts:
            raise ConfigError(f"{where}{key}: unknown option")
        if isinstance(value, list):
            value = tuple(value)
        elif opts[flag].type.size == -1 and isinstance(value, (str, int, float)) and not isinstance(value, bool):
            value = (value,)  # one item of a list option, as a manifest may write it
        by_path[opts[flag].path] = value
    if base is None:
        top = {path[0]: v for path, v in by_path.items() if len(path) == 1}
        missing = [f.name for f in dataclasses.fields(cls) if _default(f) is MISSING and f.name not in top]
        if missing:
            flags = [o.flag for o in opts.values() if o.path == (missing[0],)]
            raise ConfigError(f"{where}{flags[0] if flags else missing[0]}: required")
        base = cls(**top)
        by_path = {path: v for path, v in by_path.items() if len(path) > 1}
    config = base
    for path, value in by_path.items():
        config = _set(config, path, value)
    return config


def load_file(cls: type, path: str, base: Any = None) -> Any:
    """A config from a YAML or JSON file holding a mapping of its fields (nested configs as mappings; what
    ``run.json``'s ``config`` and :func:`to_dict` hold), applied over ``base``.

    Raises:
        ConfigError: the file is missing or not YAML/JSON, or a field is unknown or invalid (naming the file).
    """
    import json
    from pathlib import Path

    import yaml

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise ConfigError(f"{p}: cannot read the config file: {e.strerror or e}") from None
    try:
        data = json.loads(text) if p.suffix.lower() == ".json" else yaml.safe_load(text)
    except (ValueError, yaml.YAMLError) as e:
        raise ConfigError(f"{p}: not valid YAML/JSON: {' '.join(str(e).split())}") from None
    try:
        return from_dict(cls, data, where=f"{p}: ", base=base)
    except ConfigError as e:
        if str(e).startswith(f"{p}: "):
            raise
        raise ConfigError(f"{p}: {e}") from None


# --- documentation ----------------------------------------------------------------------------------------------------
def describe(cls: type) -> str:
    """A Markdown table of a config's options: option, default, units, symbol, meaning."""
    rows = ["| option | default | units | symbol | meaning |", "|---|---|---|---|---|"]
    for flag, opt in option_map(cls).items():
        p = opt.param
        d = opt.default
        d = " ".join(str(x) for x in d) if isinstance(d, tuple) else ("" if d is None else str(d))
        rows.append(
            f"| `--{flag}` | {d} | {(p.units or '') if p else ''} | {(p.symbol or '') if p else ''} | "
            f"{p.help if p else ''} |"
        )
    return "\n".join(rows) + "\n"


def usable_cores() -> list[int]:
    """The CPU ids this process may run on: its CPU affinity (a batch worker bound to a block of cores, ``taskset``,
    a container's cpuset), ``range(os.cpu_count())`` where the platform has none."""
    import os

    try:
        return sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return list(range(os.cpu_count() or 1))


def host_cores() -> int:
    """How many cores this process may run on (:func:`usable_cores`); thread pools are sized from it."""
    return max(1, len(usable_cores()))


def env_count(name: str, default: int) -> int:
    """A thread or worker count from the environment variable ``name`` (the run-time levers of issue 27, e.g.
    ``WPTRACK_MASK_WORKERS``): ``default`` when it is unset or empty, else its value when a positive integer, else 1."""
    import os

    text = os.environ.get(name, "").strip()
    if not text:
        return default
    return int(text) if text.isdigit() and int(text) > 0 else 1
