"""`wptrack track templates` and `wptrack evaluate` end to end, and their bad-input errors (one line, exit 2,
no traceback, nothing written)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wptrack.cameras.rig import Camera, Rig
from wptrack.cli import main
from wptrack.core.errors import ConfigError
from wptrack.io.tables import read_tracks
from wptrack.io.video import write_video
from wptrack.trackers.templates.tracker import HumanPrior, TemplateConfig, TemplateTracker


def _rig(tmp_path, look_up: bool = False) -> str:
    target = [0, 8, 12] if look_up else [0, 8, 0]
    cam = Camera.look_at("cam0", 160, 120, position=[0, -6, 5], target=target, fx=130)
    path = tmp_path / "rig.yaml"
    Rig(cameras=(cam,)).save(path)
    return str(path)


def _masks(tmp_path, value: int, size=(160, 120), frames: int = 4) -> str:
    path = tmp_path / f"masks{value}_{size[0]}.avi"
    write_video(path, [np.full((size[1], size[0], 3), value, np.uint8) for _ in range(frames)], fps=10)
    return str(path)


def _run(args, capsys):
    try:
        code = main(args)
    except SystemExit as e:  # argparse errors exit from the parser
        code = e.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.fixture
def scene(tmp_path_factory):
    """A tiny s3-people run on the perfect masks (CPU)."""
    tmp = tmp_path_factory.mktemp("s3")
    assert main(["synth", "s3-people", "--out", str(tmp / "scene"), "--frames", "12", "-q"]) == 0
    return tmp


def test_track_templates_writes_outputs_and_evaluates(scene, capsys):
    pytest.importorskip("motmetrics")
    out = scene / "run"
    code, text, err = _run(
        [
            "track", "templates", "--rig", str(scene / "scene/rig.yaml"), "--masks", str(scene / "scene/cam0_mask.avi"),
            "--out", str(out), "--device", "cpu", "--particles", "200", "-q",
            "--groundtruth", str(scene / "scene/groundtruth.csv"),
        ],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    assert "accuracy" in text and "MOTA" in text
    header = (out / "tracks.csv").read_text().splitlines()[0]
    assert header.startswith("frame,id,x,y,z,class,length,width,height,orientation")
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "complete" and run["tracker"] == "templates" and run["summary"]["frames"] == 12
    assert (out / "best.csv").exists() and (out / "virtual.avi").exists()
    # offline confirmation (min_track_frames 8 by default): tracks.csv keeps the tracks of >= 8 rows of tracks_all.csv
    kept, every = read_tracks(out / "tracks.csv"), read_tracks(out / "tracks_all.csv")
    ids, counts = np.unique(every["id"], return_counts=True)
    assert run["min_track_frames"] == 8 and run["short_tracks_dropped"] == int(np.sum(counts < 8))
    assert sorted(set(kept["id"].tolist())) == sorted(ids[counts >= 8].tolist()) and len(kept["id"]) > 0
    code, text, err = _run(["evaluate", str(out), "--groundtruth", str(scene / "scene/groundtruth.csv")], capsys)
    assert code == 0 and "IDF1" in text and "HOTA" in text
    # issue 30: MOTChallenge files, image boxes of the run's camera for the tracks and the ground truth
    boxes, truth = (np.loadtxt(out / "mot" / p / "cam0.txt", delimiter=",", ndmin=2) for p in (".", "gt"))
    assert len(boxes) == len(kept["frame"]) and len(truth) == len(read_tracks(scene / "scene/groundtruth.csv")["id"])
    assert (out / "mot" / "world.txt").is_file() and (out / "mot" / "gt" / "world.txt").is_file()

    def iou(a, b):
        w = min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0])
        h = min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1])
        inter = max(w, 0) * max(h, 0)
        return inter / (a[2] * a[3] + b[2] * b[3] - inter)

    last = boxes[boxes[:, 0] == boxes[:, 0].max()]
    here = truth[truth[:, 0] == last[0, 0]]
    assert all(max(iou(b[2:6], t[2:6]) for t in here) > 0.5 for b in last)  # each tracked box lies on a true one


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--max-objects", "0"], "max_objects"),
        (["--particles", "-3"], "positive integer"),
        (["--t-add", "1.5"], "t_add"),
        (["--classes", "dog"], "classes"),
        (["--min-track-frames", "0"], "min_track_frames"),
        (["--min-in-image", "1.5"], "min_in_image"),
        (["--human-entry-px", "-1"], "human_entry_px"),
    ],
)
def test_bad_parameters(tmp_path, capsys, extra, message):
    out = tmp_path / "out"
    code, _, err = _run(
        ["track", "templates", "--rig", _rig(tmp_path), "--masks", _masks(tmp_path, 0), "--out", str(out), *extra],
        capsys,
    )
    assert code == 2 and message in err and "Traceback" not in err
    assert not out.exists()


def test_mask_size_differs_from_camera(tmp_path, capsys):
    out = tmp_path / "out"
    masks = _masks(tmp_path, 255, size=(100, 120))
    code, _, err = _run(["track", "templates", "--rig", _rig(tmp_path), "--masks", masks, "--out", str(out)], capsys)
    assert code == 2 and "100x120" in err and "160x120" in err and "cam0" in err
    assert not out.exists()


def test_camera_that_does_not_see_the_ground(tmp_path, capsys):
    out = tmp_path / "out"
    rig = _rig(tmp_path, look_up=True)
    code, _, err = _run(["track", "templates", "--rig", rig, "--masks", _masks(tmp_path, 0), "--out", str(out)], capsys)
    assert code == 2 and f"wptrack: error: {rig}: camera 'cam0' does not see the ground plane" in err, err
    assert not out.exists()


def test_no_input(tmp_path, capsys):
    code, _, err = _run(["track", "templates", "--rig", _rig(tmp_path), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "--video" in err


def test_negative_template_priors():
    with pytest.raises(ConfigError, match="human.dims_sd"):
        HumanPrior(dims_sd=(-0.1, 0.01, 0.01))
    with pytest.raises(ConfigError, match="max_objects"):
        TemplateConfig(max_objects=65)
    assert TemplateConfig(max_objects=64).max_objects == 64


def test_empty_and_full_foreground(tmp_path):
    """An empty scene tracks nothing and adds nothing; an all-foreground frame stays finite."""
    rig = Rig.load(_rig(tmp_path))
    tracker = TemplateTracker(rig, TemplateConfig(particles=100, max_objects=4), device="cpu")
    for _ in range(5):
        est = tracker.step(np.zeros((120, 160), np.uint8))
        assert est.objects == [] and est.added is None and est.penalty == 0
    for _ in range(8):
        est = tracker.step(np.ones((120, 160), np.uint8))
        assert np.isfinite(est.ess) and np.isfinite(est.loglik)
        assert all(np.all(np.isfinite(o.position)) for o in est.objects + est.best)
    assert est.added is not None or est.best  # everything is foreground: objects get proposed


def test_offline_masks_keep_backgrounds_for_the_report(scene, capsys):
    """A run on the video (offline masks, the default) saves each background window it used (atomically, with an
    index), and the report's Fig. 5 shows the nearest one beside the frame."""
    import cv2

    out = scene / "run-video"
    code, _, err = _run(
        [
            "track", "templates", "--rig", str(scene / "scene/rig.yaml"), "--video", str(scene / "scene/cam0.avi"),
            "--out", str(out), "--device", "cpu", "--particles", "100", "-q", "--save-masks",
        ],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    index = json.loads((out / "backgrounds" / "index.json").read_text())
    assert index["windows"] and [w["window"] for w in index["windows"]] == sorted(w["window"] for w in index["windows"])
    first = cv2.imread(str(out / "backgrounds" / index["windows"][0]["file"]), cv2.IMREAD_COLOR)
    frame0 = cv2.VideoCapture(str(scene / "scene/cam0.avi")).read()[1]
    assert first.shape == frame0.shape
    assert np.abs(first.astype(int) - frame0.astype(int)).mean() < 20  # a background of this scene, not noise

    from wptrack.trackers.templates.report import _background_for, _backgrounds

    saved = _backgrounds(out)
    assert len(saved) == len(index["windows"])
    window, image = _background_for(saved, 5)
    assert window == min(saved, key=lambda w: abs(w[1] - 5))[0] and image.shape == frame0.shape
    assert _background_for(_backgrounds(scene / "nowhere"), 5) is None


def test_background_saver_writes_in_its_thread_and_flushes(tmp_path, monkeypatch):
    """The saver hands each window's image to its own thread (the build does not wait for the PNG): flush returns
    once every image is written, an error of that thread is raised by the next call, and an image handed over after
    close is written in the caller's thread."""
    import threading

    from wptrack.trackers.templates import run as R

    gate, threads = threading.Event(), []
    real = R.BackgroundSaver._save

    def slow(self, *a):
        threads.append(threading.current_thread().name)
        gate.wait(5)
        real(self, *a)

    monkeypatch.setattr(R.BackgroundSaver, "_save", slow)
    saver = R.BackgroundSaver(tmp_path / "bg")
    saver(0, 12.0, np.zeros((8, 10, 3), np.uint8))  # returns while the image waits
    assert not (tmp_path / "bg" / "index.json").exists()
    gate.set()
    saver.flush()
    index = json.loads((tmp_path / "bg" / "index.json").read_text())
    assert index["windows"] == [{"window": 0, "centre": 12.0, "file": "window_0000.png"}]
    assert threads[0].startswith("wptrack-backgrounds")

    def fail(self, *a):
        raise OSError("disk full")

    monkeypatch.setattr(R.BackgroundSaver, "_save", fail)
    saver(1, 30.0, np.zeros((8, 10, 3), np.uint8))
    with pytest.raises(OSError, match="disk full"):
        saver.flush()
    monkeypatch.setattr(R.BackgroundSaver, "_save", slow)
    saver.close()
    saver(2, 50.0, np.zeros((8, 10, 3), np.uint8))  # after close: in this thread
    assert threads[-1] == threading.current_thread().name and (tmp_path / "bg" / "window_0002.png").exists()


def _template_args(scene, out, *extra):
    return [
        "track", "templates", "--rig", str(scene / "scene/rig.yaml"), "--masks", str(scene / "scene/cam0_mask.avi"),
        "--out", str(out), "--device", "cpu", "--particles", "100", "--max-frames", "4", "-q", *extra,
    ]  # fmt: skip


def test_groundtruth_scoring_checked_before_tracking(scene, capsys, monkeypatch):
    """Issue 30 item 2: --groundtruth without the scoring package (or with a missing file) is one error line
    before anything runs, not after the whole run."""
    import sys

    monkeypatch.setitem(sys.modules, "motmetrics", None)  # import motmetrics raises ImportError
    out = scene / "nomm"
    code, text, err = _run(_template_args(scene, out, "--groundtruth", str(scene / "scene/groundtruth.csv")), capsys)
    assert code == 2 and "motmetrics" in err and len(err.strip().splitlines()) == 1
    assert not out.exists() and "tracked" not in text
    monkeypatch.delitem(sys.modules, "motmetrics")
    code, _, err = _run(_template_args(scene, out, "--groundtruth", str(scene / "nope.csv")), capsys)
    assert code == 2 and "nope.csv" in err and "not found" in err and not out.exists()


def test_box_groundtruth_refused_before_tracking(scene, capsys):
    """`track templates --groundtruth boxes.xml` (PETS/Milan boxes, as `wptrack evaluate` takes them with --rig and
    --box-size) tracked the whole video, then failed on the table's columns; now one line before anything runs,
    naming the `wptrack evaluate` command that scores boxes."""
    pytest.importorskip("motmetrics")
    boxes = scene / "boxes.xml"
    boxes.write_text('<dataset><frame number="0"><objectlist></objectlist></frame></dataset>')
    out = scene / "xml"
    code, text, err = _run(_template_args(scene, out, "--groundtruth", str(boxes)), capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("wptrack: error:") and "wptrack evaluate" in err
    assert not out.exists() and "tracked" not in text


def test_report_is_written_when_scoring_fails(scene, capsys, monkeypatch):
    """Issue 30 item 2: a scoring failure after the run still leaves the --report (then exits 2 with the error)."""
    pytest.importorskip("pyvista")
    import wptrack.evaluation.mot

    def broken(*a, **k):
        raise ConfigError("ground truth: scoring failed on purpose")

    monkeypatch.setattr(wptrack.evaluation.mot, "evaluate", broken)
    out = scene / "scored"
    argv = _template_args(scene, out, "--groundtruth", str(scene / "scene/groundtruth.csv"), "--report")
    code, text, err = _run(argv, capsys)
    assert code == 2 and "scoring failed on purpose" in err
    assert (out / "report" / "index.html").exists() and "report:" in text


@pytest.mark.parametrize("flag", ["--video", "--masks"])
def test_templates_refuses_two_cameras(scene, capsys, flag):
    """Issue 30 item 3: two --video (or --masks) were silently the last one with the first camera's calibration."""
    video = str(scene / "scene/cam0.avi") if flag == "--video" else str(scene / "scene/cam0_mask.avi")
    out = scene / "two"
    argv = ["track", "templates", "--rig", str(scene / "scene/rig.yaml"), flag, video, flag, video, "--out", str(out)]
    code, _, err = _run([*argv, "--device", "cpu", "-q"], capsys)
    assert code == 2 and "one camera" in err and "--camera" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
