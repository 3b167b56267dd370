"""The contact pair loop written once more in plain C, to measure what a compiled kernel outside Taichi would gain
before the state is moved to memory both can share (docs/performance.md, "The pair loop in C").

    python benchmarks/pair_loop_c.py --state "S3 6 h" --threads 1 --reps 50 [--out DIR]
    python benchmarks/pair_loop_c.py --state "S3 6 h" --threads 2 --reps 50 --out DIR [--fast-math]
    python benchmarks/pair_loop_c.py --state "S3 6 h" --threads 2 --block-dims 8,512,8192   # Taichi's chunk size

The C loop is the same algorithm as taichimyxo/physics/terms/contacts.py `pair_pass` step for step: each listed pair
(s, t > s) once, positions relative to s's first particle by the one minimum-image formula (f64 difference, then
f32), the segments' closest-points test, then both sides' samples with the local nearest-segment rule, into s's row
of pair_f. It reads the Taichi fields' values copied out once (positions, lists), so what it measures is the loop,
not the copies. Both loops run in this process on the same state, alternating, --reps times each (best and median
wall time, and cores_busy: the process's CPU time over the wall time, how many threads were at work), on
--threads threads (Taichi's pool; OpenMP's, dynamic chunks of 64 segments, its threads sleeping between calls
as Taichi's do, for C). The C result is
compared with Taichi's pair_f entry by entry (largest difference relative to the largest force): the C code is built
without fast-math unless --fast-math (Taichi builds with it), so equal to rounding is the check, not bit for bit.
Needs gcc with OpenMP.
"""
from __future__ import annotations

import csv
import ctypes
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import benchlib
from benchlib import write_csv

