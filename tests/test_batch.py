"""``wptrack batch``: manifests and grids, the same outputs as ``wptrack track``, idempotent re-runs, retries of
failed runs and of killed workers, in-process and on a local Ray instance (2 CPUs), and the sigma sweep."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from wptrack.batch import BATCH_FILE, run_batch
from wptrack.batch.manifest import load_manifest
from wptrack.cameras.rig import Camera, Rig
from wptrack.cli import main
from wptrack.core.errors import ConfigError
from wptrack.io.video import write_video

BALL = np.array([0.42, 0.45, 0.035])


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> dict:
    """Two small cameras watching a pink disc at BALL, 6 frames each (as tests/test_cli.py)."""
    import cv2

    d = tmp_path_factory.mktemp("scene")
    c1 = Camera.look_at("cam1", 96, 72, (0.5, 0.0, 0.195), (0.4, 0.45, 0.05), 90.0)
    c2 = Camera.look_at("cam2", 72, 96, (0.07, 0.485, 0.085), (0.45, 0.45, 0.05), 90.0, roll_deg=90)
    rig = Rig((c1, c2))
    rig.save(d / "rig.yaml")
    for cam in rig.cameras:
        img = np.full((cam.height, cam.width, 3), 90, np.uint8)
        uv, depth = cam.project(BALL[None])
        r = max(2, int(0.035 * cam.fx / depth[0]))
        cv2.circle(img, (int(round(uv[0, 0])), int(round(uv[0, 1]))), r, (180, 60, 230), -1)
        write_video(d / f"{cam.name}.avi", [img] * 6, fps=10)
    return {"dir": d}


COLOUR_ARGS = """\
tracker: color
args:
  rig: rig.yaml
  video: [cam1.avi, cam2.avi]
  hue: [300, 340]
  sat: [0.3, 1.0]
  init: [0.42, 0.45, 0.05]
  device: cpu
  keep_particles: 50
"""

FLAKY = """\
import os
from pathlib import Path


def run(out_dir, marker, mode="ok"):
    (Path(out_dir) / "partial.txt").write_text("written before the failure")
    if mode == "always":
        raise RuntimeError("this run always fails")
    if not Path(marker).exists():
        Path(marker).write_text("first attempt")
        if mode == "exit":
            os._exit(1)  # the worker process dies mid-run
        raise RuntimeError("first attempt fails")
    (Path(out_dir) / "result.txt").write_text("done")
    return {"frames": 1, "value": 42.0}
