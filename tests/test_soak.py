"""Long runs in bounded memory (issue 14): the soak benchmark's harness (growth computation, a short run, leak
detection) and the bounded stores behind it (timings reservoir, particle store, hull chunks)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wptrack.bench.soak import RSS_LIMIT, Case, SoakSuite, TemplateSoakSuite, growth, rss_bytes
from wptrack.io.chunklog import ChunkLog, read_chunks
from wptrack.io.run import ParticleStore, RunWriter, StageTimer

COLUMNS = ["frame", "id", "x", "y", "z"]

# ------------------------------------------------------------------------------------------ soak harness


def test_growth_is_relative_to_the_first_sample_at_or_after_settle():
    flat = [(1, 100), (500, 120), (1000, 200), (1500, 202), (2000, 201)]
    assert growth(flat, 1000) == pytest.approx(0.01)
    leaking = [(1000, 200), (1500, 210), (2000, 220), (2500, 230)]
    assert growth(leaking, 1000) == pytest.approx(0.15) and growth(leaking, 1000) > RSS_LIMIT
    assert growth(leaking, 1200) == pytest.approx(230 / 210 - 1)  # reference: the first sample >= settle
    assert growth([(1000, 200), (1500, 150)], 1000) == pytest.approx(0.0)  # shrinking is no growth
    assert growth([(1000, 200), (1500, 300), (2000, 200)], 1000) == pytest.approx(0.5)  # the peak counts
    assert growth([(1, 100), (500, 100)], 1000) is None


def test_soak_suite_short_run_structure():
    r = SoakSuite.run_case(Case(50, 2), "cpu", frames=40, sample_every=10, settle=10)
    assert r["frames"] == 40 and r["device"] == "cpu" and r["job"] == "color"
    assert [f for f, _ in r["rss"]] == [1, 10, 20, 30, 40]
    assert all(v > 0 for _, v in r["rss"]) and r["rss_settle"] == r["rss"][1][1]
    assert r["device_memory"] == [] and r["device_growth_bytes"] is None
    assert r["rss_growth"] == pytest.approx(max(v for _, v in r["rss"][1:]) / r["rss"][1][1] - 1)
    assert isinstance(r["passed"], bool)
    assert {"tracks.csv", "run.json", "particles.npz"} <= set(r["output_bytes"])
    assert "pass" in SoakSuite.format_row(r) or "FAIL" in SoakSuite.format_row(r)


def test_template_soak_suite_short_run():
    """The template tracker's job over the cycled masks: objects are tracked and written, memory sampled."""
    r = TemplateSoakSuite.run_case(Case(200, 1), "cpu", frames=24, sample_every=12, settle=12)
    assert r["tracker"] == "soak-templates" and r["job"] == "templates" and r["frames"] == 24
    assert [f for f, _ in r["rss"]] == [1, 12, 24] and isinstance(r["passed"], bool)
    assert r["output_bytes"]["tracks.csv"] > 200 and r["output_bytes"]["best.csv"] > 200  # objects tracked
    assert r["output_bytes"]["virtual.avi"] > 0


