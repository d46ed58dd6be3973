"""Configuration declared once (wptrack.core.config): validation, the command line, dicts and flat options are all
derived from one declaration per field."""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import pytest

from wptrack.core.config import (
    add_arguments,
    check,
    describe,
    from_dict,
    from_namespace,
    from_options,
    option_map,
    param,
    to_dict,
)
from wptrack.core.errors import ConfigError


@dataclass(frozen=True)
class Prior:
    cost_a: float = param(20.0, help="a_r of eq. 5", units="px", symbol="a_r", lo=0.0)
    dims: tuple[float, float, float] = param((1.7, 0.2, 0.1), help="size", units="m", lo=0.0, lo_open=True)

    def __post_init__(self) -> None:
        check(self, "prior.")


@dataclass(frozen=True)
class Demo:
    particles: int = param(1000, help="N", lo=1)
    sigma: float = param(0.03, help="walk deviation", units="m", symbol="sigma_m", lo=0.0, lo_open=True)
    scheme: str = param("systematic", help="resampling", choices=("systematic", "residual"))
    classes: tuple[str, ...] = param(("human", "vehicle"), help="classes", choices=("human", "vehicle"))
    joint: bool = param(False, help="joint filter")
    fps: float | None = param(None, help="frame rate", units="frames/s", lo=0.0, lo_open=True)
    hidden: int = param(3, help="not on the command line", flag="")
    renamed: float = param(0.5, help="a field with another flag", flag="p-b", hi=1.0)
    prior: Prior = param(default_factory=Prior, help="the prior", flag="human")

    def __post_init__(self) -> None:
        check(self)


def test_check_names_field_expected_and_value():
    with pytest.raises(ConfigError, match=r"^sigma: expected a number > 0 \(m\), got -1$"):
        Demo(sigma=-1)
    with pytest.raises(ConfigError, match=r"^particles: expected a positive integer, got 2.5$"):
        Demo(particles=2.5)
    with pytest.raises(ConfigError, match=r"^scheme: expected one of systematic, residual, got 'x'$"):
        Demo(scheme="x")
    with pytest.raises(ConfigError, match=r"^classes: expected .*one of human, vehicle.*got \('human', 'cat'\)"):
        Demo(classes=("human", "cat"))
    with pytest.raises(ConfigError, match=r"^prior.dims: expected 3 numbers > 0 \(m\), got \(1, 2\)$"):
        Prior(dims=(1, 2))
    with pytest.raises(ConfigError, match="^joint: expected true or false"):
        Demo(joint=1)
    with pytest.raises(ConfigError, match="^sigma: "):
        Demo(sigma=float("nan"))
    d = Demo(particles=5, sigma=1, classes=["human"], fps=None)
    assert d.sigma == 1.0 and isinstance(d.sigma, float) and d.classes == ("human",)


def test_command_line_is_derived():
    parser = argparse.ArgumentParser()
    opts = add_arguments(parser, Demo)
    assert set(opts) == {"particles", "sigma", "scheme", "classes", "joint", "fps", "p-b", "human-cost-a",
                         "human-dims"}  # fmt: skip
    helps = {a.option_strings[0]: a.help for a in parser._actions if a.option_strings}
    assert helps["--sigma"] == "walk deviation (m; sigma_m; default: 0.03)"
    assert helps["--human-cost-a"] == "a_r of eq. 5 (px; a_r; default: 20.0)"
    assert helps["--joint"] == "joint filter (default: off)"
    args = parser.parse_args(["--sigma", "0.1", "--classes", "human", "--no-joint", "--human-dims", "1", "2", "3"])
    d = from_namespace(Demo, args)
    assert (d.sigma, d.classes, d.joint, d.prior.dims, d.particles) == (0.1, ("human",), False, (1.0, 2.0, 3.0), 1000)
    with pytest.raises(SystemExit):
        parser.parse_args(["--scheme", "bogus"])
    with pytest.raises(ConfigError, match="^prior.dims"):
        from_namespace(Demo, parser.parse_args(["--human-dims", "1", "-2", "3"]))