"""


def write_manifest(scene, text: str, name: str = "batch.yaml") -> Path:
    path = scene["dir"] / name
    path.write_text(text)
    return path


def read_summary(out: Path) -> list[dict]:
    with open(out / "summary.csv", newline="") as f:
        return list(csv.DictReader(f))


def flaky_manifest(tmp_path: Path, mode: str, retries: int = 2) -> Path:
    (tmp_path / "flaky.py").write_text(FLAKY)
    path = tmp_path / f"flaky-{mode}.yaml"
    marker = tmp_path / f"marker-{mode}"
    path.write_text(
        f"tracker: function\nfunction: flaky.py:run\nretries: {retries}\nruns:\n"
        f"  - id: flaky\n    args: {{marker: '{marker}', mode: {mode}}}\n"
    )
    return path


def assert_clean(out: Path) -> None:
    """No partial, old or attempt-counter leftovers in the batch folder."""
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]


# ---------------------------------------------------------------------------------------------- manifests
def test_manifest_grid_ids_paths_and_hash(scene):
    path = write_manifest(
        scene,
        COLOUR_ARGS
        + "runs:\n  - id: base\n  - id: 'n{particles}-s{seed}'\n    grid: {particles: [100, 200], seed: [0, 1]}\n"
        + "  - grid: {sigma: [0.01]}\n",
    )
    m = load_manifest(path)
    assert [r.id for r in m.runs] == ["base", "n100-s0", "n100-s1", "n200-s0", "n200-s1", "run002-sigma0.01"]
    r = m.runs[2]
    assert r.tracker == "color" and r.args["particles"] == 100 and r.args["seed"] == 1
    assert r.params == {"particles": 100, "seed": 1}
    assert r.args["rig"] == str(scene["dir"] / "rig.yaml")  # relative to the manifest's folder
    assert r.args["video"] == [str(scene["dir"] / "cam1.avi"), str(scene["dir"] / "cam2.avi")]
    assert len({x.hash for x in m.runs}) == len(m.runs)  # every entry its own hash
    assert load_manifest(path).runs[2].hash == r.hash  # stable


@pytest.mark.parametrize(
    "text, message",
    [
        ("runs: 3\n", "runs: expected a non-empty list"),
        ("tracker: nope\n", "tracker: expected one of"),
        ("speed: 1\n", "unknown key(s) ['speed']"),
        (COLOUR_ARGS + "runs:\n  - args: {particle: 10}\n", "args.particle: not an option of 'wptrack track color'"),
        (COLOUR_ARGS + "runs:\n  - args: {particles: many}\n", "run run000: args.particles: expected a positive"),
        (COLOUR_ARGS + "runs:\n  - id: a\n  - id: a\n", "run id 'a' is used twice"),
        (COLOUR_ARGS + "runs:\n  - id: ../x\n", "is not a valid run id"),
        (COLOUR_ARGS + "runs:\n  - grid: {seed: 3}\n", "grid.seed: expected a non-empty list"),
        (COLOUR_ARGS + "runs:\n  - args: {out: x}\n", "are set by the batch"),
        ("tracker: function\nfunction: nowhere.py:f\n", "nowhere.py not found"),
        ("tracker: function\nfunction: wptrack.io.run:nothing\n", "cannot load it"),
        ("runs: [\n", "not valid YAML"),
    ],
)
def test_bad_manifest_one_line_error_nothing_written(scene, tmp_path, capsys, text, message):
    path = write_manifest(scene, text, "bad.yaml")
    out = tmp_path / "out"
    assert main(["batch", str(path), "--out", str(out), "--address", "inline"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("wptrack: error: ") and message in err and err.count("\n") == 1, err
    assert not out.exists()


# ---------------------------------------------------------------------------------------------- in-process
def test_inline_batch_same_outputs_as_track_and_idempotent(scene, tmp_path, capsys):
    path = write_manifest(scene, COLOUR_ARGS + "runs:\n  - id: 'n{particles}'\n    grid: {particles: [100, 150]}\n")
    out = tmp_path / "batch"
    assert main(["batch", str(path), "--out", str(out), "--address", "inline"]) == 0
    assert "2/2 runs complete" in capsys.readouterr().out
    # the same run with `wptrack track color`
    d = scene["dir"]
    ref = tmp_path / "ref"
    argv = ["track", "color", "-q", "--rig", str(d / "rig.yaml"), "--video", str(d / "cam1.avi"), "--video",
            str(d / "cam2.avi"), "--hue", "300", "340", "--sat", "0.3", "1.0", "--init", "0.42", "0.45", "0.05",
            "--device", "cpu", "--keep-particles", "50", "--particles", "150", "--out", str(ref)]  # fmt: skip
    assert main(argv) == 0
    run = out / "n150"
    assert {p.name for p in ref.iterdir()} | {BATCH_FILE} == {p.name for p in run.iterdir()}
    assert (run / "tracks.csv").read_bytes() == (ref / "tracks.csv").read_bytes()
    a, b = (json.loads((p / "run.json").read_text()) for p in (run, ref))
    assert a["status"] == "complete" and a["config"] == b["config"] and a["summary"] == b["summary"]
    rows = read_summary(out)
    assert [r["id"] for r in rows] == ["n100", "n150"]
    assert [r["param.particles"] for r in rows] == ["100", "150"]
    assert all(r["status"] == "complete" and r["reused"] == "0" and r["frames"] == "6" for r in rows)
    assert float(rows[0]["seconds"]) > 0 and float(rows[0]["time.filter_s"]) > 0
    assert_clean(out)
    # again: nothing runs; a changed entry runs again and replaces its folder, the other is kept
    before = (out / "n100" / "run.json").stat().st_mtime_ns
    res = run_batch(path, out, address="inline")
    assert [r.get("reused") for r in res] == [True, True]
    write_manifest(scene, COLOUR_ARGS + "runs:\n  - id: 'n{particles}'\n    grid: {particles: [100]}\n"
                   "    args: {seed: 3}\n  - {id: n150, args: {particles: 150}}\n")  # fmt: skip
    res = run_batch(path, out, address="inline")
    assert [bool(r.get("reused")) for r in res] == [False, True]
    assert (out / "n100" / "run.json").stat().st_mtime_ns != before
    assert json.loads((out / "n100" / "run.json").read_text())["config"]["tracker"]["seed"] == 3
    assert_clean(out)


def test_inline_retries_a_failing_run(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["batch", str(flaky_manifest(tmp_path, "raise")), "--out", str(out), "--address", "inline"]) == 0
    assert "flaky: complete" in capsys.readouterr().out
    res = json.loads((out / "flaky" / BATCH_FILE).read_text())
    assert res["attempts"] == 2 and res["summary"]["value"] == 42.0
    assert (out / "flaky" / "result.txt").exists()
    assert_clean(out)
    rc = main(["batch", str(flaky_manifest(tmp_path, "always")), "--out", str(out / "b"), "--address", "inline"])
    assert rc == 1
    assert "1 run(s) failed: flaky" in capsys.readouterr().err
    (row,) = read_summary(out / "b")
    assert row["status"] == "failed" and row["attempts"] == "3" and "always fails" in row["error"]
    assert not (out / "b" / "flaky").exists()
    assert_clean(out / "b")


def test_without_ray_local_runs_inline(tmp_path, monkeypatch):
    import wptrack.batch as batch

    monkeypatch.setattr(batch, "ray_available", lambda: False)
    res = run_batch(flaky_manifest(tmp_path, "raise"), tmp_path / "out")  # address "local" by default
    assert res[0]["status"] == "complete" and res[0]["attempts"] == 2
    with pytest.raises(ConfigError, match="Ray is not installed"):
        run_batch(flaky_manifest(tmp_path, "raise"), tmp_path / "out2", address="ray://head:10001")


def test_sweep_is_a_batch_with_the_same_table(tmp_path, capsys):
    from wptrack.trackers.colour.experiments import jump_experiment
    from wptrack.trackers.colour.sweep import read_sweep

    kw = {"particles": 64, "iterations": 12, "jump_at": 6, "runs": 2, "device": "cpu"}
    ref = jump_experiment([0.02, 0.2], **kw)
    argv = ["sweep", "-q", "--sigma", "0.02", "--sigma", "0.2", "--particles", "64", "--iterations", "12",
            "--jump-at", "6", "--runs", "2", "--device", "cpu", "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    got = read_sweep(tmp_path / "errors.csv")
    np.testing.assert_allclose(got["errors"], ref["errors"], atol=1e-6)  # errors.csv keeps 6 decimals
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["summary"] == ref["summary"]
    rows = read_summary(tmp_path / "runs")
    assert len(rows) == 4 and {r["param.sigma"] for r in rows} == {"0.02", "0.2"}
    capsys.readouterr()
    assert main([*argv, "--report"]) == 0  # every run reused; the report has the sigma_m heatmap (S1 Fig. 7)
    assert all(r["reused"] == "1" for r in read_summary(tmp_path / "runs"))
    assert (tmp_path / "report" / "sweep_heatmap.png").stat().st_size > 0
    assert "sweep_heatmap.png" in (tmp_path / "report" / "index.html").read_text()


# ---------------------------------------------------------------------------------------------- Ray
@pytest.fixture(scope="module")
def ray_local():
    """One local Ray instance (2 CPUs, no GPU even on a GPU machine: the tests pin CPU tasks and check the error
    for a GPU request) for the module; run_batch uses an instance this process already joined."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, num_gpus=0, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


