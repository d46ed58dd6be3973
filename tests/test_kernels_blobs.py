"""Geometric detection kernels of the S1 colour filter (``kernels.colour.blobs``, issue 29) against NumPy references on
every device: sub-block counts in the three scoring modes, peaks and blob centres, the per-chunk and per-camera
selection, triangulated candidates with their gates and mode-test scores, non-maximum suppression and ranking."""

from __future__ import annotations

import kernel_harness as harness
import numpy as np
import pytest
import warp as wp
from test_kernels_colour import TARGETS, mask_and_integral, upload, window_ref
from test_proposal import ray_dir, rig3

from wptrack.cameras.structs import DeviceRig
from wptrack.kernels.colour import blobs as kblobs
from wptrack.kernels.colour import proposal as kproposal
from wptrack.kernels.colour import scoring as kscoring

BLOCK = 256
SB = int(kblobs.SUBBLOCK)
CHUNK = int(kblobs.PEAK_CHUNK)
KEEP = int(kblobs.PEAK_KEEP)
LOG_ZERO = float(kproposal.LOG_ZERO)


def disc_frames(rig, rng, discs: int = 5):
    """Grey noise (never the target) with target-coloured discs of radius 3-9 pixels and sprinkled target pixels."""
    import cv2

    frames = []
    for cam in rig.cameras:
        img = rng.integers(60, 90, (cam.height, cam.width, 3)).astype(np.uint8)
        for _ in range(discs):
            c = (int(rng.integers(0, cam.width)), int(rng.integers(0, cam.height)))
            cv2.circle(img, c, int(rng.integers(3, 10)), (180, 60, 230), -1)
        flat = img.reshape(-1, 3)
        flat[rng.choice(len(flat), len(flat) // 40, replace=False)] = (180, 60, 230)
        frames.append(img)
    return frames


def grid_offsets(rig) -> np.ndarray:
    sizes = [(c.width // SB) * (c.height // SB) for c in rig.cameras]
    return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int32)


def counts_ref(rig, masks) -> np.ndarray:
    out = []
    for cam, m in zip(rig.cameras, masks, strict=True):
        nx, ny = cam.width // SB, cam.height // SB
        out.append(m[: ny * SB, : nx * SB].reshape(ny, SB, nx, SB).sum(axis=(1, 3)).reshape(-1))
    return np.concatenate(out)


def masks_of(drig, mask, rig):
    mk = mask.numpy().astype(np.int64)
    return [
        mk[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]].reshape(cam.height, cam.width)
        for c, cam in enumerate(rig.cameras)
    ]


@pytest.mark.parametrize("mode", ["direct", "integral", "map"])
def test_subblock_counts_match_numpy(device, rng, mode):
    rig = rig3()
    frames = disc_frames(rig, rng)
    drig = DeviceRig(rig, device)
    target = TARGETS[0]
    bgr = upload(frames, device)
    mask, integral, window, _ = mask_and_integral(drig, target, bgr, device)
    off = grid_offsets(rig)
    counts = wp.full(int(off[-1]), -7, dtype=wp.int32, device=device)
    m = {"direct": kscoring.SCORE_DIRECT, "integral": kscoring.SCORE_INTEGRAL, "map": kscoring.SCORE_MAP}[mode]
    sb_max = (max(c.height // SB for c in rig.cameras), max(c.width // SB for c in rig.cameras))
    wp.launch(
        kblobs.subblock_counts_kernel,
        dim=(len(rig.cameras), *sb_max),
        inputs=[drig.cams, target.to_struct(device), bgr, integral, window, int(m), wp.array(off, device=device)],
        outputs=[counts],
        device=device,
    )
    ref = counts_ref(rig, masks_of(drig, mask, rig))
    assert ref.max() == 25 and (ref == 0).any()
    np.testing.assert_array_equal(counts.numpy(), ref)


def peaks_ref(counts, nx, ny, min_pixels):
    """Peak keys (0: not a peak), blob centres and all keys of one camera's (ny, nx) grid, by the module's
    definitions: key = 1024 x (3 x 3 count) + (5 x 5 count)."""
    c = counts.reshape(ny, nx)

    def box(r):
        pad = np.pad(c, r)
        return sum(
            pad[r + dy : r + dy + ny, r + dx : r + dx + nx] for dy in range(-r, r + 1) for dx in range(-r, r + 1)
        )

    s3 = box(1)
    key = s3 * 1024 + box(2)
    kpad = np.pad(key, 1, constant_values=-1)
    score = np.zeros((ny, nx))
    centre = np.zeros((ny, nx, 2))
    for j in range(ny):
        for i in range(nx):
            s = key[j, i]
            if s3[j, i] < min_pixels or s <= 0:
                continue
            peak = True
            for dj in (-1, 0, 1):
                for di in (-1, 0, 1):
                    if di == 0 and dj == 0:
                        continue
                    t = kpad[1 + j + dj, 1 + i + di]
                    earlier = dj < 0 or (dj == 0 and di < 0)
                    if t > s or (earlier and t == s):
                        peak = False
            if peak:
                score[j, i] = s
                ys, xs = np.mgrid[max(j - 1, 0) : min(j + 2, ny), max(i - 1, 0) : min(i + 2, nx)]
                w = c[ys, xs].astype(np.float64)
                centre[j, i] = [(w * (xs * SB + 2)).sum() / w.sum(), (w * (ys * SB + 2)).sum() / w.sum()]
    return score.reshape(-1), centre.reshape(-1, 2), key.reshape(-1)


def launch_peaks(device, rig, counts_np, min_pixels, blobs):
    off = grid_offsets(rig)
    m = len(rig.cameras)
    chunks = max(1, -(-max(int(off[c + 1] - off[c]) for c in range(m)) // CHUNK))
    drig = DeviceRig(rig, device)
    counts = wp.array(counts_np.astype(np.int32), dtype=wp.int32, device=device)
    sums = wp.full(int(off[-1]), -7, dtype=wp.int32, device=device)
    sb_max = (max(c.height // SB for c in rig.cameras), max(c.width // SB for c in rig.cameras))
    off_d = wp.array(off, device=device)
    wp.launch(
        kblobs.neighbourhood_sums_kernel,
        dim=(m, *sb_max),
        inputs=[drig.cams, off_d, counts],
        outputs=[sums],
        device=device,
    )
    peaks = wp.full(int(off[-1]), -7.0, dtype=wp.float32, device=device)
    ps = wp.full((m, chunks, KEEP), -7.0, dtype=wp.float32, device=device)
    pi = wp.full((m, chunks, KEEP), -7, dtype=wp.int32, device=device)
    pu = wp.zeros((m, chunks, KEEP), dtype=wp.vec2, device=device)
    wp.launch_tiled(
        kblobs.blob_peaks_kernel,
        dim=[m, chunks],
        inputs=[drig.cams, off_d, counts, sums, min_pixels],
        outputs=[peaks, ps, pi, pu],
        block_dim=BLOCK,
        device=device,
    )
    bs = wp.full((m, blobs), -7.0, dtype=wp.float32, device=device)
    bu = wp.full((m, blobs), wp.vec2(-7.0, -7.0), dtype=wp.vec2, device=device)
    wp.launch(
        harness.blob_select_kernel, dim=(m, chunks, KEEP), inputs=[ps, pi, pu, blobs], outputs=[bs, bu], device=device
    )
    return peaks.numpy(), (ps.numpy(), pi.numpy(), pu.numpy()), bs.numpy(), bu.numpy(), sums.numpy()


@pytest.mark.parametrize("blobs", [3, 8])
def test_peaks_chunks_and_blob_selection_match_numpy(device, rng, blobs):
    rig = rig3()  # 160x120 and 120x160 grids of 32x24 / 24x32 sub-blocks: 3 chunks of 256 per camera
    off = grid_offsets(rig)
    counts = np.zeros(int(off[-1]), np.int64)
    for c, cam in enumerate(rig.cameras):
        nx, ny = cam.width // SB, cam.height // SB
        g = np.zeros((ny, nx), np.int64)
        sparse = rng.random((ny, nx)) < 0.2
        g[sparse] = rng.integers(1, 8, sparse.sum())
        for _ in range(7):  # compact blobs, some touching, plus a flat plateau (ties)
            j, i = rng.integers(0, ny), rng.integers(0, nx)
            g[max(j - 1, 0) : j + 2, max(i - 1, 0) : i + 2] += rng.integers(5, 26)
        g[2:6, 3:9] = 25
        counts[off[c] : off[c + 1]] = g.reshape(-1)
    min_pixels = 12
    peaks, (ps, pi, pu), bs, bu, sums = launch_peaks(device, rig, counts, min_pixels, blobs)
    for c, cam in enumerate(rig.cameras):
        nx, ny = cam.width // SB, cam.height // SB
        score, centre, nsum = peaks_ref(counts[off[c] : off[c + 1]], nx, ny, min_pixels)
        np.testing.assert_array_equal(sums[off[c] : off[c + 1]], nsum)
        np.testing.assert_array_equal(peaks[off[c] : off[c + 1]], score)
        # per chunk: the best KEEP peaks, score descending then index ascending
        entries = []
        for k in range(ps.shape[1]):
            idx = np.arange(k * CHUNK, min((k + 1) * CHUNK, nx * ny))
            order = sorted((i for i in idx if score[i] > 0), key=lambda i: (-score[i], i))[:KEEP]
            for r in range(KEEP):
                if r < len(order):
                    i = order[r]
                    assert (ps[c, k, r], pi[c, k, r]) == (score[i], i)
                    np.testing.assert_allclose(pu[c, k, r], centre[i], atol=1e-4)
                    entries.append(i)
                else:
                    assert ps[c, k, r] == 0.0
        best = sorted(entries, key=lambda i: (-score[i], i))[:blobs]
        assert len(best) == blobs  # the grid has more peaks than slots
        np.testing.assert_array_equal(bs[c], score[best] // 1024)
        np.testing.assert_allclose(bu[c], centre[best], atol=1e-4)
    # fewer peaks than slots: the rest are emptied
    peaks, _, bs, _, _ = launch_peaks(device, rig, np.where(np.arange(len(counts)) == 40, 20, 0), 12, blobs)
    assert bs[0, 0] == 20 and np.all(bs[0, 1:] == 0) and np.all(bs[1:] == 0)


def test_a_wide_blob_peaks_at_its_centre(device):
    """A disc wider than the 15-pixel neighbourhood: its 3 x 3 counts are full over a plateau, the 5 x 5 count picks
    the sub-block at its centre, and the blob centre lies within half a sub-block of the disc's."""
    rig = rig3()
    off = grid_offsets(rig)
    counts = np.zeros(int(off[-1]), np.int64)
    cam = rig.cameras[0]
    nx, ny = cam.width // SB, cam.height // SB
    yy, xx = np.mgrid[: ny * SB, : nx * SB]
    centre = np.array([71.0, 52.0])  # pixels; radius 13 > 7.5
    disc = ((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2 <= 13.0**2).astype(np.int64)
    counts[: nx * ny] = disc.reshape(ny, SB, nx, SB).sum(axis=(1, 3)).reshape(-1)
    _, _, bs, bu, _ = launch_peaks(device, rig, counts, 8, 4)
    assert bs[0, 0] == 225 and np.all(bs[0, 1:] == 0)
    assert np.linalg.norm(bu[0, 0] - centre) <= 2.5 * np.sqrt(2)


def mode_score_ref(rig, masks, pts):
    total = np.zeros(len(pts))
    amb = np.zeros(len(pts), bool)
    for cam, m in zip(rig.cameras, masks, strict=True):
        cnt, a = window_ref(cam, m, pts)
        total += np.where(cnt < 0, np.log(1 / 5), np.log(np.maximum(cnt, 1) / 25))
        amb |= a
    return total, amb


def test_candidates_match_numpy(device, rng):
    """Blobs at the projections of random points (plus pixel noise) and unrelated ones: the kernel's triangulations,
    reprojection gate, volume test and mode-test scores against cv2 rays and NumPy window counts."""
    rig = rig3()
    m, nb = len(rig.cameras), 6
    drig = DeviceRig(rig, device)
    frames = disc_frames(rig, rng, discs=8)
    target = TARGETS[0]
    bgr = upload(frames, device)
    mask, integral, window, _ = mask_and_integral(drig, target, bgr, device)
    masks = masks_of(drig, mask, rig)
    pts = np.array([0.42, 0.5, 0.06]) + rng.uniform(-0.06, 0.06, (4, 3))
    score = np.zeros((m, nb), np.float32)
    uv = np.zeros((m, nb, 2), np.float32)
    for c, cam in enumerate(rig.cameras):
        p, _ = cam.project(pts)
        uv[c, :4] = p + rng.normal(0, 1.5, p.shape)
        uv[c, 4:] = rng.uniform([0, 0], [cam.width, cam.height], (2, 2))
        score[c, : nb - (c == 1)] = rng.integers(10, 200, nb - (c == 1))  # camera 1's last slot is empty
    pairs = [(a, b) for a in range(m) for b in range(a + 1, m)]
    lo, hi = np.array([-0.5, -0.5, -0.2]), np.array([1.2, 1.2, 0.8])
    gate = 3.0
    n = len(pairs) * nb * nb
    pos = wp.full(n, wp.vec3(7.0, 7.0, 7.0), dtype=wp.vec3, device=device)
    sc = wp.full(n, 7.0, dtype=wp.float32, device=device)
    wp.launch(
        harness.candidates_kernel,
        dim=n,
        inputs=[drig.cams, target.to_struct(device), bgr, integral, window, int(kscoring.SCORE_INTEGRAL)]
        + [wp.array(score, device=device), wp.array(uv, dtype=wp.vec2, device=device)]
        + [wp.array([p[0] for p in pairs], dtype=wp.int32, device=device)]
        + [wp.array([p[1] for p in pairs], dtype=wp.int32, device=device), gate, wp.vec3(*lo), wp.vec3(*hi)],
        outputs=[pos, sc],
        device=device,
    )
    got_p, got_s = pos.numpy(), sc.numpy()
    valid_ref = np.zeros(n, bool)
    borderline = np.zeros(n, bool)
    ref_p = np.zeros((n, 3))
    for p, (a, b) in enumerate(pairs):
        ca, cb = rig.cameras[a], rig.cameras[b]
        for i in range(nb):
            for j in range(nb):
                t = (p * nb + i) * nb + j
                if score[a, i] <= 0 or score[b, j] <= 0:
                    continue
                da, db = ray_dir(ca, uv[a, i]), ray_dir(cb, uv[b, j])
                (s, u), *_ = np.linalg.lstsq(np.stack([da, -db], 1), cb.center - ca.center, rcond=None)
                if s <= 0 or u <= 0:
                    continue
                x = 0.5 * (ca.center + s * da + cb.center + u * db)
                if np.any(x < lo) or np.any(x > hi):
                    continue
                ea = np.linalg.norm(ca.project(x[None])[0][0] - uv[a, i])
                eb = np.linalg.norm(cb.project(x[None])[0][0] - uv[b, j])
                borderline[t] = abs(max(ea, eb) - gate) < 0.05
                if max(ea, eb) <= gate:
                    valid_ref[t], ref_p[t] = True, x
    ok = ~borderline
    assert valid_ref.sum() >= 12 and (~valid_ref).sum() > 50  # the true pairs pass, most others fail a gate
    np.testing.assert_array_equal(got_s[ok] > LOG_ZERO, valid_ref[ok])
    np.testing.assert_array_equal(got_s[ok & ~valid_ref], np.float32(LOG_ZERO))
    v = ok & valid_ref
    np.testing.assert_allclose(got_p[v], ref_p[v], atol=2e-4)
    ref_s, amb = mode_score_ref(rig, masks, got_p[v].astype(np.float64))
    np.testing.assert_allclose(got_s[v][~amb], ref_s[~amb], rtol=1e-5, atol=1e-5)


def keep_rank_ref(pos, score, radius, k):
    n = len(score)
    better = lambda q, t: score[q] > score[t] or (score[q] == score[t] and q < t)  # noqa: E731
    valid = score > LOG_ZERO
    keep = np.array(
        [
            valid[t]
            and not any(valid[q] and better(q, t) and np.sum((pos[q] - pos[t]) ** 2) < radius**2 for q in range(n))
            for t in range(n)
        ]
    )
    order = sorted(np.flatnonzero(keep), key=lambda t: (-score[t], t))[:k]
    return keep, order


@pytest.mark.parametrize("k", [4, 256])
def test_suppression_and_ranking_match_numpy(device, rng, k):
    n = 300
    pos = rng.uniform(0, 1, (n, 3)).astype(np.float32)
    pos[50:60] = pos[50] + rng.normal(0, 0.01, (10, 3))  # a cluster: one survivor
    score = rng.normal(-4, 2, n).astype(np.float32)
    score[rng.random(n) < 0.4] = LOG_ZERO
    score[100:110] = -2.5  # ties, ranked by index
    score[50:60] = 2.0  # above every other score
    radius = 0.08
    pos_d = wp.array(pos, dtype=wp.vec3, device=device)
    sc_d = wp.array(score, dtype=wp.float32, device=device)
    keep = wp.full(n, 7, dtype=wp.int32, device=device)
    wp.launch(harness.candidate_keep_kernel, dim=n, inputs=[pos_d, sc_d, radius], outputs=[keep], device=device)
    det_pos = wp.full(k, wp.vec3(7.0, 7.0, 7.0), dtype=wp.vec3, device=device)
    det_sc = wp.full(k, 7.0, dtype=wp.float32, device=device)
    wp.launch(
        harness.candidate_rank_kernel,
        dim=max(n, k),
        inputs=[pos_d, sc_d, keep],
        outputs=[det_pos, det_sc],
        device=device,
    )
    keep_ref, order = keep_rank_ref(pos.astype(np.float64), score, radius, k)
    np.testing.assert_array_equal(keep.numpy().astype(bool), keep_ref)
    assert keep_ref[50:60].sum() == 1
    got = det_sc.numpy()
    np.testing.assert_array_equal(got[: len(order)], score[order])
    np.testing.assert_array_equal(det_pos.numpy()[: len(order)], pos[order])
    np.testing.assert_array_equal(got[len(order) :], np.float32(LOG_ZERO))
    assert (len(order) == k) == (k == 4)  # 256 slots: more than the survivors, the rest emptied


def test_detect_tail_kernel_equals_the_staged_launches(device, rng):
    """The one-block tail (blob selection, candidates, suppression, ranking, mode test) gives exactly what the five
    separate launches give, on a frame of discs seen by three cameras (some candidates, some suppressed)."""
    from statistics import NormalDist

    from wptrack.kernels.core import reduce as kreduce

    rig = rig3()
    m = len(rig.cameras)
    drig = DeviceRig(rig, device)
    ball = np.array([0.42, 0.5, 0.06])
    frames = disc_frames(rig, rng, discs=4)
    import cv2

    for cam, img in zip(rig.cameras, frames, strict=True):  # the ball in every camera: valid candidates
        uv, depth = cam.project(ball[None])
        cv2.circle(img, (int(round(uv[0, 0])), int(round(uv[0, 1]))), 8, (180, 60, 230), -1)
    target = TARGETS[0]
    bgr = upload(frames, device)
    mask, integral, window, _ = mask_and_integral(drig, target, bgr, device)
    off = grid_offsets(rig)
    sb_max = (max(c.height // SB for c in rig.cameras), max(c.width // SB for c in rig.cameras))
    chunks = max(1, -(-max(int(off[c + 1] - off[c]) for c in range(m)) // CHUNK))
    tgt = target.to_struct(device)
    obs = [drig.cams, tgt, bgr, integral, window, int(kscoring.SCORE_INTEGRAL)]
    off_d = wp.array(off, device=device)
    counts = wp.zeros(int(off[-1]), dtype=wp.int32, device=device)
    keys = wp.zeros(int(off[-1]), dtype=wp.int32, device=device)
    wp.launch(kblobs.subblock_counts_kernel, dim=(m, *sb_max), inputs=[*obs, off_d], outputs=[counts], device=device)
    wp.launch(
        kblobs.neighbourhood_sums_kernel,
        dim=(m, *sb_max),
        inputs=[drig.cams, off_d, counts],
        outputs=[keys],
        device=device,
    )
    peaks = wp.zeros(int(off[-1]), dtype=wp.float32, device=device)
    part = [wp.zeros((m, chunks, KEEP), dtype=dt, device=device) for dt in (wp.float32, wp.int32, wp.vec2)]
    wp.launch_tiled(
        kblobs.blob_peaks_kernel,
        dim=[m, chunks],
        inputs=[drig.cams, off_d, counts, keys, 8],
        outputs=[peaks, *part],
        block_dim=BLOCK,
        device=device,
    )
    nb, k = 6, 5
    pairs = [(a, b) for a in range(m) for b in range(a + 1, m)]
    pa = wp.array([p[0] for p in pairs], dtype=wp.int32, device=device)
    pb = wp.array([p[1] for p in pairs], dtype=wp.int32, device=device)
    n = len(pairs) * nb * nb
    lo, hi = wp.vec3(-1.0, -1.0, -0.5), wp.vec3(2.0, 2.0, 1.5)
    est = np.zeros(int(kreduce.EST_SIZE))
    est[kreduce.EST_MEAN : kreduce.EST_MEAN + 3] = ball + 0.3
    est[kreduce.EST_MAP : kreduce.EST_MAP + 3] = ball + 0.3
    est_d = wp.array(est, dtype=wp.float64, device=device)
    frame = wp.array([4], dtype=wp.int32, device=device)
    uni = wp.array([-1], dtype=wp.int32, device=device)
    thr = wp.vec2(NormalDist().inv_cdf(0.5), float(kproposal.NO_JUMP))

    def buffers():
        return {
            "blob_score": wp.full((m, nb), 7.0, dtype=wp.float32, device=device),
            "blob_uv": wp.full((m, nb), wp.vec2(7.0, 7.0), dtype=wp.vec2, device=device),
            "cand_pos": wp.full(n, wp.vec3(7.0, 7.0, 7.0), dtype=wp.vec3, device=device),
            "cand_score": wp.full(n, 7.0, dtype=wp.float32, device=device),
            "keep": wp.full(n, 7, dtype=wp.int32, device=device),
            "det_pos": wp.full(k, wp.vec3(7.0, 7.0, 7.0), dtype=wp.vec3, device=device),
            "det_score": wp.full(k, 7.0, dtype=wp.float32, device=device),
            "det_cum": wp.full(k, 7.0, dtype=wp.float32, device=device),
            "det_count": wp.full(1, 7, dtype=wp.int32, device=device),
            "mix": wp.zeros(int(kproposal.MIX_SIZE), dtype=wp.float32, device=device),
        }

    a = buffers()
    wp.launch(
        harness.blob_select_kernel, dim=(m, chunks, KEEP), inputs=[*part, nb], outputs=[a["blob_score"], a["blob_uv"]]
    )
    wp.launch(
        harness.candidates_kernel,
        dim=n,
        inputs=[*obs, a["blob_score"], a["blob_uv"], pa, pb, 8.0, lo, hi],
        outputs=[a["cand_pos"], a["cand_score"]],
        device=device,
    )
    wp.launch(
        harness.candidate_keep_kernel,
        dim=n,
        inputs=[a["cand_pos"], a["cand_score"], 0.04],
        outputs=[a["keep"]],
        device=device,
    )
    wp.launch(
        harness.candidate_rank_kernel,
        dim=max(n, k),
        inputs=[a["cand_pos"], a["cand_score"], a["keep"]],
        outputs=[a["det_pos"], a["det_score"]],
        device=device,
    )
    wp.launch(
        kproposal.jump_decision_kernel,
        dim=1,
        inputs=[*obs, a["det_pos"], a["det_score"], est_d, frame, uni, thr, 2.0, 0.0, 0.06],
        outputs=[a["det_cum"], a["det_count"], a["mix"]],
        device=device,
    )
    b = buffers()
    wp.launch_tiled(
        kblobs.detect_tail_kernel,
        dim=[1],
        inputs=[*obs, *part, pa, pb, len(pairs), 8.0, lo, hi, 0.04, est_d, frame, uni, thr, 2.0, 0.0, 0.06],
        outputs=[b[key] for key in ("blob_score", "blob_uv", "cand_pos", "cand_score", "keep", "det_pos")]
        + [b[key] for key in ("det_score", "det_cum", "det_count", "mix")],
        block_dim=BLOCK,
        device=device,
    )
    for key in a:
        np.testing.assert_array_equal(a[key].numpy(), b[key].numpy(), err_msg=key)
    # the frame exercised the stages: candidates on the ball, some suppressed, a jump away from the far cloud
    assert (a["cand_score"].numpy() > LOG_ZERO).sum() > a["keep"].numpy().sum() >= 1
    assert np.linalg.norm(a["det_pos"].numpy()[0] - ball) < 0.03 and a["mix"].numpy()[kproposal.MIX_JUMP] == 1.0
