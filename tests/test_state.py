"""The trackers' explicit state (``state_arrays`` / ``state_dict`` / ``load_state_dict``): a tracker restored from
another's state after k frames continues exactly as the original (every configuration whose chain differs), and a
state of another configuration is refused naming the arrays."""

from __future__ import annotations

import numpy as np
import pytest

from wptrack.cameras.rig import Rig
from wptrack.core.errors import ConfigError
from wptrack.io.frames import open_frames
from wptrack.motion.masks import open_masks
from wptrack.synth import render_scene
from wptrack.trackers.colour.tracker import ColorConfig, ColorTracker, HSITarget
from wptrack.trackers.templates.tracker import TemplateConfig, TemplateTracker

TARGET = HSITarget(hue=(312, 348), sat=(0.3, 0.8), intensity=(20, 240))


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    res = render_scene("s1-lab", tmp_path_factory.mktemp("lab"), frames=10, seed=0)
    return Rig.load(res.rig_path), list(open_frames([str(v) for v in res.videos]))


@pytest.fixture(scope="module")
def plaza(tmp_path_factory):
    res = render_scene("s3-mixed", tmp_path_factory.mktemp("plaza"), frames=16, seed=11)
    return Rig.load(res.rig_path), list(open_masks(masks=str(res.mask_videos[0])))


COLOUR = {
    "prior": {"proposal": "prior", "init": (0.4, 0.1, 0.2), "resampling": "residual", "ess_threshold": 0.5},
    "mixture": {"proposal": "mixture", "init": "random", "keep_particles": 20},
}
TEMPLATES = {
    "partitioned": {},
    "joint_stratified_ess": {"partition": False, "resampling": "stratified", "ess_threshold": 0.6},
}