def test_ray_batch_same_outputs_as_inline(ray_local, scene, tmp_path):
    path = write_manifest(scene, COLOUR_ARGS + "runs:\n  - id: 'n{particles}'\n    grid: {particles: [100, 150]}\n")
    res = run_batch(path, tmp_path / "ray", address="local", gpus_per_task=0)
    assert [r["status"] for r in res] == ["complete", "complete"]
    assert len({r["pid"] for r in res}) >= 1 and all(r["gpus"] in (None, "") for r in res)
    run_batch(path, tmp_path / "inline", address="inline")
    for rid in ("n100", "n150"):
        a, b = (tmp_path / k / rid / "tracks.csv" for k in ("ray", "inline"))
        assert a.read_bytes() == b.read_bytes()
    assert [r["status"] for r in read_summary(tmp_path / "ray")] == ["complete", "complete"]
    assert_clean(tmp_path / "ray")


@pytest.mark.parametrize("pool", ["actors", "tasks"])
def test_ray_killed_task_is_retried(ray_local, tmp_path, pool):
    """The run's worker process dies (os._exit) in its first attempt: the run is retried on another worker (a new
    actor, or a new task worker), the retry starts from a clean partial folder and the completed run replaces it."""
    out = tmp_path / "out"
    res = run_batch(flaky_manifest(tmp_path, "exit"), out, address="local", gpus_per_task=0, pool=pool)
    assert res[0]["status"] == "complete" and res[0]["attempts"] == 2
    assert (tmp_path / "marker-exit").read_text() == "first attempt"  # the first attempt did die
    assert sorted(p.name for p in (out / "flaky").iterdir()) == [BATCH_FILE, "partial.txt", "result.txt", "run.json"]
    assert_clean(out)
    (row,) = read_summary(out)
    assert row["status"] == "complete" and row["attempts"] == "2" and row["value"] == "42.0"