def test_dicts_and_options_round_trip():
    d = Demo(sigma=0.2, prior=Prior(cost_a=5.0))
    data = to_dict(d)
    assert data["prior"] == {"cost_a": 5.0, "dims": [1.7, 0.2, 0.1]} and data["classes"] == ["human", "vehicle"]
    assert from_dict(Demo, data) == d
    assert from_dict(Demo, {"prior": {"cost_a": 7}}).prior == Prior(cost_a=7.0)
    with pytest.raises(ConfigError, match=r"^prior.cost_b: unknown field; expected one of cost_a, dims$"):
        from_dict(Demo, {"prior": {"cost_b": 1}})
    assert from_options(Demo, {"p_b": 0.25, "human-cost-a": 3}) == Demo(renamed=0.25, prior=Prior(cost_a=3.0))
    with pytest.raises(ConfigError, match="^runs\\[2\\].hidden: unknown option$"):
        from_options(Demo, {"hidden": 1}, where="runs[2].")
    assert option_map(Demo)["human-cost-a"].default == 20.0


def test_describe_lists_every_option():
    table = describe(Demo)
    assert "| `--sigma` | 0.03 | m | sigma_m | walk deviation |" in table
    assert table.count("\n") == 2 + len(option_map(Demo))


@dataclass(frozen=True)
class Inputs:
    rig: str = param(help="rig file")
    video: tuple[str, ...] = param(help="one video per camera")
    partition: bool = param(True, help="independent groups", negative="joint")
    shadows: bool = param(True, help="detect shadows", negative="keep-shadows")

    def __post_init__(self) -> None:
        check(self)


def test_required_fields_negative_flags_and_prefixes():
    parser = argparse.ArgumentParser()
    add_arguments(parser, Inputs, prefix="in-")
    with pytest.raises(SystemExit):  # --in-rig and --in-video are required
        parser.parse_args(["--in-video", "a.avi"])
    args = parser.parse_args(["--in-rig", "r.yaml", "--in-video", "a.avi", "b.avi", "--in-joint"])
    got = from_namespace(Inputs, args, prefix="in-")
    assert got == Inputs(rig="r.yaml", video=("a.avi", "b.avi"), partition=False, shadows=True)
    args = parser.parse_args(["--in-rig", "r", "--in-video", "v", "--in-partition", "--in-keep-shadows"])
    assert from_namespace(Inputs, args, prefix="in-").shadows is False
    assert from_options(Inputs, {"rig": "r", "video": ["v"], "partition": False}).partition is False
    with pytest.raises(ConfigError, match="^video: required$"):
        from_options(Inputs, {"rig": "r"})
    with pytest.raises(ConfigError, match="^x.yaml: video: required$"):
        from_dict(Inputs, {"rig": "r"}, where="x.yaml: ")


def test_load_file_reads_what_to_dict_writes(tmp_path):
    import json

    from wptrack.core.config import load_file

    d = Demo(sigma=0.2, classes=("human",), prior=Prior(dims=(1.8, 0.2, 0.1)))
    (tmp_path / "c.json").write_text(json.dumps(to_dict(d)))
    assert load_file(Demo, str(tmp_path / "c.json")) == d
    (tmp_path / "c.yaml").write_text("particles: 50\nprior: {cost_a: 3}\n")
    assert load_file(Demo, str(tmp_path / "c.yaml")) == Demo(particles=50, prior=Prior(cost_a=3.0))
    (tmp_path / "bad.yaml").write_text("particles: -5\n")
    with pytest.raises(ConfigError, match=r"bad.yaml: particles: expected a positive integer, got -5$"):
        load_file(Demo, str(tmp_path / "bad.yaml"))
    with pytest.raises(ConfigError, match="bad2.yaml: partcles: unknown field"):
        (tmp_path / "bad2.yaml").write_text("partcles: 5\n")
        load_file(Demo, str(tmp_path / "bad2.yaml"))


def test_list_options_accumulate_when_repeated():
    parser = argparse.ArgumentParser()
    add_arguments(parser, Inputs)
    args = parser.parse_args(["--rig", "r", "--video", "a.avi", "--video", "b.avi", "c.avi"])
    assert from_namespace(Inputs, args).video == ("a.avi", "b.avi", "c.avi")
