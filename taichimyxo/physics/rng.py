"""Counter-based random numbers: a value is a pure function of (seed, stream, index, counter), so a run is the same
on 1 or 2 threads and after a resume. SplitMix64 finaliser in numpy; the kernels use `hash_u32` below."""

import numpy as np
import taichi as ti

_M = np.uint64(0xFFFFFFFFFFFFFFFF)

# streams
STREAM_PLACE = 1
STREAM_POLARITY = 2
STREAM_REVERSAL = 3
STREAM_TILT = 4


def _mix64(z):
    z = np.asarray(z, dtype=np.uint64)
    with np.errstate(over="ignore"):
        z = (z + np.uint64(0x9E3779B97F4A7C15)) & _M
        z = ((z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)) & _M
        z = ((z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)) & _M
        return z ^ (z >> np.uint64(31))


def uniform(seed: int, stream: int, index, counter=0) -> np.ndarray:
    """Uniform [0, 1) doubles, one per (index, counter) element (broadcast)."""
    idx = np.asarray(index, dtype=np.uint64)
    cnt = np.asarray(counter, dtype=np.uint64)
    with np.errstate(over="ignore"):
        z = _mix64(np.uint64(seed) * np.uint64(0x100000001B3) + np.uint64(stream))
        z = _mix64(z ^ (idx * np.uint64(0xD6E8FEB86659FD93)))
        z = _mix64(z ^ (cnt * np.uint64(0xA0761D6478BD642F)))
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


class Stream:
    """Sequential draws from one (seed, stream): call .next(n) repeatedly; reproducible, thread-independent."""

    def __init__(self, seed: int, stream: int):
        self.seed, self.stream, self.counter = seed, stream, 0

    def next(self, n: int) -> np.ndarray:
        out = uniform(self.seed, self.stream, np.arange(self.counter, self.counter + n))
        self.counter += n
        return out


@ti.func
def hash_u32(x):
    """lowbias32 (Chris Wellons): a well-mixed 32-bit integer hash."""
    x = ti.cast(x, ti.u32)
    x ^= x >> 16
    x *= ti.u32(0x7FEB352D)
    x ^= x >> 15
    x *= ti.u32(0x846CA68B)
    x ^= x >> 16
    return x


@ti.func
def uniform_ti(seed, stream, index, counter):
    """Uniform in (0, 1) from a hash of its counters (no state)."""
    h = hash_u32(seed * ti.u32(0x9E3779B9) ^ hash_u32(stream + ti.u32(0x632BE5AB)))
    h = hash_u32(h ^ hash_u32(index + ti.u32(0x85EBCA6B)))
    h = hash_u32(h ^ hash_u32(counter + ti.u32(0xC2B2AE35)))
    return (ti.cast(h, ti.f64) + 0.5) / 4294967296.0


def hash_u32_np(x):
    x = np.asarray(x, dtype=np.uint64) & np.uint64(0xFFFFFFFF)
    x ^= x >> np.uint64(16)
    x = (x * np.uint64(0x7FEB352D)) & np.uint64(0xFFFFFFFF)
    x ^= x >> np.uint64(15)
    x = (x * np.uint64(0x846CA68B)) & np.uint64(0xFFFFFFFF)
    x ^= x >> np.uint64(16)
    return x


def uniform_ti_np(seed, stream, index, counter):
    """Numpy twin of `uniform_ti` (for tests of reversal statistics)."""
    m = np.uint64(0xFFFFFFFF)
    def u(v):
        return np.asarray(v, dtype=np.uint64) & m
    h = hash_u32_np((u(seed) * np.uint64(0x9E3779B9) & m) ^ hash_u32_np(u(stream) + np.uint64(0x632BE5AB)))
    h = hash_u32_np(h ^ hash_u32_np(u(index) + np.uint64(0x85EBCA6B)))
    h = hash_u32_np(h ^ hash_u32_np(u(counter) + np.uint64(0xC2B2AE35)))
    return (h.astype(np.float64) + 0.5) / 4294967296.0