def test_ray_failing_run_reported_after_retries(ray_local, tmp_path, capsys):
    out = tmp_path / "out"
    rc = main(["batch", str(flaky_manifest(tmp_path, "always", retries=1)), "--out", str(out),
               "--gpus-per-task", "0"])  # fmt: skip
    assert rc == 1
    (row,) = read_summary(out)
    assert row["status"] == "failed" and "always fails" in row["error"]
    assert not (out / "flaky").exists()
    assert_clean(out)
    with pytest.raises(ConfigError, match="the Ray cluster has 0 GPU"):
        run_batch(flaky_manifest(tmp_path, "raise"), tmp_path / "gpu", gpus_per_task=1)
    assert not (tmp_path / "gpu").exists()


def test_example_manifest_is_valid():
    from wptrack.batch.manifest import validate

    m = load_manifest(Path(__file__).resolve().parents[1] / "examples" / "batch_lab.yaml")
    assert [r.id for r in m.runs][:2] == ["n200-seed0", "n200-seed1"] and len(m.runs) == 7 and m.retries == 2
    for r in m.runs:
        validate(r)


def test_track_arguments_of_every_tracker(tmp_path):
    """Manifest args become the run's declared parts (wptrack.runs.spec), by option name: lists for list options,
    booleans as values or as their opposite flag (no_virtual, joint), None for an option's default."""
    from wptrack.batch.manifest import RunSpec, track_parts

    kw = {"rig": "r.yaml", "video": "v.avi", "classes": ["human"], "no_virtual": True, "camera": 0, "t_add": 0.4}
    t = track_parts(RunSpec("t", "templates", {**kw, "max_frames": None, "joint": True}), tmp_path)
    got = (t["config"].classes, t["inputs"].virtual, t["config"].camera, t["config"].t_add, t["control"].max_frames)
    assert got == (("human",), False, "0", 0.4, None) and t["config"].partition is False
    assert t["control"].out == str(tmp_path)
    p = track_parts(RunSpec("p", "people", {"rig": "r.yaml", "video": ["a.avi", "b.avi"], "p_b": 0.1}), "o")
    assert p["inputs"].video == ("a.avi", "b.avi") and p["config"].motion.p_b == 0.1 and not p["control"].resume
    kw = {"rig": "r", "video": "v", "hue": [350, 10], "sat": [0, 1], "init_random": True, "report": False}
    c = track_parts(RunSpec("c", "color", {**kw, "volume": [-1, -1, 0, 1, 1, 2]}), "o")
    assert c["target"].hue == (350.0, 10.0) and c["inputs"].init_random and c["control"].report is False
    assert c["config"].box == ((-1.0, -1.0, 0.0), (1.0, 1.0, 2.0))
    with pytest.raises(ConfigError, match="run t: args.report: expected true or false"):
        track_parts(RunSpec("t", "templates", {"rig": "r", "report": "yes"}), "o")
    with pytest.raises(ConfigError, match="run t: args.particels: not an option of 'wptrack track templates'"):
        track_parts(RunSpec("t", "templates", {"rig": "r", "particels": 5}), "o")


