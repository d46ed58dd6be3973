"""Why the round-three camera-set kernel was no faster than the general one (issue 13, BENCHMARKS.md round four).

Times the predict+score kernel at large N on a 4-camera ``ColorTracker``'s state: the general kernel, the shipped
camera-set kernel (count fixed at compile time), the camera count read at run time (``inline``: round three's
kernel), and that one under launch bounds / register caps; then the 4 cameras unrolled in the kernel body
(``inline4``, ``hoist``). Measurement scaffolding, not shipped: ``python benchmarks/colour_map_kernel_variants.py
1e8`` (a CUDA device; on the CPU backend the launch-bound variants do not run every lane, so their log-weights
differ there).
"""

import sys
import time

import numpy as np
import warp as wp

from wptrack.kernels.colour.scoring import map_log_likelihood
from wptrack.kernels.colour.walk import gaussian_walk
from wptrack.kernels.core.camera import CameraSet
from wptrack.kernels.core.reduce import finite_logw, moments_push, moments_store, moments_zero

N = int(float(sys.argv[1]))
DEV = sys.argv[2] if len(sys.argv) > 2 else "cuda:0"
REPS = 20


def make(style, lb=None, maxreg=None):
    @wp.kernel(
        enable_backward=False,
        module="unique",
        module_options={"fast_math": True},
        launch_bounds=lb,
        cuda_max_registers=maxreg,
    )
    def k(
        cams: CameraSet,
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
        nc = cams.count
        if wp.static(style == "hoist"):
            c0 = cams.c0
            c1 = cams.c1
            c2 = cams.c2
            c3 = cams.c3
        best, arg, sw, sw2, sx, sxx = moments_zero()
        for i in range(start + lane, stop, wp.block_dim()):
            x = gaussian_walk(particles[ancestors[i]], s, seed, i, f)
            particles_out[i] = x
            lw = 0.0
            if wp.static(style == "inline"):
                lw = map_log_likelihood(cams.c0, window, x)
                if nc > 1:
                    lw += map_log_likelihood(cams.c1, window, x)
                if nc > 2:
                    lw += map_log_likelihood(cams.c2, window, x)
                if nc > 3:
                    lw += map_log_likelihood(cams.c3, window, x)
                if nc > 4:
                    lw += map_log_likelihood(cams.c4, window, x)
                if nc > 5:
                    lw += map_log_likelihood(cams.c5, window, x)
                if nc > 6:
                    lw += map_log_likelihood(cams.c6, window, x)
                if nc > 7:
                    lw += map_log_likelihood(cams.c7, window, x)
            elif wp.static(style == "inline4"):
                lw = map_log_likelihood(cams.c0, window, x)
                lw += map_log_likelihood(cams.c1, window, x)
                lw += map_log_likelihood(cams.c2, window, x)
                lw += map_log_likelihood(cams.c3, window, x)
            elif wp.static(style == "hoist"):
                lw = map_log_likelihood(c0, window, x)
                lw += map_log_likelihood(c1, window, x)
                lw += map_log_likelihood(c2, window, x)
                lw += map_log_likelihood(c3, window, x)
            if keep:
                lw += logw_prev[i]
            lw = finite_logw(lw)
            logw_out[i] = lw
            best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, lw, i, x)
        moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)

    return k


def main():
    from colour_kernel_variants import tracker_state  # the same tracker state (run from benchmarks/)

    from wptrack.core.filter import BLOCK
    from wptrack.kernels.colour import scoring as kscoring

    tr, _rig, common_in, outs = tracker_state(N, DEV)
    dst = 1 - tr.parity

    def timeit(fn):
        fn()
        wp.synchronize()
        ts = []
        for _ in range(REPS):
            t0 = time.perf_counter()
            fn()
            wp.synchronize()
            ts.append(1e3 * (time.perf_counter() - t0))
        return float(np.median(ts)), float(np.min(ts))

    def launch(kern, first):
        wp.launch_tiled(
            kern, dim=[tr.blocks], inputs=[*first, *common_in], outputs=outs, block_dim=BLOCK, device=tr.device
        )

    ref = None
    print(f"N={N} blocks={tr.blocks} chunk={tr.chunk} BLOCK={BLOCK}")
    gen = [tr.drig.cams, tr._target, tr.bgr, tr._integral, tr._window, tr._mode_id]
    for _rep in range(2):
        print("general  ", timeit(lambda: launch(kscoring.colour_predict_score_kernel, gen)))
        shipped = kscoring.colour_predict_score_map_kernel(4)
        print("shipped  ", timeit(lambda k=shipped: launch(k, [tr.drig.cam_set, tr._window])))
        for style, lb, mr in [
            ("inline", None, None),
            ("inline", (256, 3), None),
            ("inline", (256, 4), None),
            ("inline", None, 80),
            ("inline", None, 64),
            ("inline4", None, None),
            ("hoist", None, None),
            ("hoist", (256, 4), None),
        ]:
            kk = make(style, lb, mr)
            print(f"{style:9s} {lb} {mr}", timeit(lambda k=kk: launch(k, [tr.drig.cam_set, tr._window])))
            lw = tr.logw[dst].numpy().copy()
            if ref is None:
                ref = lw
            print("   same log-weights as the first variant:", bool(np.array_equal(lw, ref)))


if __name__ == "__main__":
    main()
