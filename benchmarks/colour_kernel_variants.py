"""Where the time of the colour predict+score kernel goes at large N (profiling script of issue 13, not shipped).

Variants of ``kernels.colour.scoring.colour_predict_score_kernel`` (map scoring) compiled with ``wp.static`` flags - the
cameras from the struct array or by value (the ``Cams4`` argument), 10 or 7 Philox rounds, with or without the
scoring, the weighted moments, the gather through the ancestors - are launched on the state of a real ``ColorTracker``
(the benchmark's 4-camera scene after 5 frames) and timed with CUDA events (median of 20 launches), next to a device
copy of 64 bytes per particle for the memory bandwidth. The kernels live here, not in ``kernels/``, because they are
measurement scaffolding; the shipped kernel is ``kernels.colour.scoring.colour_predict_score_map_kernel``.

Usage: ``python benchmarks/colour_kernel_variants.py 1e8 [cuda:0]`` (BENCHMARKS.md, issue 13).
"""

import sys
import time

import numpy as np
import warp as wp

from wptrack.kernels.core import random as krandom
from wptrack.kernels.core.camera import Camera, pixel_of, project
from wptrack.kernels.core.reduce import finite_logw, moments_push, moments_store, moments_zero

N = int(float(sys.argv[1])) if len(sys.argv) > 1 else 10**8
DEV = sys.argv[2] if len(sys.argv) > 2 else "cuda:0"
REPS = 20


@wp.struct
class Cams4:
    c0: Camera
    c1: Camera
    c2: Camera
    c3: Camera


@wp.func
def philox_r(c0: wp.uint32, c1: wp.uint32, c2: wp.uint32, k0: wp.uint32, k1: wp.uint32, rounds: int):
    x0 = c0
    x1 = c1
    x2 = c2
    x3 = wp.uint32(0)
    key0 = k0
    key1 = k1
    for _r in range(rounds):
        p0 = krandom.PHILOX_M0 * wp.uint64(x0)
        p1 = krandom.PHILOX_M1 * wp.uint64(x2)
        hi0 = wp.uint32(p0 >> krandom.SHIFT32)
        lo0 = wp.uint32(p0 & krandom.MASK32)
        hi1 = wp.uint32(p1 >> krandom.SHIFT32)
        lo1 = wp.uint32(p1 & krandom.MASK32)
        y0 = hi1 ^ x1 ^ key0
        y1 = lo1
        y2 = hi0 ^ x3 ^ key1
        y3 = lo0
        x0 = y0
        x1 = y1
        x2 = y2
        x3 = y3
        key0 = key0 + krandom.PHILOX_W0
        key1 = key1 + krandom.PHILOX_W1
    return wp.vec4ui(x0, x1, x2, x3)


@wp.func
def cam_loglik(cam: Camera, window: wp.array(dtype=wp.uint8), x: wp.vec3):
    uvz = project(cam, x)
    m = -1
    if uvz[2] > 0.0:
        px = pixel_of(uvz[0])
        py = pixel_of(uvz[1])
        if px >= 0 and py >= 0 and px < cam.width and py < cam.height:
            m = int(window[cam.pixel_offset + py * cam.width + px])
    return wp.log(float(wp.max(m, 1))) - 3.2188758248682006


def make(rounds: int, const_cams: bool, score: bool, moments: bool, gather: bool):
    @wp.kernel(enable_backward=False, module="unique", module_options={"fast_math": True})
    def k(
        cams: wp.array(dtype=Camera),
        c4: Cams4,
        window: wp.array(dtype=wp.uint8),
        particles: wp.array(dtype=wp.vec3),
        ancestors: wp.array(dtype=wp.int32),
        logw_prev: wp.array(dtype=wp.float32),
        resampled: wp.array(dtype=wp.int32),
        sigma: wp.array(dtype=wp.float32),
        seed: wp.vec2ui,
        frame: wp.array(dtype=wp.int32),
        n: int,
        chunk: int,
        particles_out: wp.array(dtype=wp.vec3),
        logw_out: wp.array(dtype=wp.float32),
        part_max: wp.array(dtype=wp.float32),
        part_arg: wp.array(dtype=wp.int32),
        part: wp.array2d(dtype=wp.float64),
    ):
        b, lane = wp.tid()
        start = b * chunk
        stop = wp.min(start + chunk, n)
        s = sigma[0]
        f = frame[0]
        keep = resampled[0] == 0
        best, arg, sw, sw2, sx, sxx = moments_zero()
        for i in range(start + lane, stop, wp.block_dim()):
            xp = wp.vec3(0.0)
            if wp.static(gather):
                xp = particles[ancestors[i]]
            else:
                xp = particles[i]
            w = philox_r(wp.uint32(i), wp.uint32(f), wp.uint32(1), seed[0], seed[1], wp.static(rounds))
            u0 = krandom.word_to_unit(w[0])
            u1 = krandom.word_to_unit(w[1])
            u2 = krandom.word_to_unit(w[2])
            u3 = krandom.word_to_unit(w[3])
            r0 = wp.sqrt(-2.0 * wp.log(u0))
            r1 = wp.sqrt(-2.0 * wp.log(u2))
            a0 = 6.283185307179586 * u1
            a1 = 6.283185307179586 * u3
            x = xp + s * wp.vec3(r0 * wp.cos(a0), r0 * wp.sin(a0), r1 * wp.cos(a1))
            particles_out[i] = x
            lw = float(0.0)  # noqa: UP018 (dynamic variable: the array-cameras variant adds to it in a loop)
            if wp.static(score):
                if wp.static(const_cams):
                    lw += cam_loglik(c4.c0, window, x)
                    lw += cam_loglik(c4.c1, window, x)
                    lw += cam_loglik(c4.c2, window, x)
                    lw += cam_loglik(c4.c3, window, x)
                else:
                    for c in range(cams.shape[0]):
                        lw += cam_loglik(cams[c], window, x)
            if keep:
                lw += logw_prev[i]
            lw = finite_logw(lw)
            logw_out[i] = lw
            if wp.static(moments):
                best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, lw, i, x)
            else:
                if lw > best:
                    best = lw
                    arg = i
        moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)

    return k