def test_attempts_count_only_this_invocation(scene, tmp_path, capsys):
    """Issue 30 item 5: a run that failed with a user error (a missing video, not retried) reported '2 attempts'
    once fixed, although nothing was retried in that invocation."""
    d = scene["dir"]
    path = write_manifest(scene, COLOUR_ARGS.replace("cam2.avi]", "cam2-later.avi]") + "id: one\n", "later.yaml")
    out = tmp_path / "batch"
    assert main(["batch", str(path), "--out", str(out), "--address", "inline"]) == 1
    assert "one: failed" in capsys.readouterr().out
    assert read_summary(out)[0]["attempts"] == "1"
    assert_clean(out)
    (d / "cam2-later.avi").write_bytes((d / "cam2.avi").read_bytes())
    assert main(["batch", str(path), "--out", str(out), "--address", "inline"]) == 0
    text = capsys.readouterr().out
    assert "one: complete" in text and " attempts)" not in text
    assert read_summary(out)[0]["attempts"] == "1"
    # a counter left by a crashed earlier invocation does not count either
    (out / ".one.attempts").write_text("5\n")
    (out / "one" / BATCH_FILE).unlink()
    assert main(["batch", str(path), "--out", str(out), "--address", "inline"]) == 0
    assert read_summary(out)[0]["attempts"] == "1"


def test_readme_batch_example_runs_as_written(tmp_path, monkeypatch, capsys):
    """Issue 30 item 5: the README's batch example failed from the repo root (the scene it needs was made only in
    a comment of the YAML) and its YAML differed from the file. Now the README shows the file as it is, and its
    commands (with 3 frames, in-process) run from a copy of the repo root."""
    import shlex

    root = Path(__file__).resolve().parents[1]
    readme = (root / "README.md").read_text(encoding="utf-8")
    manifest = (root / "examples" / "batch_lab.yaml").read_text(encoding="utf-8")
    assert f"```yaml\n{manifest}```" in readme
    block = readme[readme.index("```bash\nwptrack synth s1-lab --out examples/lab") :].split("```")[1]
    synth, batch = (line.split("#")[0] for line in block.splitlines()[1:3])
    assert batch.split()[:2] == ["wptrack", "batch"]
    (tmp_path / "examples").mkdir()
    (tmp_path / "examples" / "batch_lab.yaml").write_text(manifest)
    monkeypatch.chdir(tmp_path)
    argv = shlex.split(synth.replace("--frames 100", "--frames 3"))[1:]
    assert main([*argv, "-q"]) == 0
    assert main([*shlex.split(batch)[1:], "--address", "inline"]) == 0
    assert "7/7 runs complete" in capsys.readouterr().out
    assert {r["id"]: r["status"] for r in read_summary(tmp_path / "lab-batch")}["paper-filter"] == "complete"


