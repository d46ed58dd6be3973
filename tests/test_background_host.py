"""Host side of the offline background model (wptrack.motion.background): the fast gain, median, shadow-ratio and
hysteresis code against the plain NumPy formulas it replaced (the same numbers, byte for byte), the sampler's
forward reading, and the per-frame step on every device against the NumPy reference of the kernels."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wptrack.bench import numpy_masks
from wptrack.io.frames import open_source
from wptrack.io.video import write_video
from wptrack.motion import background as B
from wptrack.motion import stats as S
from wptrack.motion import windows as Wn
from wptrack.motion.levels import hysteresis
from wptrack.motion.masks import MaskConfig

H, W = 60, 80


def _frame_gain_ref(values: np.ndarray, background: np.ndarray) -> np.ndarray:
    out = np.ones(3)
    for c in range(3):
        ok = background[:, c] >= S.MIN_GAIN_LEVEL
        if ok.sum() >= 16:
            out[c] = float(np.median(values[ok, c] / background[ok, c]))
    return np.clip(out, 0.05, 20.0)


def _sample_gains_ref(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = samples.astype(np.float64)
    ref = np.median(x, axis=0)
    gains = np.stack([_frame_gain_ref(xk, ref) for xk in x])
    gains /= np.median(gains, axis=0, keepdims=True)
    return gains.astype(np.float32), np.median(x / gains[:, None, :], axis=0)


def _samples(rng: np.random.Generator, k: int, p: int = 3000) -> np.ndarray:
    base = rng.uniform(0, 255, (p, 3))  # some channels below MIN_GAIN_LEVEL
    gains = rng.uniform(0.6, 1.4, (k, 1, 3))
    x = np.clip(base[None] * gains + rng.normal(0, 3, (k, p, 3)), 0, 255).astype(np.uint8)
    x[:, : p // 10] = rng.integers(0, 256, (k, p // 10, 3))  # changed pixels (people)
    return x


@pytest.mark.parametrize("k", [1, 2, 5, 24, 25])
def test_sample_gains_and_frame_gain_equal_numpy_formulas(rng, k):
    samples = _samples(rng, k)
    gains, background = S.sample_gains(samples)
    ref_gains, ref_background = _sample_gains_ref(samples)
    np.testing.assert_array_equal(gains, ref_gains)
    np.testing.assert_array_equal(background, ref_background)
    assert k < 3 or np.ptp(gains, axis=0).min() > 0.1  # the gains differ: the test sees them
    for xk in samples:
        np.testing.assert_array_equal(S.frame_gain(xk, background), _frame_gain_ref(xk, background))
    dark = np.full_like(background, 10.0)  # too dark everywhere: gain 1
    np.testing.assert_array_equal(S.frame_gain(samples[0], dark), np.ones(3))


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("n", [1, 2, 7, 24, 25, 64, 65, 300, 301])
def test_median_last_equals_numpy_median(rng, n, threads, monkeypatch):
    """The same numbers as np.median, in the calling thread and with the rows split among threads (as a 1080p
    window's statistics are; here from 64 elements on)."""
    monkeypatch.setattr(S, "PARALLEL_MIN", 64)
    monkeypatch.setattr(S, "host_threads", lambda: threads)
    ints = rng.integers(0, 256, (4, 50, n), dtype=np.uint8)
    floats = ints / rng.uniform(0.5, 1.5, n)
    singles = (floats * np.float32(np.pi)).astype(np.float32)  # float32 means round as np.median's do
    for x in (ints, floats, singles, singles[0, 0]):
        got, expected = S.median_last(x), np.median(x, axis=-1)
        assert got.dtype == expected.dtype
        np.testing.assert_array_equal(got, expected)
        if x.dtype == np.uint8:
            np.testing.assert_array_equal(got, np.median(x.astype(np.float64), axis=-1))


def test_shadow_ratio_equals_full_formula(rng):
    """The ratios are computed on the foreground pixels only; the votes are those of the full formula."""
    k, p = 6, 4000
    background = rng.uniform(60, 200, (p, 3))
    mad = rng.integers(1, 4, (p, 3)).astype(np.uint8)
    samples = np.clip(background[None] + rng.normal(0, 3, (k, p, 3)), 0, 255)
    samples[:, :1500] *= rng.choice([0.45, 0.5, 0.7], (k, 1500, 1))  # shadows (neutral) and dark objects
    samples[:, 1500:1700, 0] *= 0.3  # coloured changes (not shadows)
    samples = samples.astype(np.uint8)
    gains = rng.uniform(0.95, 1.05, (k, 3)).astype(np.float32)
    b = background.astype(np.float64)
    s = np.maximum(3.0, 1.4826 * np.sqrt((mad.astype(np.float64) ** 2).mean(axis=1)))
    bb = (b * b).sum(axis=1)
    votes = []
    for xk, g in zip(samples, gains, strict=True):
        x = xk.astype(np.float64) / g[None, :]
        ib = (x * b).sum(axis=1)
        a = ib / np.maximum(bb, 1.0)
        cd = np.sqrt(np.maximum((x * x).sum(axis=1) - a * ib, 0.0) / np.maximum(bb, 1.0))
        z = np.sqrt(((x - b) ** 2).mean(axis=1)) / s
        votes.append(a[(z > 4.0) & (cd <= 0.1) & (bb >= 1.0)])
    edges = np.arange(0.3, 0.95 + 0.01, 0.02)
    counts, _ = np.histogram(np.concatenate(votes), bins=edges)
    smooth = np.convolve(counts.astype(np.float64), [0.25, 0.5, 0.25], mode="same")
    peaks = [i for i in range(1, len(smooth) - 1) if smooth[i] >= smooth[i - 1] and smooth[i] > smooth[i + 1]]
    expected = float(edges[max(peaks, key=lambda i: smooth[i])] + 0.01)
    got = S.shadow_ratio(samples, gains, background, mad, 4.0, 3.0, 0.1)
    assert got == expected and 0.44 < got < 0.52


def test_hysteresis_large_random_levels_equal_label_lookup(rng):
    """Against the label lookup it replaced (every component of ``levels > 0`` holding a strong pixel)."""
    for density, strong in ((0.05, 0.01), (0.4, 0.002), (0.7, 0.0), (0.0, 0.0)):
        levels = (rng.random((200, 300)) < density).astype(np.uint8)
        levels[rng.random((200, 300)) < strong] = 2
        count, labels = cv2.connectedComponents((levels > 0).view(np.uint8), connectivity=8)
        keep = np.zeros(count, np.uint8)
        keep[labels[levels == 2]] = 1
        keep[0] = 0
        got = hysteresis(levels)
        assert got.dtype == np.uint8
        np.testing.assert_array_equal(got, keep[labels])


class _CountingCapture:
    """A cv2.VideoCapture that counts the seeks."""

    def __init__(self, cap) -> None:
        self.cap, self.seeks = cap, 0

    def set(self, prop, value):
        self.seeks += 1
        return self.cap.set(prop, value)

    def __getattr__(self, name):
        return getattr(self.cap, name)


def test_sampler_reads_forward_and_keeps_the_next_windows_frames(tmp_path, rng):
    frames = 80
    video = np.clip(rng.normal(128, 40, (frames, 24, 32, 3)), 0, 255).astype(np.uint8)  # every frame differs
    path = tmp_path / "v.avi"
    write_video(path, video)
    source = open_source(path)
    decoded = np.stack(list(source))
    windows = Wn.plan_windows(frames, 40, 8)  # samples 5 frames apart, windows 20 frames apart
    assert len(windows) == 3
    sampler = Wn._Sampler(source)
    sampler.cap = _CountingCapture(source._open())
    for i, w in enumerate(windows):
        ahead = windows[i + 1].samples if i + 1 < len(windows) else ()
        got = sampler.read(w.samples, ahead)
        np.testing.assert_array_equal(np.stack(got), decoded[list(w.samples)])
        passed = [a for a in ahead if a <= w.samples[-1]]
        assert sorted(sampler.kept) == passed  # the overlap is kept, nothing else
        assert passed or i == len(windows) - 1
    assert sampler.cap.seeks == 0  # forward only: no window seeks back into its predecessor's frames
    sampler.close()
    assert sampler.kept == {}


def test_sampler_seeks_beyond_seek_gap(tmp_path, rng):
    frames = 3 * Wn.SEEK_GAP
    video = np.clip(rng.normal(128, 40, (frames, 24, 32, 3)), 0, 255).astype(np.uint8)
    path = tmp_path / "v.avi"
    write_video(path, video)
    source = open_source(path)
    decoded = np.stack(list(source))
    sampler = Wn._Sampler(source)
    sampler.cap = _CountingCapture(source._open())
    indices = (2, 3 + Wn.SEEK_GAP, 4 + Wn.SEEK_GAP, frames - 1)  # gaps from the next frame: 0, SEEK_GAP, 0, > it
    np.testing.assert_array_equal(np.stack(sampler.read(indices)), decoded[list(indices)])
    assert sampler.cap.seeks == 2  # the two long gaps; the short ones are grabbed
    sampler.close()


def test_offline_evidence_matches_numpy_reference(device, rng):
    """The per-frame step on the device (pinned staging buffers on CUDA, the caller's frame in place on the CPU)
    against the NumPy reference of the kernels, between two windows (w > 0), under a global gain change; each
    frame's probability is the caller's own array."""
    frames = 16
    grey = rng.uniform(60, 200, (H // 8, W // 8, 3)).astype(np.float32)
    bg = cv2.resize(grey, (W, H), interpolation=cv2.INTER_LINEAR)
    video = np.empty((frames, H, W, 3), np.uint8)
    for t in range(frames):
        img = bg * (0.8 if t >= 10 else 1.0) + rng.normal(0, 3.0, bg.shape)
        img[15:35, 4 + 3 * t : 16 + 3 * t] = (30, 200, 90)
        img[35:45, 4 + 3 * t : 16 + 3 * t] = img[35:45, 4 + 3 * t : 16 + 3 * t] * 0.9 + 4  # faint part: weak
        video[t] = np.clip(img, 0, 255).astype(np.uint8)
    config = MaskConfig(window=8, samples=5, device=device)
    model = B.OfflineBackground(open_source(video), config, device)
    outputs, equal, gains = [], 0, []
    for t in range(frames):
        mask, prob = model.evidence(t, video[t])
        gains.append(model.last_gain.mean())
        i, j, w = Wn.bracket(model.centres, t)
        b0, m0 = (a.numpy().reshape(H, W, 3) for a in model._window(i))
        b1, m1 = (a.numpy().reshape(H, W, 3) for a in model._window(j))
        p = model.params
        nb = (1.0 - w) * model._nb_scale[i] + w * model._nb_scale[j]
        # the local light field and patch statistics of this frame from the device (their kernels have their own
        # references: tests/test_background_illumination.py); the per-frame tests given them
        local = model.light.local.numpy().reshape(p.tiles_y, p.tiles_x, 3).astype(np.float64)
        st = model.light.patch.numpy().reshape(H, W, 6).astype(np.float64)
        veto = dict(
            st=st,
            texture=p.veto_texture,
            veto_ncc=p.veto_ncc,
            veto_grad=p.veto_grad,
            resid=p.veto_resid,
            illum_lo=p.illum_lo,
            illum_hi=p.illum_hi,
            illum_chroma=p.illum_chroma,
            gap=p.gain_gap,
        )
        ref = numpy_masks.foreground(
            video[t], b0, m0, b1, m1, w, p.threshold, p.soft_scale, p.noise_floor, bool(p.shadow), p.shadow_lo,
            p.shadow_hi, p.chroma_max, model.last_gain, p.low_threshold, p.spread_cap, p.shadow_edge_hi,
            config.neighbourhood, nb, field=numpy_masks.local_field(local, p.tile, H, W), veto=veto,
        )  # fmt: skip
        near = (np.abs(ref["z"] - p.threshold) < 1e-3) | (np.abs(ref["z"] - p.low_threshold) < 1e-3)
        assert np.all((mask.astype(bool) == ref["mask"]) | near)
        np.testing.assert_allclose(prob, ref["prob"], atol=1e-4)
        equal += bool(np.array_equal(mask.astype(bool), ref["mask"]))
        outputs.append((mask, prob, prob.copy()))
    model.close()
    assert equal >= frames - 2 and any(0 < w < 1 for w in [Wn.bracket(model.centres, t)[2] for t in range(frames)])
    assert min(gains) < 0.95 and abs(gains[0] - 1.0) < 0.02  # the dimming is compensated
    assert all(o[1] is not outputs[0][1] for o in outputs[1:])
    for mask, prob, copy in outputs:
        np.testing.assert_array_equal(prob, copy)  # not overwritten by a later frame
        assert mask.sum() > 100


def test_frame_gain_on_at_most_gain_pixels(rng, monkeypatch):
    """Above GAIN_PIXELS subsampled pixels, a frame's gain is the median over every m-th of them (m the smallest
    step that brings them under the bound), against the window's background at those pixels."""
    monkeypatch.setattr(B, "GAIN_PIXELS", 100)
    video = np.clip(rng.normal(120, 20, (4, H, W, 3)), 0, 255).astype(np.uint8)
    model = B.OfflineBackground(open_source(video), MaskConfig(window=4, samples=4, device="cpu"), "cpu")
    sub = model._sub.reshape(-1, 3)  # every 13th pixel: 370 of them
    step = model._gain_step
    assert step == 4 and len(sub[::step]) <= 100 < len(sub[:: step - 1])
    frame = (video[2] * 0.7).astype(np.uint8)
    model.evidence(2, frame)
    background = model._bg_sub[0].T  # (P', 3)
    expected = _frame_gain_ref(frame.reshape(-1)[sub[::step]], background[::step])
    np.testing.assert_array_equal(model.last_gain, expected)
    assert not np.array_equal(expected, _frame_gain_ref(frame.reshape(-1)[sub], background))
    model.close()


def test_unreadable_window_reuses_another_with_its_statistics(rng, caplog):
    """The frames before the last window's centre use the window before it when the last cannot be read (its
    gains, spread and shadow statistics too: no KeyError)."""
    video = np.clip(rng.normal(120, 5, (12, H, W, 3)), 0, 255).astype(np.uint8)
    model = B.OfflineBackground(open_source(video), MaskConfig(window=6, samples=3, device="cpu"), "cpu")
    assert len(model.windows) >= 2
    read = model._sampler.read
    model._sampler.read = lambda idx, ahead=(): [] if idx == model.windows[-1].samples else read(idx, ahead)
    before = [t for t in range(len(video)) if model.centres[-2] < t < model.centres[-1]]
    masks = [model.evidence(t, video[t])[0] for t in range(max(before) + 1)]
    model.close()
    assert before and "could be read; reusing another" in caplog.text
    assert sum(m.sum() for m in masks) < 0.01 * masks[0].size * len(masks)  # a static scene: background


def test_evidence_rejects_a_frame_of_another_size(rng):
    from wptrack.core.errors import FrameError

    video = np.clip(rng.normal(120, 5, (4, H, W, 3)), 0, 255).astype(np.uint8)
    model = B.OfflineBackground(open_source(video), MaskConfig(window=4, device="cpu"), "cpu")
    with pytest.raises(FrameError, match=r"frame 1 has shape \(60, 79, 3\), expected \(60, 80, 3\)"):
        model.evidence(1, video[1][:, :-1])
    model.close()