def test_soak_suite_detects_a_leak():
    """1 % of the process's memory kept per frame: 30 frames after settle it has grown by about 30 %, far beyond 5 %."""
    leak = max(1 << 20, rss_bytes() // 100)
    r = SoakSuite.run_case(Case(50, 2), "cpu", frames=40, sample_every=10, settle=10, leak_bytes_per_frame=leak)
    assert r["rss_growth"] >= 0.8 * 30 * leak / r["rss_settle"] and r["rss_growth"] > 0.15
    assert r["passed"] is False


def test_cli_soak_suite_writes_json(tmp_path, capsys):
    from wptrack.cli import main

    out = tmp_path / "soak.json"
    argv = ["bench", "-q", "--tracker", "soak", "--device", "cpu", "--particles", "50", "--frames", "30"]
    rc = main([*argv, "--out", str(out)])
    text = capsys.readouterr().out
    assert rc in (0, 1) and "RSS@settle" in text and "soak" in text
    res = json.loads(out.read_text())["results"][0]
    assert res["frames"] == 30 and res["settle"] == 29  # settle clamped to the run's length


# ------------------------------------------------------------------------------------------ bounded stores


def test_stage_timer_exact_then_reservoir():
    t = StageTimer(reservoir=64)
    for v in [0.003, 0.001, 0.002]:
        t.add(v)
    s = t.summary()
    assert s == {"total_s": pytest.approx(0.006), "count": 3, "mean_ms": pytest.approx(2.0), "median_ms": 2.0}
    assert t.exact
    rng = np.random.default_rng(0)
    big = StageTimer(reservoir=4096)
    values = rng.exponential(1.0, 100_000)
    for v in values:
        big.add(v)
    s = big.summary()
    assert not big.exact and s["count"] == 100_000
    assert s["total_s"] == pytest.approx(values.sum()) and s["mean_ms"] == pytest.approx(1e3 * values.mean())
    # the reservoir median lies within the 48th..52nd percentiles (rank standard error 0.8 %)
    lo, hi = np.quantile(values, [0.48, 0.52]) * 1e3
    assert lo < s["median_ms"] < hi
    # a biased reservoir (keeping only the first samples) would fail on a trend: the median of 0..N-1 is ~N/2
    trend = StageTimer(reservoir=1000)
    for v in range(100_000):
        trend.add(v)
    assert 45_000 < trend.summary()["median_ms"] / 1e3 < 55_000


def test_particle_store_is_bounded_and_evenly_spaced():
    store = ParticleStore(every=1, cap=10)
    for f in range(1000):
        store.add(f, np.zeros((2, 3), np.float32), np.ones(2, np.float32))
        assert len(store) <= 10
        kept = sorted(store.frames)
        assert kept == list(range(0, f + 1, store.stride))  # a function of the last frame alone
        assert store.stride == 1 or len(range(0, f + 1, store.stride // 2)) > 10  # the smallest such stride
    assert store.stride == 128 and sorted(store.frames) == list(range(0, 1000, 128))
    every3 = ParticleStore(every=3, cap=4)
    for f in range(30):
        every3.add(f, np.zeros((1, 3)), np.ones(1))
    assert sorted(every3.frames) == [0, 12, 24]


def test_run_writer_particles_resume_equals_uninterrupted(tmp_path):
    """The particle frames kept after a crash past the last checkpoint and a resume equal an uninterrupted run's."""

    def feed(rw, frames):
        for f in frames:
            rw.add_rows([(f, 0, 0.0, 0.0, 0.0)])
            rw.add_particles(f, np.full((4, 3), f, np.float32))
            rw.frame_done(f)

    with RunWriter(tmp_path / "full", "pf", COLUMNS, {}, particles_frames=8) as rw:
        feed(rw, range(100))
    cut = tmp_path / "cut"
    rw = RunWriter(cut, "pf", COLUMNS, {}, particles_frames=8, flush_seconds=3600)
    feed(rw, range(41))
    rw.flush()  # the checkpoint after frame 40
    feed(rw, range(41, 70))
    rw.flush()  # written later with a larger stride, then the process dies (no close)
    rw._csv_file.close()
    with RunWriter(cut, "pf", COLUMNS, {}, particles_frames=8, resume_from=40) as rw:
        feed(rw, range(41, 100))
    with np.load(tmp_path / "full" / "particles.npz") as a, np.load(cut / "particles.npz") as b:
        np.testing.assert_array_equal(a["frames"], b["frames"])
        np.testing.assert_array_equal(a["positions"], b["positions"])
        assert len(a["frames"]) <= 8 and int(a["every"]) == 16
    run = json.loads((cut / "run.json").read_text())
    assert run["frames"] == 100 and run["rows"] == 100


def test_chunk_log_streams_and_resumes(tmp_path):
    log = ChunkLog(tmp_path / "h", chunk_frames=10)
    verts = {}
    for f in range(35):
        for pid in (0, 1):
            v = np.full((4 + pid, 3), f + 0.1 * pid, np.float32)
            verts[(f, pid)] = v
            log.add(f, pid, v)
            assert len(log) <= 20  # one chunk in memory
    log.flush()
    assert sorted(p.name for p in (tmp_path / "h").iterdir()) == [f"{k:08d}.npz" for k in (0, 10, 20, 30)]
    index, allv = read_chunks(tmp_path / "h")
    assert len(index) == 70
    for f, pid, s, c in index:
        np.testing.assert_array_equal(allv[s : s + c], verts[(int(f), int(pid))])
    # resume after frame 12: chunks 20 and 30 dropped, chunk 10 kept up to frame 12, then continue
    log2 = ChunkLog(tmp_path / "h", chunk_frames=10, resume_after=12)
    for f in range(13, 35):
        for pid in (0, 1):
            log2.add(f, pid, verts[(f, pid)])
    log2.close()
    index2, allv2 = read_chunks(tmp_path / "h")
    np.testing.assert_array_equal(index2, index)
    np.testing.assert_array_equal(allv2, allv)
    assert read_chunks(tmp_path / "missing")[0].shape == (0, 4)
    some, somev = read_chunks(tmp_path / "h", frames=[3, 12, 34, 99])  # only these frames are loaded
    assert sorted({int(f) for f in some[:, 0]}) == [3, 12, 34] and len(some) == 6
    for f, pid, s, c in some:
        np.testing.assert_array_equal(somev[s : s + c], verts[(int(f), int(pid))])
    assert len(somev) == sum(int(c) for c in some[:, 3])
