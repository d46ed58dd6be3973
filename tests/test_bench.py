"""`wptrack bench` runs a suite end to end on a tiny grid and checks the Warp tracker against the NumPy reference."""

from __future__ import annotations

import json

from wptrack.cli import main


def test_bench_color_tiny(tmp_path, capsys, device):
    out = tmp_path / "bench.json"
    code = main(
        [
            "bench",
            "-q",
            "--device",
            device,
            "--particles",
            "2000",
            "--cameras",
            "1",
            "2",
            "--frames",
            "3",
            "--out",
            str(out),
        ]
    )
    text = capsys.readouterr().out
    assert code == 0, text
    res = json.loads(out.read_text())["results"]
    assert [(r["particles"], r["cameras"]) for r in res] == [(2000, 1), (2000, 2)]
    for r in res:
        assert r["equivalent"] is True
        assert r["frame_ms"] > 0 and r["numpy_ms"] > 0 and r["particles_per_s"] > 0
        assert set(r["stages_ms"]) == {"observe", "predict_score", "estimate", "resample", "readback"}
    assert "frame ms" in text


def test_bench_color_weights(tmp_path, capsys, device):
    """--weights: resampling alone on synthetic log-weights, one case per particle count, the long-range path
    bit-identical to the serial scatter and to the NumPy reference."""
    out = tmp_path / "weights.json"
    argv = ["bench", "-q", "--device", device, "--particles", "3000", "--weights", "concentrated", "--frames", "2"]
    code = main([*argv, "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    (r,) = json.loads(out.read_text())["results"]
    assert r["weights"] == "concentrated" and r["equivalent"] is True, r
    assert r["long_ranges"] > 0 and r["max_offspring"] > 64 and r["resample_ms"] > 0 and r["serial_ms"] > 0
    assert "resample concentrated" in text


def test_bench_weights_only_for_color(capsys):
    assert main(["bench", "--tracker", "templates", "--device", "cpu", "--weights", "ordinary"]) == 2
    assert "--weights" in capsys.readouterr().err


def test_bench_unknown_suite(capsys):
    assert main(["bench", "--tracker", "nope", "--device", "cpu"]) == 2
    assert "unknown suite" in capsys.readouterr().err


def test_suite_registry_names_match():
    """Every registered suite imports from the package and carries the name it is registered under."""
    from wptrack.bench import SUITES, load_suite

    assert {"color", "color-e2e", "templates"} <= set(SUITES)
    for name in SUITES:
        assert load_suite(name).name == name


def test_numpy_references_are_independent_of_the_kernels():
    """The NumPy references check the kernels: importing them must load neither Warp nor wptrack.kernels."""
    import subprocess
    import sys

    code = (
        "import sys, wptrack.bench.numpy_colour, wptrack.bench.numpy_templates; "
        "bad = sorted(m for m in sys.modules if m == 'warp' or m.startswith(('warp.', 'wptrack.kernels'))); "
        "print(bad); sys.exit(1 if bad else 0)"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr


def test_bench_end_to_end_tiny(tmp_path, capsys):
    out = tmp_path / "e2e.json"
    assert (
        main(
            [
                "bench",
                "-q",
                "--tracker",
                "color-e2e",
                "--device",
                "cpu",
                "--particles",
                "1000",
                "--frames",
                "5",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    (r,) = json.loads(out.read_text())["results"]
    assert r["frames"] == 5 and r["decode_s"] > 0 and r["total_s"] > 0
    assert "decode alone" in capsys.readouterr().out


TEMPLATE_KEYS = {
    "tracker",
    "particles",
    "objects",
    "frame_ms",
    "frames_per_s",
    "step_ms",
    "stages_ms",
    "measure_ms",
    "particles_per_s",
    "bytes_per_particle",
    "state_bytes_est",
    "numpy_ms",
    "penalty_mean",
    "penalty_max_abs_diff",
    "penalty_max_diff_rel_mean",
    "penalty_median_rel_diff",
    "penalty_frac_particles_diff",
    "uoh_frac_pixels_diff",
    "equivalent",
    "equivalence_particles",
}


def test_bench_templates_tiny(tmp_path, capsys):
    """The template suite on one tiny CPU case: N=100, one object, 2 frames; the Warp penalties, complexities,
    log-weights and UOH agree with the NumPy reference on the same particles."""
    out = tmp_path / "templates.json"
    argv = ["bench", "-q", "--tracker", "templates", "--device", "cpu", "--particles", "100", "--objects", "1"]
    code = main([*argv, "--frames", "2", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    (r,) = json.loads(out.read_text())["results"]
    assert TEMPLATE_KEYS <= set(r)
    assert (r["tracker"], r["particles"], r["objects"], r["equivalence_particles"]) == ("templates", 100, 1, 100)
    assert r["equivalent"] is True and r["penalty_median_rel_diff"] < 1e-3
    assert r["penalty_mean"] > 0 and r["complexity_max_rel_diff"] < 1e-5 and r["uoh_frac_pixels_diff"] < 1e-3
    assert r["logw_max_rel_diff"] < 1e-4  # the same particles' eq. 6 (the CPU once compared against a view)
    assert r["frame_ms"] > 0 and r["numpy_ms"] > 0 and r["particles_per_s"] > 0
    assert set(r["stages_ms"]) == {"observe", "raster", "score", "uoh", "estimate", "resample_predict", "readback"}
    assert "fps" in text and "templates" in text


def test_bench_bad_out_is_said_before_the_cases(tmp_path, capsys):
    """`--out` naming a folder (or lying under a file) is one `wptrack: error:` line, exit 2, before any case runs
    (it was an internal error, IsADirectoryError or FileNotFoundError, after the first case)."""
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    argv = ["bench", "--tracker", "templates", "--device", "cpu", "--particles", "100", "--objects", "1"]
    for out in (tmp_path, blocker / "b.json"):
        assert main([*argv, "--frames", "2", "--out", str(out)]) == 2
        captured = capsys.readouterr()
        err = captured.err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("wptrack: error:") and "not writable" in err[0], err
        assert "frame ms" not in captured.out, "no case may run"


def test_bench_templates_rejects_cameras(capsys):
    assert main(["bench", "--tracker", "templates", "--device", "cpu", "--cameras", "2"]) == 2
    assert "--objects" in capsys.readouterr().err


def _small_tracker(device, n=20_000):
    from wptrack.bench.colour import HUE, INTENSITY, SAT, bench_frames, bench_rig
    from wptrack.trackers.colour.tracker import ColorTracker, HSITarget

    rig = bench_rig(2)
    frames, balls = bench_frames(rig, 3)
    tr = ColorTracker(rig, HSITarget(HUE, SAT, INTENSITY), particles=n, sigma=0.01, init=balls[0], device=device)
    for f in frames:
        tr.step(f)
    return tr


def test_offspring_check_passes_and_catches_a_broken_resampler(device, monkeypatch):
    from wptrack.bench.colour import offspring_check

    tr = _small_tracker(device)
    res = offspring_check(tr, replays=8, groups=50)
    assert res["checked"] and res["bounds_ok"] and res["ok"], res
    # an identity "resampler" ignores the weights: the check must fail
    import warp as wp

    def identity(logw, est, slot, seed, frame, anc, enabled=None):
        anc.assign(wp.array(range(anc.shape[0]), dtype=wp.int32, device="cpu"))

    monkeypatch.setattr(tr.resampler, "from_log_weights", identity)
    bad = offspring_check(tr, replays=4, groups=50)
    assert not bad["ok"] and bad["max_abs_z"] > 5.0


def test_cpu_threads_harness_runs_workers():
    """The multi-core measurement harness (python -m wptrack.bench.cpu_threads) on tiny cases: threads with the
    tracker's untiled observation stage, and the NumPy reference filter."""
    from wptrack.bench.cpu_threads import run_workers

    r = run_workers("threads", "warp-observe", 2, 20_000, 1, 2)
    assert (r["workers"], r["frames"], len(r["worker_s"])) == (2, 2, 2)
    assert r["wall_s"] >= max(r["worker_s"]) > 0 and r["frames_per_s"] == 4 / r["wall_s"]
    r = run_workers("threads", "numpy", 1, 1000, 1, 2)
    assert r["impl"] == "numpy" and r["wall_s"] > 0 and r["cpu_s"] > 0 and r["cpu_ms_per_frame"] > 0


def test_bench_masks_end_to_end_tiny(device):
    """The masks suite's end-to-end case: the default mask pipeline over a video of three default windows, its wall
    time against decoding, reported as added and added/decode, whole pass and after the first mask; the 1920x1080
    end-to-end case only with a GPU."""
    from wptrack.bench.masks import Case, MasksSuite

    r = MasksSuite.run_case(Case(64, 48), device, frames=5)
    assert r["equivalent"] is True
    assert r["e2e_frames"] == 600 and r["e2e_windows"] == 3 and r["e2e_repeats"] == (1 if device == "cpu" else 2)
    assert r["e2e_ms"] > r["e2e_decode_ms"] > 0
    assert abs(r["added_ms"] - (r["e2e_ms"] - r["e2e_decode_ms"])) < 1e-9
    assert abs(r["added_vs_decode"] - r["added_ms"] / r["e2e_decode_ms"]) < 1e-9
    # the start-up (the first window read before the first mask) apart from the per-frame cost after it
    assert 0 < r["e2e_first_ms"] < 600 * r["e2e_ms"] and r["e2e_steady_ms"] > 0
    total = r["e2e_first_ms"] + 599 * r["e2e_steady_ms"]
    if r["e2e_repeats"] == 1:  # one pass: first + steady is the pass (medians of several passes need not add up)
        assert abs(total - 600 * r["e2e_ms"]) < 1e-6 * total
    assert abs(r["added_steady_ms"] - (r["e2e_steady_ms"] - r["e2e_decode_ms"])) < 1e-9
    assert abs(r["added_steady_vs_decode"] - r["added_steady_ms"] / r["e2e_decode_ms"]) < 1e-9
    row = MasksSuite.format_row(r)
    assert f"added/decode {r['added_vs_decode']:.2f}" in row and "3 windows" in row
    assert f"added/decode {r['added_steady_vs_decode']:.2f}" in row and "first mask after" in row
    assert "end to end: -" in MasksSuite.format_row(MasksSuite.run_case(Case(64, 48, e2e=False), device, frames=3))
    assert [c.e2e for c in MasksSuite.default_grid(False)] == [True, False]
    assert [c.e2e for c in MasksSuite.default_grid(True)] == [True, True]


def test_bench_masks_frames_bound_the_end_to_end_pass(tmp_path, capsys, caplog, monkeypatch):
    """Issue 30 item 7: `bench --tracker masks --frames 5` ran the 600-frame end-to-end pass anyway (~32 s of
    silence after a warning naming a temporary file). Now --frames bounds it, each case is announced and the bench's
    own short videos raise no warning."""
    from wptrack.bench.masks import Case, MasksSuite

    monkeypatch.setattr(MasksSuite, "default_grid", staticmethod(lambda is_cuda: [Case(64, 48)]))
    out = tmp_path / "masks.json"
    with caplog.at_level("WARNING"):
        assert main(["bench", "--tracker", "masks", "--device", "cpu", "--frames", "4", "--out", str(out)]) == 0
    (r,) = json.loads(out.read_text())["results"]
    assert r["frames"] == 4 and r["e2e_frames"] == 4
    err = capsys.readouterr().err
    assert "masks: case 1/1: 64x48, 4 frames, then the end-to-end mask pass over 4 frames" in err
    assert "shorter than the background window" not in caplog.text and ".avi" not in err


def test_bench_notes_only_for_the_default_grid(capsys):
    """Issue 30 item 13: a grid the user gave was told what the default grid leaves out; --weights printed the
    colour table's header above its resampling rows."""
    from wptrack.bench.templates import TemplateSuite

    argv = ["bench", "--tracker", "templates", "--device", "cpu", "--particles", "100", "--objects", "1"]
    assert main([*argv, "--frames", "1", "-q"]) == 0
    assert "leaves out" not in capsys.readouterr().out
    assert TemplateSuite.notes(False) and "leaves out N=10000 x 10" in TemplateSuite.notes(False)[0]
    assert TemplateSuite.notes(True) == []
    argv = ["bench", "-q", "--device", "cpu", "--particles", "2000", "--weights", "ordinary", "--frames", "1"]
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("resampling alone") and "frame ms" not in lines[0]
    assert lines[1].startswith("resample ordinary")


def test_bench_counts_are_positive_whole_numbers(capsys):
    """`--particles 1.5` ran one particle, `--particles 0` / `--objects 0` / `--cameras 0` failed after the table's
    header: now argparse's one line, exit 2, before anything runs; `1e2` still reads as 100."""
    from wptrack.cli.common import positive_count

    assert positive_count("1e2") == 100 and positive_count("2000") == 2000
    base = ["bench", "--device", "cpu", "--frames", "2"]
    for extra in (
        ["--tracker", "templates", "--particles", "1.5", "--objects", "1"],
        ["--tracker", "templates", "--particles", "0", "--objects", "1"],
        ["--tracker", "templates", "--particles", "100", "--objects", "0"],
        ["--tracker", "color", "--particles", "100", "--cameras", "0"],
    ):
        try:
            code = main([*base, *extra])
        except SystemExit as e:  # argparse's errors exit from the parser
            code = e.code
        captured = capsys.readouterr()
        err = captured.err.strip().splitlines()
        assert code == 2 and len(err) == 1 and err[0].startswith("wptrack: error:"), (extra, err)
        assert "frame ms" not in captured.out, extra