# ---------------------------------------------------------------------------------------------- warm workers
VICTIM = """\
import os
import time
from pathlib import Path


def run(out_dir, marker, name):
    (Path(out_dir) / "partial.txt").write_text("written before the kill")
    if name == "victim" and not Path(marker).exists():
        Path(marker).write_text(str(os.getpid()))
        time.sleep(120)  # the test kills this worker here
    return {"frames": 1, "pid": os.getpid(), "threads": os.environ.get("WPTRACK_DECODE_THREADS")}
"""


def test_actor_killed_mid_run_is_retried_elsewhere(ray_local, tmp_path):
    """Issue 32: a warm worker (actor) is killed (SIGKILL from outside) in the middle of a run: the run is retried
    on another worker and completes, the other runs complete, the batch finishes, nothing partial is left."""
    import os
    import signal
    import threading
    import time

    (tmp_path / "victim.py").write_text(VICTIM)
    marker = tmp_path / "victim-pid"
    names = ["a", "victim", "b", "c"]
    runs = "".join(f"  - {{id: {n}, args: {{marker: '{marker}', name: {n}}}}}\n" for n in names)
    path = tmp_path / "victim.yaml"
    path.write_text(f"tracker: function\nfunction: victim.py:run\nretries: 1\nruns:\n{runs}")
    killed: list[int] = []

    def killer() -> None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if marker.exists() and marker.read_text().strip():
                time.sleep(0.2)  # mid-run: the victim sleeps
                killed.append(int(marker.read_text()))
                os.kill(killed[0], signal.SIGKILL)
                return
            time.sleep(0.05)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    out = tmp_path / "out"
    res = run_batch(path, out, gpus_per_task=0, cpus_per_task=1, pool="actors", pin_cores=True)
    thread.join(timeout=5)
    assert killed, "the victim run never started"
    by_id = {r["id"]: r for r in res}
    assert [r["status"] for r in res] == ["complete"] * 4
    assert by_id["victim"]["attempts"] == 2 and by_id["victim"]["summary"]["pid"] != killed[0]
    assert all(r["summary"]["threads"] == "1" for r in res)  # decode threads = the worker's cores
    if hasattr(os, "sched_setaffinity") and len(os.sched_getaffinity(0)) >= 2:
        assert all(r["worker_cores"] == 1 for r in res)  # each worker bound to a core of its own (the new one too)
    assert sorted(p.name for p in (out / "victim").iterdir()) == [BATCH_FILE, "partial.txt", "run.json"]
    assert_clean(out)
    rows = {r["id"]: r for r in read_summary(out)}
    assert rows["victim"]["attempts"] == "2" and rows["a"]["attempts"] == "1"


def test_warm_worker_runs_match_inline_and_record_stages(ray_local, scene, tmp_path):
    """One warm worker (2 cores: the whole local instance) runs three colour runs one after another: each gives the
    tracks.csv of the same run in-process, the later ones are warm (no imports, no Warp start, kernels loaded), and
    summary.csv / batch.json carry the stage times."""
    path = write_manifest(
        scene, COLOUR_ARGS + "runs:\n  - id: 'n{particles}'\n    grid: {particles: [100, 150, 200]}\n", "warm.yaml"
    )
    res = run_batch(path, tmp_path / "ray", gpus_per_task=0, cpus_per_task=2, pool="actors")
    assert [r["status"] for r in res] == ["complete"] * 3
    assert len({r["pid"] for r in res}) == 1 and sorted(r["worker_runs"] for r in res) == [0, 1, 2]
    run_batch(path, tmp_path / "inline", address="inline")
    for rid in ("n100", "n150", "n200"):
        a, b = (tmp_path / k / rid / "tracks.csv" for k in ("ray", "inline"))
        assert a.read_bytes() == b.read_bytes()
    rows = read_summary(tmp_path / "ray")
    stages = [c for c in rows[0] if c.startswith("stage.")]
    assert {"stage.import_s", "stage.frame_loop_s", "stage.decode_wait_s", "stage.total_s"} <= set(stages)
    for r in res:
        st = r["stages"]
        assert st["frame_loop_s"] > 0 and st["setup_s"] >= 0 and st["cpu_s"] > 0
        parts = ("import_s", "warp_init_s", "context_s", "setup_s", "module_load_s", "frame_loop_s", "score_s")
        assert sum(st[k] for k in parts) + st["finish_s"] == pytest.approx(st["total_s"], abs=1e-4)
        assert st["decode_wait_s"] <= st["frame_loop_s"] and st["to_first_frame_s"] < st["total_s"]
    warm = [r for r in res if r["worker_runs"] > 0]
    assert all(r["stages"]["warp_init_s"] < 0.01 for r in warm)  # Warp started once, in the worker's warm-up
    phases = json.loads((tmp_path / "ray" / "n100" / "run.json").read_text())["phases"]
    assert phases["frame_loop_s"] > 0 and phases["module_load_s"] >= 0
    assert_clean(tmp_path / "ray")


