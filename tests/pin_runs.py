"""Fixed-seed runs whose ``tracks.csv`` is pinned byte for byte (``tests/data/pin/``), so that a change meant to
keep behaviour (a refactor, a move) is proved to keep it, and a change meant to alter it shows which trackers it
alters.

Each case is a synthetic scene rendered by ``wptrack synth`` and one ``wptrack track`` command on the CPU; the
PETS development clip case runs only where ``../shared/data`` is present. To regenerate the pinned files after a
deliberate behaviour change (say why in the commit)::

    python tests/pin_runs.py            # writes tests/data/pin/<case>.csv
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

PIN_DIR = Path(__file__).parent / "data" / "pin"
REPO = Path(__file__).resolve().parents[1]


def shared_data(name: str) -> Path | None:
    """``../shared/data/<name>`` beside the checkout (or beside a folder of worktrees above it), or None."""
    for p in (REPO.parent, REPO.parent.parent):
        d = p / "shared" / "data" / name
        if d.is_dir():
            return d
    return None


SCENES: dict[str, list[str]] = {
    "lab": ["synth", "s1-lab", "--frames", "40", "--seed", "1"],
    "office": ["synth", "s2-office", "--frames", "45", "--seed", "0"],
    "mixed": ["synth", "s3-mixed", "--frames", "30", "--seed", "11"],
}
"""Scene name -> the ``wptrack`` arguments that render it (``--out`` is added)."""

CASES: dict[str, tuple[str | None, list[str]]] = {
    "colour_mixture": (
        "lab",
        ["track", "color", "--rig", "{s}/rig.yaml", "--video", "{s}/cam1.avi", "--video", "{s}/cam2.avi",
         "--hue", "312", "348", "--sat", "0.3", "0.8", "--particles", "300", "--init-random", "--seed", "3"],
    ),
    "colour_prior": (
        "lab",
        ["track", "color", "--rig", "{s}/rig.yaml", "--video", "{s}/cam1.avi", "--video", "{s}/cam2.avi",
         "--hue", "312", "348", "--sat", "0.3", "0.8", "--particles", "200", "--init", "0.4", "0.1", "0.2",
         "--proposal", "prior", "--resampling", "residual", "--ess-threshold", "0.5", "--seed", "2"],
    ),
    "people": (
        "office",
        ["track", "people", "--rig", "{s}/rig.yaml", "--video", "{s}/cam1.avi", "--video", "{s}/cam2.avi",
         "--video", "{s}/cam3.avi", "--particles", "200", "--seed", "1"],
    ),
    "templates_offline": (
        "mixed",
        ["track", "templates", "--rig", "{s}/rig.yaml", "--video", "{s}/cam0.avi", "--particles", "300",
         "--seed", "1", "--no-virtual"],
    ),
    "templates_masks_joint": (
        "mixed",
        ["track", "templates", "--rig", "{s}/rig.yaml", "--masks", "{s}/cam0_mask.avi", "--particles", "200",
         "--seed", "4", "--joint", "--min-track-frames", "1", "--no-virtual"],
    ),
    "templates_pets": (
        None,
        ["track", "templates", "--rig", "{pets}/rig.yaml", "--video", "{pets_data}/video.avi", "--particles", "300",
         "--seed", "0", "--max-frames", "60", "--classes", "human", "--no-virtual"],
    ),
}  # fmt: skip
"""Case name -> (scene it tracks, or None for the PETS clip; ``wptrack`` arguments with ``{s}`` the scene folder)."""


def pets_rig(folder: Path, data: Path) -> Path:
    """The PETS View_001 rig (Tsai calibration scaled to the 480x360 video) in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    rig = folder / "rig.yaml"
    rig.write_text(f"cameras:\n  - tsai: {data / 'View_001.xml'}\n    width: 480\n    height: 360\n")
    return rig


def run_case(name: str, work: Path, scenes: dict[str, Path]) -> Path:
    """Run case ``name`` into ``work/<name>`` (rendering its scene into ``scenes`` once) and return its
    ``tracks.csv``. CPU, no progress bars."""
    from wptrack.cli import main

    scene, args = CASES[name]
    subs: dict[str, str] = {}
    if scene is None:
        data = shared_data("pets09-s2l1-view001-dev")
        if data is None:
            raise FileNotFoundError("the PETS development clip is not in ../shared/data")
        subs = {"pets": str(pets_rig(work / "pets", data).parent), "pets_data": str(data)}
    else:
        if scene not in scenes:
            folder = work / f"scene-{scene}"
            if folder.exists():
                shutil.rmtree(folder)
            assert main([*SCENES[scene], "--out", str(folder), "-q"]) == 0
            scenes[scene] = folder
        subs = {"s": str(scenes[scene])}
    out = work / name
    if out.exists():
        shutil.rmtree(out)
    argv = [a.format(**subs) for a in args] + ["--out", str(out), "--device", "cpu", "-q"]
    assert main(argv) == 0, argv
    return out / "tracks.csv"


if __name__ == "__main__":  # pragma: no cover - regenerates the pinned files
    import tempfile

    PIN_DIR.mkdir(parents=True, exist_ok=True)
    names = sys.argv[1:] or list(CASES)
    with tempfile.TemporaryDirectory() as tmp:
        scenes: dict[str, Path] = {}
        for case in names:
            try:
                tracks = run_case(case, Path(tmp), scenes)
            except FileNotFoundError as e:
                print(f"{case}: skipped ({e})")
                continue
            shutil.copyfile(tracks, PIN_DIR / f"{case}.csv")
            print(f"{case}: {tracks.stat().st_size} bytes")