C_SRC = r"""
#include <math.h>
#include <omp.h>

typedef struct { float x, y; } v2;
static int N; static double Lx, Ly; static float W, KC;

static inline v2 mk(float x, float y) { v2 r = {x, y}; return r; }
static inline v2 add(v2 a, v2 b) { return mk(a.x + b.x, a.y + b.y); }
static inline v2 sub(v2 a, v2 b) { return mk(a.x - b.x, a.y - b.y); }
static inline v2 scl(float s, v2 a) { return mk(s * a.x, s * a.y); }
static inline float dot(v2 a, v2 b) { return a.x * b.x + a.y * b.y; }
static inline float nrm(v2 a) { return sqrtf(a.x * a.x + a.y * a.y); }
static inline float clamp01(float v) { return fminf(fmaxf(v, 0.0f), 1.0f); }
static inline double wrapd(double a, double L) {
    if (a >= 0.5 * L) return a - L;
    if (a <= -0.5 * L) return a + L;
    return a;
}
static inline v2 rel(const double *x, int y, int o) {
    return mk((float)wrapd(x[2 * y] - x[2 * o], Lx), (float)wrapd(x[2 * y + 1] - x[2 * o + 1], Ly));
}
static inline void chain(int t, int *p) {         /* Ap, A, B, Bn of segment t */
    int c = t / (N - 1), k = t % (N - 1), a = c * N + k, b = a + 1;
    p[0] = k > 0 ? a - 1 : a; p[1] = a; p[2] = b; p[3] = k < N - 2 ? b + 1 : b;
}
static inline float closest_gap(v2 p1, v2 q1, v2 p2, v2 q2) {
    v2 d1 = sub(q1, p1), d2 = sub(q2, p2), r = sub(p1, p2);
    float a = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r), c = dot(d1, r), b = dot(d1, d2);
    float eps = 1e-12f, s = 0.0f, t = 0.0f;
    if (a > eps && e > eps) {
        float denom = a * e - b * b;
        if (denom > 1e-9f * a * e) s = clamp01((b * f - c * e) / denom);
        else s = 0.5f * (clamp01(-c / a) + clamp01((b - c) / a));
        t = (b * s + f) / e;
        if (t < 0.0f) { t = 0.0f; s = clamp01(-c / a); }
        else if (t > 1.0f) { t = 1.0f; s = clamp01((b - c) / a); }
    } else if (a > eps) s = clamp01(-c / a);
    else if (e > eps) t = clamp01(f / e);
    return nrm(sub(add(p2, scl(t, d2)), add(p1, scl(s, d1))));
}
static inline float point_seg(v2 xp, v2 A, v2 B, float *u, v2 *cp) {
    v2 e0 = sub(A, xp), e = sub(B, A);
    float ee = dot(e, e), uu = 0.0f;
    if (ee > 1e-12f) uu = clamp01(-dot(e0, e) / ee);
    *cp = add(e0, scl(uu, e)); *u = uu;
    return nrm(*cp);
}
static inline int apart(int h, int k) { return h - (2 * k + 2) >= 3 || 2 * k - h >= 3; }

/* the samples of p_seg (P0, P1) pressed out of o_seg (A, B, its chain neighbours Ap, Bn): forces into f[0..7] */
static inline void side(int p_seg, int o_seg, v2 P0, v2 P1, const v2 *T, v2 *pa, v2 *pb, v2 *oa, v2 *ob) {
    int kp = p_seg % (N - 1), kt = o_seg % (N - 1), same = p_seg / (N - 1) == o_seg / (N - 1);
    int ns = kp == N - 2 ? 3 : 2;
    v2 A = T[0], B = T[1], Ap = T[2], Bn = T[3];
    for (int j = 0; j < ns; j++) {
        int h = 2 * kp + j;
        if (same && !apart(h, kt)) continue;
        float w = (h == 0 || h == 2 * (N - 1)) ? 0.5f : 0.25f;
        v2 xp = j == 0 ? P0 : (j == 1 ? scl(0.5f, add(P0, P1)) : P1);
        float u; v2 cp;
        float dist = point_seg(xp, A, B, &u, &cp);
        if (!(dist < W)) continue;
        float du; v2 dc;
        if (kt > 0 && (!same || apart(h, kt - 1)) && point_seg(xp, Ap, A, &du, &dc) <= dist) continue;
        if (kt < N - 2 && (!same || apart(h, kt + 1)) && point_seg(xp, B, Bn, &du, &dc) < dist) continue;
        v2 n;
        if (dist > 1e-9f) n = scl(-1.0f / dist, cp);
        else {
            v2 e = sub(B, A); float ln = nrm(e);
            n = mk(1.0f, 0.0f);
            if (ln > 1e-12f) n = mk(-e.y / ln, e.x / ln);
            if (p_seg < o_seg) n = scl(-1.0f, n);
        }
        v2 f = scl(w * KC * (W - dist), n);
        float P = 0.5f * j;
        *pa = add(*pa, scl(1.0f - P, f)); *pb = add(*pb, scl(P, f));
        *oa = sub(*oa, scl(1.0f - u, f)); *ob = sub(*ob, scl(u, f));
    }
}

void pair_loop(int n_s, int cap, int N_, double Lx_, double Ly_, float W_, float kc, int threads,
               const double *x, const int *nbr, const int *nbr_n, float *pair_f) {
    N = N_; Lx = Lx_; Ly = Ly_; W = W_; KC = kc;
    omp_set_num_threads(threads);
    #pragma omp parallel for schedule(dynamic, 64)
    for (int s = 0; s < n_s; s++) {
        int n = nbr_n[s];
        if (n == 0) continue;
        int ps[4]; chain(s, ps);
        v2 zero = mk(0.0f, 0.0f), Bs = rel(x, ps[2], ps[1]);
        for (int q = 0; q < n; q++) {
            int t = nbr[s * cap + q];
            if (t <= s) continue;
            float *v = pair_f + ((long)s * cap + q) * 8;
            for (int i = 0; i < 8; i++) v[i] = 0.0f;
            int pt[4]; chain(t, pt);
            v2 At = rel(x, pt[1], ps[1]), Bt = rel(x, pt[2], pt[1]);
            if (!(closest_gap(zero, Bs, At, add(At, Bt)) < W)) continue;
            v2 Ts[4] = {At, rel(x, pt[2], ps[1]), rel(x, pt[0], ps[1]), rel(x, pt[3], ps[1])};
            v2 St[4] = {rel(x, ps[1], pt[1]), rel(x, ps[2], pt[1]), rel(x, ps[0], pt[1]), rel(x, ps[3], pt[1])};
            v2 sa = zero, sb = zero, ta = zero, tb = zero, pa = zero, pb = zero, oa = zero, ob = zero;
            side(s, t, zero, Bs, Ts, &sa, &sb, &ta, &tb);
            side(t, s, zero, Bt, St, &pa, &pb, &oa, &ob);
            v[0] = sa.x + oa.x; v[1] = sa.y + oa.y; v[2] = sb.x + ob.x; v[3] = sb.y + ob.y;
            v[4] = ta.x + pa.x; v[5] = ta.y + pa.y; v[6] = tb.x + pb.x; v[7] = tb.y + pb.y;
        }
    }
}
"""