def test_kept_workers_serve_the_next_batch(ray_local, tmp_path):
    from wptrack.batch.actors import release_workers

    (tmp_path / "victim.py").write_text(VICTIM)
    a = tmp_path / "one.yaml"
    a.write_text(f"tracker: function\nfunction: victim.py:run\nargs: {{marker: '{tmp_path / 'm'}', name: a}}\n")
    first = run_batch(a, tmp_path / "one", gpus_per_task=0, keep_workers=True)
    second = run_batch(a, tmp_path / "two", gpus_per_task=0, keep_workers=True)
    assert first[0]["status"] == second[0]["status"] == "complete"
    assert second[0]["pid"] == first[0]["pid"] and second[0]["worker_runs"] >= 1  # the same warm process
    assert release_workers() >= 1 and release_workers() == 0


def test_pool_size():
    from wptrack.batch.actors import cpus_per_slot, pool_size

    assert pool_size({"GPU": 2, "CPU": 16}, 1, 1, 64) == 2
    assert pool_size({"GPU": 4, "CPU": 16}, 0.5, 2, 64) == 8  # two workers per GPU
    assert pool_size({"GPU": 4, "CPU": 16}, 0.5, 4, 64) == 4  # the cores limit them
    assert pool_size({"GPU": 4, "CPU": 16}, 1, 1, 3) == 3  # never more than the runs
    assert pool_size({"CPU": 2}, 0, 1, 8) == 2 and pool_size({"CPU": 2}, 0, 3, 8) == 1
    # the default cores per GPU worker: what the smallest GPU node gives each (a head without GPUs aside)
    head = {"Alive": True, "Resources": {"CPU": 8}}
    small = {"Alive": True, "Resources": {"CPU": 16, "GPU": 4}}
    big = {"Alive": True, "Resources": {"CPU": 64, "GPU": 8}}
    assert cpus_per_slot([head, small, big], 1) == 4 and cpus_per_slot([head, big], 1) == 8
    assert cpus_per_slot([head, small], 0.5) == 2 and cpus_per_slot([head], 1) == 1
    assert cpus_per_slot([{"Alive": False, "Resources": {"CPU": 2, "GPU": 2}}, big], 1) == 8


def test_decode_threads_shared_among_a_runs_videos(scene, monkeypatch):
    from wptrack.io.decode import DECODE_THREADS_ENV
    from wptrack.io.frames import open_frames

    d = scene["dir"]
    videos = [str(d / "cam1.avi"), str(d / "cam2.avi")]
    default = list(open_frames(videos))
    monkeypatch.setenv(DECODE_THREADS_ENV, "5")
    frames = open_frames(videos)
    assert [s.threads for s in frames.sources] == [2, 2]
    got = list(frames)
    assert len(got) == len(default) == 6
    assert all(np.array_equal(a, b) for fa, fb in zip(default, got, strict=True) for a, b in zip(fa, fb, strict=True))
    monkeypatch.setenv(DECODE_THREADS_ENV, "1")
    assert [s.threads for s in open_frames(videos).sources] == [1, 1]


