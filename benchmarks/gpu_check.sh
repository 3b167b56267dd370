#!/usr/bin/env bash
# Check taichimyxo on a CUDA GPU and measure its speed there, in one command from the repository root:
#
#     bash benchmarks/gpu_check.sh
#
# It installs what is missing, runs the `gpu` tests (CUDA against the CPU in f32, mixed and f64 precision, and the free
# cell speed) while the benchmark's kernels compile, then the CUDA throughput benchmark at 1x, 4x and 16x the paper's
# area with the projected wall time of a full 6 h S3. Each step runs under its own time limit, so the script ends
# within about 8 minutes whatever hangs. Results land in $OUT (default ./gpu-check-results, git-ignored):
#   gpu_check.log       everything printed
#   env.txt             GPU, driver, versions, whether Taichi started on CUDA
#   gpu_tests.xml       the gpu tests' results (JUnit)
#   gpu_compare.jsonl   the CUDA-CPU differences each comparison measured (tests/backend_compare.py)
#   throughput.csv/json particle-steps per second per scene and size, and the full-S3 projection
# Send these back with an issue, or add the numbers with their command to docs/performance.md.
#
# Installing: with a package index it runs `pip install -e '.[test]'` when taichi is missing. A GPU machine without
# one needs the wheels brought along: on a machine with an index, `bash benchmarks/gpu_check.sh --prepare` downloads
# taichi, dill and gsd for CPython 3.12 on x86-64 Linux (57 MB) into .whl/ (git-ignored); copy the clone with .whl/ to
# the GPU machine and run the command above there (it installs the wheels into a scratch folder). Its Python must
# already have numpy, pytest, matplotlib, scipy, imageio and tqdm; pytest-xdist is used when present.
#
# Settings (environment variables): PY (python3), OUT, GPU_CHECK_ARCH (cuda), GPU_CHECK_SIZES ("1 4 16"),
# GPU_CHECK_SCENES (S1,S3,S11), GPU_CHECK_STEPS (500), GPU_CHECK_WORKERS (6 test workers). A dry run on a CPU:
#     GPU_CHECK_ARCH=cpu GPU_CHECK_SIZES=0.04 PY=.venv/bin/python OUT=gpu-check-results/cpu bash benchmarks/gpu_check.sh
set -u
cd "$(dirname "$0")/.."
PY=${PY:-python3}

if [ "${1:-}" = "--prepare" ]; then
    echo /.whl/ >> "$(git rev-parse --git-path info/exclude)"
    exec "$PY" -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
        --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
        --platform manylinux2014_x86_64 -d .whl taichi==1.7.4 dill gsd
fi

OUT=${OUT:-gpu-check-results}
ARCH=${GPU_CHECK_ARCH:-cuda}
SIZES=${GPU_CHECK_SIZES:-1 4 16}
SCENES=${GPU_CHECK_SCENES:-S1,S3,S11}
STEPS=${GPU_CHECK_STEPS:-500}
WORKERS=${GPU_CHECK_WORKERS:-6}
mkdir -p "$OUT"
# scratch files in a fresh folder of their own, removed at the end (two checks on one machine never share one)
SCRATCH="$(mktemp -d "${TMPDIR:-/tmp}/gpu_check.XXXXXX")"
trap 'rm -rf "$SCRATCH"' EXIT
exec > >(tee -a "$OUT/gpu_check.log") 2>&1
export PYTHONUNBUFFERED=1 PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
t0=$(date +%s)
stamp() { echo "== $(( $(date +%s) - t0 )) s: $*"; }

stamp "install"
if ! "$PY" -c "import taichi" 2>/dev/null; then
    if ls .whl/*.whl >/dev/null 2>&1; then
        timeout -k 5 60 "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target "$SCRATCH/site" \
            .whl/*.whl && export PYTHONPATH="$PYTHONPATH:$SCRATCH/site"
    else
        timeout -k 5 240 "$PY" -m pip install -q -e '.[test]'
    fi
fi

stamp "environment"
{
    date -u; nvidia-smi 2>&1 | head -20
    timeout -k 5 30 "$PY" -c "
import numpy, taichi as ti
print('taichi', ti.__version__, 'numpy', numpy.__version__)
ti.init(arch=getattr(ti, '$ARCH'), log_level=ti.ERROR)
print('taichi runs on', ti.lang.impl.current_cfg().arch)"
} > "$OUT/env.txt" 2>&1
cat "$OUT/env.txt"

# the tests and the benchmark's compiling run side by side (both are CPU work: Taichi compiles every kernel on the
# CPU, ~10-30 s each); the timed part of the benchmark runs afterwards, alone on the GPU
stamp "gpu tests (background, limit 200 s) and compiling the benchmark's kernels (limit 180 s)"
xdist=""
"$PY" -c "import xdist" 2>/dev/null && xdist="-n $WORKERS"
TAICHIMYXO_GPU_REPORT="$OUT/gpu_compare.jsonl" timeout -k 10 200 "$PY" -m pytest tests/test_gpu.py -m gpu -rs \
    -p no:cacheprovider $xdist --junitxml="$OUT/gpu_tests.xml" > "$SCRATCH/gpu_tests.txt" 2>&1 &
tests=$!
compiling=()
for s in $SIZES; do
    for sc in ${SCENES//,/ }; do
        timeout -k 5 180 "$PY" -m taichimyxo bench throughput --arch "$ARCH" --scenes "$sc" --sizes "$s" --steps 1 \
            --warm 2 --out "$SCRATCH/compile/$sc-$s" > "$SCRATCH/compile_$sc-$s.txt" 2>&1 &
        compiling+=($!)
    done
done
wait "${compiling[@]}"
stamp "compiled; waiting for the tests"
wait $tests; echo "pytest exit status $?"
cat "$SCRATCH/gpu_tests.txt"
tail -n 3 "$SCRATCH"/compile_*.txt

for s in $SIZES; do
    limit=45; [ "$s" = 16 ] && limit=75
    stamp "throughput at ${s}x the paper's area (limit $limit s)"
    timeout -k 5 $limit "$PY" -m taichimyxo bench throughput --arch "$ARCH" --scenes "$SCENES" --sizes "$s" \
        --steps "$STEPS" --warm 50 --out "$OUT" || echo "bench at ${s}x: exit status $?"
done
stamp "done"
ls -l "$OUT"