def c_library(fast_math: bool):
    """The C loop, built once per source text and flags (-O3 -march=native, OpenMP; -ffast-math as Taichi's)."""
    flags = ["-O3", "-march=native", "-fopenmp"] + (["-ffast-math"] if fast_math else [])
    tag = hashlib.sha1((C_SRC + " ".join(flags)).encode()).hexdigest()[:10]
    so = Path(tempfile.gettempdir()) / f"pair_loop_c_{tag}.so"
    if not so.is_file():
        src = so.with_suffix(".c")
        src.write_text(C_SRC)
        p = subprocess.run(["gcc", *flags, "-shared", "-fPIC", "-o", str(so), str(src), "-lm"], capture_output=True,
                           text=True)
        if p.returncode != 0:
            raise SystemExit(f"pair_loop_c: gcc failed (a C compiler with OpenMP is needed): {p.stderr.strip()[:300]}")
    # OpenMP's threads sleep between calls as Taichi's pool's do: none spins through the other loop's calls
    os.environ.setdefault("OMP_WAIT_POLICY", "passive")
    lib = ctypes.CDLL(str(so))
    d, i, f = ctypes.c_double, ctypes.c_int, ctypes.c_float
    ptr = np.ctypeslib.ndpointer
    lib.pair_loop.argtypes = [i, i, i, d, d, f, f, i, ptr(np.float64, flags="C"), ptr(np.int32, flags="C"),
                              ptr(np.int32, flags="C"), ptr(np.float32, flags="C")]
    lib.pair_loop.restype = None
    return lib


