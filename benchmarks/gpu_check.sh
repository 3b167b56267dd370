#!/usr/bin/env bash
# The device check of issue 16, for the day a CUDA GPU is lent (an NVIDIA H200 for ~15 minutes): install, the `gpu`
# tests (CUDA against the CPU in f32, mixed, f64; the free speed), then the CUDA throughput benchmark at 1x, 4x and
# 16x the paper's area with the projected wall time of a full 6 h S3. Everything lands in $OUT; each step runs under
# its own time limit, so the whole script ends within about 8 minutes (7.5 at worst), whatever hangs.
#
# Prepare here, once (the device machine reaches no package index; its python3 is 3.12 with numpy, pytest,
# pytest-xdist, matplotlib, scipy, imageio, tqdm, rich; taichi, dill and gsd travel as wheels, 57 MB):
#     bash benchmarks/gpu_check.sh --prepare        # wheels into .whl/ (git-ignored through info/exclude)
# then, with the device tool, from the repository root:
#     run(command="bash benchmarks/gpu_check.sh", carry=[".whl"], timeout_s=560)
# Without .whl/ and without taichi it runs `pip install -e '.[test]'` (a machine with a package index).
#
# What comes back ($OUT, 6 files): gpu_check.log (everything printed), env.txt (GPU, driver, versions, Taichi's CUDA
# start), gpu_tests.xml (JUnit of the gpu tests), gpu_compare.jsonl (the differences each comparison measured:
# tests/backend_compare.py), throughput.csv and throughput.json (rows per scene and size, projection of a full S3).
# Nothing here is a claimed GPU figure until it has run on a GPU and been read.
#
# Knobs (for a dry run on the CPU: GPU_CHECK_ARCH=cpu GPU_CHECK_SIZES=0.04 PY=.venv/bin/python OUT=/tmp/x):
#   PY (python3), GPU_CHECK_ARCH (cuda), GPU_CHECK_SIZES ("1 4 16"), GPU_CHECK_SCENES (S1,S3,S11),
#   GPU_CHECK_STEPS (500), GPU_CHECK_WORKERS (6, pytest-xdist workers for the tests)
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
exec > >(tee -a "$OUT/gpu_check.log") 2>&1
export PYTHONUNBUFFERED=1 PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
t0=$(date +%s)
stamp() { echo "== $(( $(date +%s) - t0 )) s: $*"; }

stamp "install"
if ! "$PY" -c "import taichi" 2>/dev/null; then
    if ls .whl/*.whl >/dev/null 2>&1; then
        timeout -k 5 60 "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site \
            .whl/*.whl && export PYTHONPATH="$PYTHONPATH:/tmp/site"
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
    -p no:cacheprovider $xdist --junitxml="$OUT/gpu_tests.xml" > /tmp/gpu_tests.txt 2>&1 &
tests=$!
compiling=()
for s in $SIZES; do
    for sc in ${SCENES//,/ }; do
        timeout -k 5 180 "$PY" -m taichimyxo bench throughput --arch "$ARCH" --scenes "$sc" --sizes "$s" --steps 1 \
            --warm 2 --out "/tmp/gpu_check_compile/$sc-$s" > "/tmp/gpu_check_compile_$sc-$s.txt" 2>&1 &
        compiling+=($!)
    done
done
wait "${compiling[@]}"
stamp "compiled; waiting for the tests"
wait $tests; echo "pytest exit status $?"
cat /tmp/gpu_tests.txt
tail -n 3 /tmp/gpu_check_compile_*.txt

for s in $SIZES; do
    limit=45; [ "$s" = 16 ] && limit=75
    stamp "throughput at ${s}x the paper's area (limit $limit s)"
    timeout -k 5 $limit "$PY" -m taichimyxo bench throughput --arch "$ARCH" --scenes "$SCENES" --sizes "$s" \
        --steps "$STEPS" --warm 50 --out "$OUT" || echo "bench at ${s}x: exit status $?"
done
stamp "done"
ls -l "$OUT"
