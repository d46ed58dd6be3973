"""Counter-based random numbers: Philox4x32-10 (Salmon et al., SC'11, "Parallel random numbers: as easy
as 1, 2, 3").

A draw is a pure function of ``(key, counter)``: the key is the user's 64-bit seed, the counter is
``(index, frame, stream, 0)`` where ``index`` is the particle (or output slot), ``frame`` the filter
iteration and ``stream`` names the purpose (motion noise, resampling, initialisation, ...). Unlike
``wp.rand_init`` (one 32-bit state per thread, so neighbouring seeds overlap after ~2^16 draws and streams
collide at 1e8 particles), distinct counters never share a stream: 2^32 particles x 2^32 frames x 2^32
streams, each giving 4 independent 32-bit words. The same values come out on every device, which makes
CPU/CUDA runs comparable and graph replay trivial (the frame number lives in a device array).
"""

import warp as wp

PHILOX_M0 = wp.constant(wp.uint64(0xD2511F53))
PHILOX_M1 = wp.constant(wp.uint64(0xCD9E8D57))
PHILOX_W0 = wp.constant(wp.uint32(0x9E3779B9))
PHILOX_W1 = wp.constant(wp.uint32(0xBB67AE85))
MASK32 = wp.constant(wp.uint64(0xFFFFFFFF))
SHIFT32 = wp.constant(wp.uint64(32))

# Stream identifiers (third counter word): one per purpose so that draws never overlap.
STREAM_MOTION = wp.constant(1)
STREAM_RESAMPLE = wp.constant(2)
STREAM_INIT = wp.constant(3)
STREAM_RESIDUAL = wp.constant(4)
STREAM_SYNTH = wp.constant(5)
STREAM_TEMPLATE_EVENT = wp.constant(6)  # S3: object deletion
STREAM_TEMPLATE_ADD = wp.constant(7)  # S3: object addition (one draw per particle)
STREAM_TEMPLATE_NOISE = wp.constant(8)  # S3: diffusion noise, first 4 normals per object
STREAM_TEMPLATE_NOISE2 = wp.constant(9)  # S3: diffusion noise, next 4 normals per object
STREAM_TEMPLATE_INIT = wp.constant(10)  # S3: prior draws of an added object (dims, heading)
STREAM_TEMPLATE_INIT2 = wp.constant(11)  # S3: prior draws of an added object (velocity)
STREAM_PEOPLE_VELOCITY = wp.constant(12)  # S2: velocity noise (position noise uses STREAM_MOTION)
STREAM_PEOPLE_JUMP = wp.constant(13)  # S2: the jumps along a camera's ray (kernels.people.filter.ray_jump)


@wp.func
def philox4x32(c0: wp.uint32, c1: wp.uint32, c2: wp.uint32, c3: wp.uint32, k0: wp.uint32, k1: wp.uint32):
    """Philox4x32 with 10 rounds. Returns the 4 output words as a ``wp.vec4ui``."""
    x0 = c0
    x1 = c1
    x2 = c2
    x3 = c3
    key0 = k0
    key1 = k1
    for _r in range(10):
        p0 = PHILOX_M0 * wp.uint64(x0)
        p1 = PHILOX_M1 * wp.uint64(x2)
        hi0 = wp.uint32(p0 >> SHIFT32)
        lo0 = wp.uint32(p0 & MASK32)
        hi1 = wp.uint32(p1 >> SHIFT32)
        lo1 = wp.uint32(p1 & MASK32)
        y0 = hi1 ^ x1 ^ key0
        y1 = lo1
        y2 = hi0 ^ x3 ^ key1
        y3 = lo0
        x0 = y0
        x1 = y1
        x2 = y2
        x3 = y3
        key0 = key0 + PHILOX_W0
        key1 = key1 + PHILOX_W1
    return wp.vec4ui(x0, x1, x2, x3)


@wp.func
def random_words(seed: wp.vec2ui, index: int, frame: int, stream: int):
    """Four independent uniformly distributed 32-bit words for ``(seed, index, frame, stream)``."""
    return philox4x32(wp.uint32(index), wp.uint32(frame), wp.uint32(stream), wp.uint32(0), seed[0], seed[1])


@wp.func
def random_words_at(seed: wp.vec2ui, index: int, frame: int, stream: int, word: int):
    """:func:`random_words` with ``word`` as the counter's fourth word (``word`` 0: :func:`random_words` exactly):
    more independent streams per ``(index, frame, stream)``."""
    return philox4x32(wp.uint32(index), wp.uint32(frame), wp.uint32(stream), wp.uint32(word), seed[0], seed[1])


@wp.func
def word_to_unit(w: wp.uint32):
    """Map a 32-bit word to a float in the open interval (0, 1) (24-bit resolution, never 0 or 1)."""
    return (wp.float32(w >> wp.uint32(8)) + 0.5) * (1.0 / 16777216.0)


@wp.func
def word_to_unit64(w: wp.uint32):
    """Map a 32-bit word to a float64 in the open interval (0, 1) (32-bit resolution)."""
    return (wp.float64(w) + wp.float64(0.5)) * wp.float64(2.3283064365386963e-10)


@wp.func
def uniform4(seed: wp.vec2ui, index: int, frame: int, stream: int):
    """Four independent U(0, 1) float32 values."""
    w = random_words(seed, index, frame, stream)
    return wp.vec4(word_to_unit(w[0]), word_to_unit(w[1]), word_to_unit(w[2]), word_to_unit(w[3]))


@wp.func
def uniform4_at(seed: wp.vec2ui, index: int, frame: int, stream: int, word: int):
    """:func:`uniform4` of the stream with fourth counter word ``word`` (:func:`random_words_at`)."""
    w = random_words_at(seed, index, frame, stream, word)
    return wp.vec4(word_to_unit(w[0]), word_to_unit(w[1]), word_to_unit(w[2]), word_to_unit(w[3]))


@wp.func
def normal4_at(seed: wp.vec2ui, index: int, frame: int, stream: int, word: int):
    """:func:`normal4` of the stream with fourth counter word ``word`` (:func:`random_words_at`)."""
    u = uniform4_at(seed, index, frame, stream, word)
    r0 = wp.sqrt(-2.0 * wp.log(u[0]))
    r1 = wp.sqrt(-2.0 * wp.log(u[2]))
    a0 = 6.283185307179586 * u[1]
    a1 = 6.283185307179586 * u[3]
    return wp.vec4(r0 * wp.cos(a0), r0 * wp.sin(a0), r1 * wp.cos(a1), r1 * wp.sin(a1))


@wp.func
def normal4(seed: wp.vec2ui, index: int, frame: int, stream: int):
    """Four independent N(0, 1) values by two Box-Muller transforms of one Philox block."""
    u = uniform4(seed, index, frame, stream)
    r0 = wp.sqrt(-2.0 * wp.log(u[0]))
    r1 = wp.sqrt(-2.0 * wp.log(u[2]))
    a0 = 6.283185307179586 * u[1]
    a1 = 6.283185307179586 * u[3]
    return wp.vec4(r0 * wp.cos(a0), r0 * wp.sin(a0), r1 * wp.cos(a1), r1 * wp.sin(a1))


@wp.kernel
def philox_kernel(
    seed: wp.vec2ui,
    frame: int,
    stream: int,
    words: wp.array2d(dtype=wp.uint32),
):
    """Raw Philox words for indices ``0..N-1`` (tests and diagnostics). ``words``: (N, 4)."""
    i = wp.tid()
    w = random_words(seed, i, frame, stream)
    for k in range(4):
        words[i, k] = w[k]