# ---------------------------------------------------------------------------------------------- --videos
def test_videos_batch_one_run_per_recording(scene, tmp_path, capsys, monkeypatch):
    """Issue 32: ``wptrack batch --videos`` without a manifest: one run per recording (two cameras paired by file
    stem), its id the stem, the track options of the tracker, the same outputs as ``wptrack track``; a progress bar
    and a table at the end; a second batch skips the completed runs."""
    d = scene["dir"]
    for cam in ("cam1", "cam2"):
        (tmp_path / cam).mkdir()
        for stem in ("day-1", "day 2"):
            (tmp_path / cam / f"{stem}.avi").write_bytes((d / f"{cam}.avi").read_bytes())
    monkeypatch.chdir(tmp_path)
    opts = ["--rig", str(d / "rig.yaml"), "--hue", "300", "340", "--sat", "0.3", "1.0", "--init", "0.42", "0.45",
            "0.05", "--device", "cpu", "--keep-particles", "50", "--particles", "120"]  # fmt: skip
    argv = ["batch", "--videos", "cam1/*.avi", "--videos", "cam2/*.avi", "--tracker", "color", *opts]
    assert main([*argv, "--out", "vb", "--address", "inline"]) == 0
    out = capsys.readouterr()
    assert "runs:" in out.err and "2/2" in out.err  # the progress bar over runs
    table = out.out[out.out.index("id ") :].splitlines()
    assert table[0].split() == ["id", "status", "frames", "seconds", "frames/s"]
    assert [line.split()[:3] for line in table[1:3]] == [["day-1", "complete", "6"], ["day_2", "complete", "6"]]
    ref = tmp_path / "ref"
    assert main(["track", "color", "-q", "--video", "cam1/day 2.avi", "--video", "cam2/day 2.avi", *opts,
                 "--out", str(ref)]) == 0  # fmt: skip
    assert (tmp_path / "vb" / "day_2" / "tracks.csv").read_bytes() == (ref / "tracks.csv").read_bytes()
    rows = read_summary(tmp_path / "vb")
    assert [r["id"] for r in rows] == ["day-1", "day_2"] and all(r["status"] == "complete" for r in rows)
    assert main([*argv, "--out", "vb", "--address", "inline", "-q"]) == 0  # again: both reused
    assert all(r["reused"] == "1" for r in read_summary(tmp_path / "vb"))


COLOUR_OPTS = "--tracker color --rig r.yaml --hue 1 2 --sat 0 1"


@pytest.mark.parametrize(
    "extra, message",
    [
        (f"--videos nothing/*.avi {COLOUR_OPTS}", "--videos nothing/*.avi: no file matches"),
        (f"--videos cam1/*.avi --videos cam2/*.avi {COLOUR_OPTS}", "do not pair up by name: b"),
        ("--videos cam1/*.avi --videos cam2/*.avi --tracker templates --rig r.yaml", "takes 1 video(s) per run"),
        ("--videos cam1/*.avi", "give the runs' --tracker"),
        ("m.yaml --videos cam1/*.avi", "a manifest or --videos, not both"),
        ("", "give a manifest (YAML) or --videos"),
        ("--videos cam1/*.avi --tracker templates", "the following arguments are required: --rig"),
        ("--videos cam1/*.avi --tracker templates --rig r --particels 3", "unrecognized arguments: --particels"),
    ],
)
def test_videos_batch_mistakes_one_line(tmp_path, capsys, monkeypatch, extra, message):
    for cam, stems in (("cam1", "ab"), ("cam2", "a")):
        (tmp_path / cam).mkdir()
        for stem in stems:
            (tmp_path / cam / f"{stem}.avi").write_bytes(b"x")
    monkeypatch.chdir(tmp_path)
    assert main(["batch", *extra.split(), "--out", "vb", "--address", "inline"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("wptrack: error: ") and message in err and err.count("\n") == 1, err
    assert not (tmp_path / "vb").exists()