def tracker_state(n: int, device: str):
    """A 4-camera ``ColorTracker`` of ``n`` particles on ``device`` after 5 frames of the benchmark scene, with the
    predict+score kernels' common inputs (after the observation arguments) and outputs for its next frame.

    Returns:
        ``(tracker, rig, common_in, outs)``.
    """
    from wptrack.bench.colour import HUE, INTENSITY, SAT, bench_frames, bench_rig
    from wptrack.trackers.colour.tracker import ColorTracker, HSITarget

    wp.config.quiet = True
    rig = bench_rig(4)
    images, balls = bench_frames(rig, 6, 0)
    tr = ColorTracker(
        rig,
        HSITarget(hue=HUE, sat=SAT, intensity=INTENSITY),
        particles=n,
        sigma=0.01,
        init=tuple(balls[0]),
        device=device,
        seed=0,
    )
    for k in range(5):
        tr.step(images[k])
    wp.synchronize()
    src, dst = tr.parity, 1 - tr.parity
    common_in = [tr.x[src], tr.ancestors, tr.logw[src], tr.resampled, tr.sigma, tr.seed, tr.frame, tr.n, tr.chunk]
    outs = [tr.x[dst], tr.logw[dst], tr.part_max, tr.part_arg, tr.part]
    return tr, rig, common_in, outs


def main():
    from wptrack.cameras.structs import camera_struct
    from wptrack.core.filter import BLOCK
    from wptrack.kernels.colour import scoring as kscoring

    tr, rig, common_in, outs = tracker_state(N, DEV)
    c4 = Cams4()
    structs = [
        camera_struct(c, int(tr.drig.pixel_offsets[j]), int(tr.drig.integral_offsets[j]))
        for j, c in enumerate(rig.cameras)
    ]
    c4.c0, c4.c1, c4.c2, c4.c3 = structs
    is_cuda = wp.get_device(DEV).is_cuda

    def timeit(fn):
        fn()
        wp.synchronize()
        ts = []
        for _ in range(REPS):
            if not is_cuda:
                t0 = time.perf_counter()
                fn()
                wp.synchronize()
                ts.append(1e3 * (time.perf_counter() - t0))
                continue
            e0 = wp.Event(enable_timing=True)
            e1 = wp.Event(enable_timing=True)
            wp.record_event(e0)
            fn()
            wp.record_event(e1)
            wp.synchronize()
            ts.append(wp.get_event_elapsed_time(e0, e1))
        return float(np.median(ts))

    def prod():
        wp.launch_tiled(
            kscoring.colour_predict_score_kernel,
            dim=[tr.blocks],
            inputs=[tr.drig.cams, tr._target, tr.bgr, tr._integral, tr._window, tr._mode_id, *common_in],
            outputs=outs,
            block_dim=BLOCK,
            device=tr.device,
        )

    print(f"N={N} blocks={tr.blocks} chunk={tr.chunk} BLOCK={BLOCK} mode={tr.score_mode}", flush=True)
    print(f"production kernel: {timeit(prod):.3f} ms", flush=True)
    variants = [
        ("full r10 arraycams", dict(rounds=10, const_cams=False, score=True, moments=True, gather=True)),
        ("full r10 constcams", dict(rounds=10, const_cams=True, score=True, moments=True, gather=True)),
        ("full r7 constcams", dict(rounds=7, const_cams=True, score=True, moments=True, gather=True)),
        ("noscore r10", dict(rounds=10, const_cams=True, score=False, moments=True, gather=True)),
        ("noscore nomoments r10", dict(rounds=10, const_cams=True, score=False, moments=False, gather=True)),
        ("noscore nomoments r0", dict(rounds=0, const_cams=True, score=False, moments=False, gather=True)),
        ("noscore nomoments r0 nogather", dict(rounds=0, const_cams=True, score=False, moments=False, gather=False)),
        ("score nomoments r10 constcams", dict(rounds=10, const_cams=True, score=True, moments=False, gather=True)),
    ]
    for name, flags in variants:
        k = make(**flags)
        t0 = time.perf_counter()
        wp.load_module(k.module, device=DEV)

        def run(k=k):
            wp.launch_tiled(
                k,
                dim=[tr.blocks],
                inputs=[tr.drig.cams, c4, tr._window, *common_in],
                outputs=outs,
                block_dim=BLOCK,
                device=tr.device,
            )

        t = timeit(run)
        print(f"{name:40s} {t:.3f} ms   (compile {time.perf_counter() - t0:.1f} s)", flush=True)
    a = wp.empty(N * 8, dtype=wp.float32, device=DEV)
    bb = wp.empty(N * 8, dtype=wp.float32, device=DEV)
    t = timeit(lambda: wp.copy(bb, a))
    print(f"copy of 32 B/particle (read+write 64 B): {t:.3f} ms -> {2 * 32 * N / t / 1e6:.0f} GB/s", flush=True)


if __name__ == "__main__":
    main()
