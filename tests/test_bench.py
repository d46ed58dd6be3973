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


def test_bench_unknown_suite(capsys):
    assert main(["bench", "--tracker", "nope", "--device", "cpu"]) == 2
    assert "unknown suite" in capsys.readouterr().err


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