def main(argv=None) -> int:
    p = benchlib.parser(__doc__)
    p.add_argument("--state", default="S3 6 h", help='a benchmark state of dense_step.py (default "S3 6 h")')
    p.add_argument("--threads", type=int, default=1, help="threads for both loops (default 1)")
    p.add_argument("--reps", type=int, default=50, help="timed calls of each loop (default 50)")
    p.add_argument("--fast-math", action="store_true", help="build the C loop with -ffast-math (Taichi's default)")
    p.add_argument("--block-dims", default="", help="also time Taichi's loop at these chunk sizes (powers of two, "
                   "comma-separated; Taichi's own choice is about n_s / (32 threads))")
    a = p.parse_args(argv)
    if a.threads < 1 or a.reps < 1:
        raise SystemExit("pair_loop_c: --threads and --reps must be at least 1")
    try:
        block_dims = [int(b) for b in a.block_dims.split(",") if b.strip()]
    except ValueError:
        raise SystemExit(f"pair_loop_c: --block-dims {a.block_dims!r}: integers, comma-separated") from None
    if any(b < 1 or b & (b - 1) for b in block_dims):
        raise SystemExit(f"pair_loop_c: --block-dims {a.block_dims!r}: each a power of two (Taichi's rule)")
    lib = c_library(a.fast_math)          # before Taichi starts: a build failure costs nothing
    import dense_step
    import taichi as ti

    from taichimyxo.runtime import backend
    backend.init("cpu", a.threads)
    sim = dense_step.make_sim(a.state, None, None)
    nl, st, con = sim.neighbours, sim.state, sim.model.contacts
    if con.pair_f is None:
        raise SystemExit("pair_loop_c: the state's scene records contacts (implicit step); this compares pair_f")

    @ti.kernel
    def pairs_only():                 # the contacts' share of Model.pairs, as the step kernel launches it
        ti.loop_config(**st.loops.items)
        for i in range(st.n_s):
            con.pair_pass(st.segment_of(i))

    def chunked(b):
        @ti.kernel
        def pairs_chunked():
            ti.loop_config(block_dim=b)
            for i in range(st.n_s):
                con.pair_pass(st.segment_of(i))
        return pairs_chunked

    nl.rebuild()
    pairs_only()
    ti.sync()
    x = np.ascontiguousarray(st.x.to_numpy(), dtype=np.float64)
    nbr = np.ascontiguousarray(nl.nbr.to_numpy(), dtype=np.int32)
    nbr_n = np.ascontiguousarray(nl.nbr_n.to_numpy(), dtype=np.int32)
    cap = nbr.shape[1]
    ref = con.pair_f.to_numpy().reshape(st.n_s, cap, 8)
    out = np.zeros((st.n_s, cap, 8), dtype=np.float32)
    args = (st.n_s, cap, st.N, float(st.Lx), float(st.Ly), float(con.W), float(con.k_c), a.threads, x, nbr, nbr_n,
            out)
    lib.pair_loop(*args)
    mask = (np.arange(cap)[None, :] < nbr_n[:, None]) & (nbr > np.arange(st.n_s)[:, None])
    scale = float(np.abs(ref[mask]).max())
    diff = float(np.abs(out[mask] - ref[mask]).max())
    calls = {"taichi": pairs_only, **{f"taichi_block{b}": chunked(b) for b in block_dims},
             "c": lambda: lib.pair_loop(*args)}
    for fn in calls.values():
        fn()
    ti.sync()
    walls = {k: [] for k in calls}
    cpus = {k: 0.0 for k in calls}                        # the process's CPU time (all threads) per loop
    for _ in range(a.reps):                               # alternating, so a change of machine speed hits all
        for k, fn in calls.items():
            c0, t0 = time.process_time(), time.perf_counter()
            fn()
            ti.sync()
            walls[k].append(time.perf_counter() - t0)
            cpus[k] += time.process_time() - c0
    info = {"state": a.state, "threads": a.threads, "fast_math": a.fast_math, "reps": a.reps,
            "pairs_evaluated": int(mask.sum()),
            "largest_force_pN": scale, "largest_difference_pN": diff, "relative_difference": diff / scale,
            "entries_differing": int((out[mask] != ref[mask]).any(axis=-1).sum())}
    for k, w in walls.items():
        info[f"{k}_best_ms"] = round(1e3 * min(w), 4)
        info[f"{k}_median_ms"] = round(1e3 * float(np.median(w)), 4)
        info[f"{k}_cores_busy"] = round(cpus[k] / sum(w), 2)          # CPU time / wall time: threads at work
    info["speedup_best"] = round(info["taichi_best_ms"] / info["c_best_ms"], 2)
    info["speedup_median"] = round(info["taichi_median_ms"] / info["c_median_ms"], 2)
    print(json.dumps(info))
    if a.out:
        out_dir = Path(a.out)
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / "pair_loop_c.csv"          # one row per call: the 1- and 2-thread runs side by side
        rows = []
        if path.is_file():
            with open(path, newline="") as f:
                rows = list(csv.DictReader(f))
        write_csv(path, rows + [info], cols=list(info))
    sim.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