def _same(a, b) -> None:
    for name in ("mean", "std", "map"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert (a.ess, a.loglik, a.resampled, a.frame) == (b.ess, b.loglik, b.resampled, b.frame)


@pytest.mark.parametrize("variant", sorted(COLOUR))
def test_colour_state_continues_identically(device, lab, variant):
    rig, frames = lab
    kw = {"particles": 300, "seed": 4, **COLOUR[variant]}
    a = ColorTracker(rig, TARGET, ColorConfig(), device=device, **kw)
    ref = [a.step(f) for f in frames]
    b = ColorTracker(rig, TARGET, ColorConfig(), device=device, **kw)
    for f in frames[:4]:
        b.step(f)
    state = b.state_dict()
    assert set(state) == set(b.state_arrays()) | {"__parity__", "__frames_done__"}
    c = ColorTracker(rig, TARGET, ColorConfig(), device=device, **{**kw, "seed": 4})
    c.load_state_dict(state)
    for f, r in zip(frames[4:], ref[4:], strict=True):
        _same(c.step(f), r)


@pytest.mark.parametrize("variant", sorted(TEMPLATES))
def test_template_state_continues_identically(device, plaza, variant):
    rig, masks = plaza
    cfg = TemplateConfig(particles=150, max_objects=6, seed=3, fps=15.0, **TEMPLATES[variant])
    a = TemplateTracker(rig, cfg, device=device)
    ref = [a.step(m) for m in masks]
    assert any(e.objects for e in ref)  # the scene has objects for the state to carry
    b = TemplateTracker(rig, cfg, device=device)
    for m in masks[:7]:
        b.step(m)
    c = TemplateTracker(rig, cfg, device=device)
    c.load_state_dict(b.state_dict())
    for m, r in zip(masks[7:], ref[7:], strict=True):
        e = c.step(m)
        assert [(o.id, o.cls) for o in e.objects] == [(o.id, o.cls) for o in r.objects]
        for o, p in zip(e.objects, r.objects, strict=True):
            np.testing.assert_array_equal(o.ground, p.ground)
        assert (e.ess, e.loglik, e.penalty) == (r.ess, r.loglik, r.penalty)


def test_state_of_another_configuration_is_refused(plaza):
    rig, masks = plaza
    joint = TemplateTracker(rig, TemplateConfig(particles=100, max_objects=4, partition=False), device="cpu")
    parted = TemplateTracker(rig, TemplateConfig(particles=100, max_objects=4), device="cpu")
    state = parted.state_dict()
    with pytest.raises(ConfigError, match=r"ancestors is int32 \(4, 100\), the tracker's is int32 \(1, 100\)"):
        joint.load_state_dict(state)
    bigger = TemplateTracker(rig, TemplateConfig(particles=120, max_objects=4), device="cpu")
    with pytest.raises(ConfigError, match="state.0.kind"):
        bigger.load_state_dict(state)
    with pytest.raises(ConfigError, match=r"missing \['next_label'\]"):
        parted.load_state_dict({k: v for k, v in state.items() if k != "next_label"})
    with pytest.raises(ConfigError, match=r"unexpected \['stray'\]"):
        parted.load_state_dict({**state, "stray": np.zeros(1)})
    state["frame"] = state["frame"].astype(np.float32)
    with pytest.raises(ConfigError, match="frame is float32"):
        parted.load_state_dict(state)


def test_every_tracker_keeps_the_contract(lab, plaza):
    """The three trackers (and the point filter of the extended paper's experiments) are ``Tracker``s, and the
    people tracker iterates over ``(images, masks)`` pairs like the others over their observations."""
    from wptrack.core.filter import Tracker
    from wptrack.synth.office import office_rig
    from wptrack.trackers.colour.gaussian3d import Gaussian3DTracker
    from wptrack.trackers.people.config import PeopleConfig
    from wptrack.trackers.people.tracker import PeopleTracker

    rig, frames = lab
    office = office_rig(160, 120)  # the people tracker needs ground two cameras see (the lab rig's volume has none)
    people = PeopleTracker(office, PeopleConfig(particles=50), device="cpu")
    trackers = [
        ColorTracker(rig, TARGET, ColorConfig(particles=50, init=(0.4, 0.1, 0.2)), device="cpu"),
        TemplateTracker(plaza[0], TemplateConfig(particles=50, max_objects=2), device="cpu"),
        people,
        Gaussian3DTracker(particles=50, sigma=0.03, device="cpu"),
    ]
    assert all(isinstance(t, Tracker) for t in trackers)
    images = [np.zeros((cam.height, cam.width, 3), np.uint8) for cam in office.cameras]
    masks = [np.zeros(img.shape[:2], np.uint8) for img in images]
    ests = list(people.track(((images, masks) for _ in frames), max_frames=3))
    assert [e.frame for e in ests] == [0, 1, 2] and all(e.people == [] for e in ests)


def test_garbage_collection_is_off_while_a_graph_is_captured(monkeypatch):
    """A CUDA graph capture runs with the collector off (after one collection), so the frees of an earlier run's
    arrays cannot land in the capture (the batch workers' "Cannot synchronize stream while graph capture is
    active"); the collector's state is restored, also after an error."""
    import gc

    from wptrack.core.filter import no_gc

    seen = []
    assert gc.isenabled()
    with no_gc():
        seen.append(gc.isenabled())
    assert seen == [False] and gc.isenabled()
    with pytest.raises(RuntimeError), no_gc():
        raise RuntimeError("capture failed")
    assert gc.isenabled()
    gc.disable()
    try:
        with no_gc():
            pass
        assert not gc.isenabled()  # off before, off after
    finally:
        gc.enable()


def test_the_frame_chain_captures_with_the_collector_off(monkeypatch):
    import contextlib
    import gc

    import warp as wp

    from wptrack.core.filter import FrameChain

    states = []

    class Chain(FrameChain):
        def stages(self, src, dst):
            return [("record", lambda: states.append(gc.isenabled()))]

    @contextlib.contextmanager
    def fake_capture(device):
        yield type("Capture", (), {"graph": "graph"})()

    monkeypatch.setattr(wp, "ScopedCapture", fake_capture)
    monkeypatch.setattr(wp, "capture_launch", lambda graph: states.append(graph))
    chain = Chain("cpu")
    chain.use_graph, chain._warm = True, [True, True]  # as on CUDA after the warm-up frame
    chain._run_chain(0, 1)  # captures, then replays
    chain._run_chain(0, 1)  # replays
    assert states == [False, "graph", "graph"] and gc.isenabled()
