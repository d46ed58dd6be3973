"""Mask options that the chosen method does not use are refused in one line (exit 2, nothing written), on the command
line of ``wptrack masks`` and ``wptrack track`` and in batch manifests; once ``wptrack masks --method mog2 --window
50`` ran with the window silently unused. The table of which method reads which option is checked against the
options' help and against the masks themselves (changing an option a method does not use changes none of its masks).
Small, CPU only."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wptrack.cameras.rig import Camera, Rig
from wptrack.cli import main
from wptrack.core.config import fields_of
from wptrack.core.errors import ConfigError
from wptrack.io.video import write_video
from wptrack.motion.masks import METHODS, MaskConfig, open_masks
from wptrack.motion.options import SUBTRACTED, check_mask_options, methods_using
from wptrack.runs.spec import command, parts_from_options

W, H = 64, 48


def _frames(rng, n=6):
    """A textured background with a dark square moving across: (n, H, W, 3) uint8."""
    base = np.repeat(np.repeat(rng.uniform(60, 200, (H // 4, W // 4, 3)), 4, 0), 4, 1)
    out = np.clip(base + rng.normal(0, 2, (n, H, W, 3)), 0, 255).astype(np.uint8)
    for t in range(n):
        out[t, 16:32, 4 + 8 * t : 16 + 8 * t] = 20
    return out


def _video(tmp_path, rng) -> str:
    path = tmp_path / "v.avi"
    write_video(path, list(_frames(rng)), fps=10)
    return str(path)


def _one_line(capsys) -> tuple[str, str]:
    err = capsys.readouterr().err
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("Warp CUDA warning")]
    assert len(lines) == 1 and lines[0].startswith("wptrack: error: ") and "Traceback" not in err, err
    return lines[0], err


# ---------------------------------------------------------------------------------------------- wptrack masks
@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--method", "mog2", "--window", "50"], "--window: an option of the offline background model (--method "
         "offline)"),
        (["--method", "knn", "--illum-tiles", "0"], "--illum-tiles: an option of the offline background model"),
        (["--method", "mog2", "--shadow-band", "0"], "it has no effect with --method mog2"),
        (["--method", "knn", "--var-threshold", "10"], "--var-threshold: an option of --method mog2 only"),
        (["--method", "mog2", "--dist2-threshold", "100"], "--dist2-threshold: an option of --method knn only"),
        (["--history", "50"], "--history: an option of --method mog2 and knn only; it has no effect with --method "
         "offline"),
        (["--learning-rate", "0.1"], "--learning-rate: an option of --method mog2 and knn only"),
        (["--given-threshold", "100"], "--given-threshold: an option of given masks (--masks) only"),
        (["--method", "mog2", "--device", "cpu"], "--device cpu: the offline background model's device"),
    ],
)  # fmt: skip
def test_masks_refuses_options_of_another_method(tmp_path, rng, capsys, argv, needle):
    out = tmp_path / "out"
    extra = [] if "--device" in argv else ["--device", "cpu"]
    code = main(["masks", "--video", _video(tmp_path, rng), "--out", str(out), *extra, *argv, "-q"])
    line, err = _one_line(capsys)
    assert code == 2 and needle in line, err
    assert not out.exists()


@pytest.mark.parametrize("method", ["mog2", "knn"])
def test_masks_takes_the_options_of_its_method(tmp_path, rng, capsys, method):
    out = tmp_path / "out"
    own = ["--var-threshold", "20"] if method == "mog2" else ["--dist2-threshold", "300"]
    argv = ["masks", "--video", _video(tmp_path, rng), "--out", str(out), "--method", method, "--history", "5", *own]
    code = main([*argv, "--learning-rate", "0.2", "--open-px", "0", "--keep-shadows", "-q"])
    assert code == 0, capsys.readouterr().err
    assert (out / "masks.avi").is_file()


# ---------------------------------------------------------------------------------------------- wptrack track
def _rig(tmp_path) -> str:
    cam = Camera.look_at("cam0", W, H, position=[0, -6, 5], target=[0, 8, 0], fx=60)
    Rig(cameras=(cam,)).save(tmp_path / "rig.yaml")
    return str(tmp_path / "rig.yaml")


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--mask-window", "50"], "--mask-window: an option of the offline background model (--mask-method offline); "
         "it has no effect on given masks (--masks)"),
        (["--mask-open-px", "0"], "--mask-open-px: an option of masks made from camera frames"),
        (["--mask-keep-shadows"], "--mask-detect-shadows/--mask-keep-shadows: an option of masks made from camera "
         "frames"),
        (["--mask-method", "mog2"], "--mask-method mog2: given masks (--masks) are read, not made"),
    ],
)  # fmt: skip
def test_track_refuses_mask_options_for_given_masks(tmp_path, capsys, argv, needle):
    masks = tmp_path / "m.avi"
    write_video(masks, [np.zeros((H, W, 3), np.uint8)] * 3, fps=10)
    out = tmp_path / "out"
    code = main(["track", "templates", "--rig", _rig(tmp_path), "--masks", str(masks), "--out", str(out), *argv])
    line, err = _one_line(capsys)
    assert code == 2 and needle in line, err
    assert not out.exists()


def test_track_refuses_online_options_for_the_offline_model(tmp_path, rng, capsys):
    out = tmp_path / "out"
    argv = ["track", "templates", "--rig", _rig(tmp_path), "--video", _video(tmp_path, rng), "--out", str(out)]
    code = main([*argv, "--mask-history", "50"])
    line, err = _one_line(capsys)
    assert code == 2 and "--mask-history: an option of --mask-method mog2 and knn only" in line, err
    assert "with --mask-method offline" in line and not out.exists()


def test_manifest_args_are_checked_the_same_way(tmp_path):
    cmd = command("templates")
    base = {"rig": "rig.yaml", "out": "o"}
    with pytest.raises(ConfigError, match=r"^run a: mask-window: an option of the offline .* on given masks \(masks\)"):
        parts_from_options(cmd, {**base, "masks": ["m.avi"], "mask_window": 50}, where="run a: ")
    with pytest.raises(ConfigError, match=r"^run b: mask-var-threshold: an option of mask-method mog2 only"):
        parts_from_options(cmd, {**base, "video": ["v.avi"], "mask-method": "knn", "mask-var-threshold": 9}, "run b: ")
    parts = parts_from_options(cmd, {**base, "video": ["v.avi"], "mask-method": "mog2", "mask-history": 9})
    assert parts["masks"].history == 9
    parts = parts_from_options(cmd, {**base, "masks": ["m.avi"], "mask-given-threshold": 9, "mask-method": "given"})
    assert parts["masks"].threshold == 9


# ---------------------------------------------------------------------------------------------- the table
def test_the_table_agrees_with_the_help():
    prefixes = {"offline:": ("offline",), "mog2/knn:": ("mog2", "knn"), "mog2:": ("mog2",), "knn:": ("knn",),
                "given masks:": ("given",)}  # fmt: skip
    for f, p, _ in fields_of(MaskConfig):
        users = methods_using(f.name)
        said = next((m for pre, m in prefixes.items() if p.help.startswith(pre)), None)
        assert users == said if said is not None else users in (METHODS, SUBTRACTED), (f.name, users, p.help)
    with pytest.raises(ConfigError, match="--window"):
        check_mask_options(MaskConfig(method="mog2"), ["window"])
    check_mask_options(MaskConfig(method="mog2"), ["history", "open-px", "method"])  # its own: nothing raised


def _changed(field: str):
    """A valid value other than the default for ``field`` (a number doubled or bumped, a boolean flipped)."""
    default = getattr(MaskConfig(), field)
    if isinstance(default, bool):
        return not default
    special = {"method": "mog2", "device": "cpu", "samples": 3, "window": 4, "threshold": 50, "learning_rate": 0.5,
               "shadow_hi": 0.9, "illum_tiles": 0, "neighbourhood": 0, "illum_verify": 0.5, "illum_veto": 0.3,
               "shadow_lo": 0.6, "illum_keep": 0.5, "illum_dead": 0.1, "illum_grad": 0.5, "shadow_band": 0.2,
               "mode_band": 0.0, "spread_cap": 0.0, "fg_low": 2.0, "illum_radius": 1, "illum_patch": 2,
               "shadow_texture": 0.5, "shadow_peak": 0.2}  # fmt: skip
    return special.get(field, default * 2 if default else 1)


@pytest.mark.parametrize("method", ["mog2", "knn", "given"])
def test_options_a_method_does_not_use_change_none_of_its_masks(rng, method):
    """What the table says is true: every option it says ``method`` does not use leaves its masks unchanged (so a user
    passing one would have had no effect, which is why it is refused)."""
    frames = _frames(rng)
    source = dict(masks=frames) if method == "given" else dict(video=frames)
    base = MaskConfig(method=method, device="cpu")
    ref = np.stack(list(open_masks(config=base, **source)))
    assert ref.any() and not ref.all()
    unused = [f.name for f, _, _ in fields_of(MaskConfig) if method not in methods_using(f.name) and f.name != "method"]
    assert len(unused) >= 5
    for name in unused:
        other = dataclasses.replace(base, **{name: _changed(name)})
        np.testing.assert_array_equal(np.stack(list(open_masks(config=other, **source))), ref, err_msg=name)


def test_options_the_online_models_use_change_their_masks(rng):
    """The converse for a few fields the table gives to mog2 (a table that refused everything would fail here)."""
    frames = _frames(rng, 8)
    ref = np.stack(list(open_masks(video=frames, config=MaskConfig(method="mog2", open_px=0, close_px=0))))
    for name, value in (("history", 2), ("var_threshold", 1.0), ("learning_rate", 1.0)):
        cfg = MaskConfig(method="mog2", open_px=0, close_px=0, **{name: value})
        assert not np.array_equal(np.stack(list(open_masks(video=frames, config=cfg))), ref), name
