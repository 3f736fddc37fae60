#!/usr/bin/env bash
# One lent GPU session in one call of the device tool (docs/gpu.md, "Measuring on a lent GPU"). Before the call, on a
# machine with PyPI: `bash devtools/gpu_wheels.sh` (gymnasium and what it needs that the image lacks, into .whl/,
# git-ignored); the call carries it: carry [".whl"], command `bash devtools/gpu_session.sh [--ladder]`, timeout_s
# 480. Nothing outside the repository is used. On the device: install the carried wheels,
# then, each part under its own time limit and each run even where one before it failed:
#   1. the gpu tests (tests/backends/test_cuda.py -m gpu);
#   2. tests/backends/cuda_sim_check.py on the real GPU (the CUDA backend against the CPU, step by step; it stops at the
#      first difference and says where);
#   3. devtools.throughput_gpu --variants -> docs/throughput_gpu.md;
#   4. studies.ppo_torch_report (training.ppo_torch) with configs/train/ppo_torch_gpu.yaml -> docs/ppo_torch_gpu.md;
#   5. with --ladder: the agent ladder's GPU cells (configs/ladder/gpu.yaml) -> docs/ladder_gpu.md, resumable: the
#      jobs finished before the time limit are kept in $OUT/ladder_gpu (carry runs/ladder_gpu back to resume).
# The reports are written where they are committed, then copied with one log to $OUT (8 files at most come back).
# PARTS (default "tests check throughput ppo", and "ladder" after them with --ladder) picks the parts and their
# order, so that one call fits the device time: PARTS="check throughput tests" runs the step-by-step check first (its
# compiles fill numba's cache for the rest), then the benchmark, then the tests; each part's time limit is
# TESTS_SECONDS, CHECK_SECONDS, THROUGHPUT_SECONDS, PPO_SECONDS, LADDER_SECONDS.
#   usage: [PARTS="..."] bash devtools/gpu_session.sh [--ladder]
set -u
LADDER=
if [ "${1:-}" = "--ladder" ]; then LADDER=1; shift; fi
PARTS=${PARTS:-"tests check throughput ppo${LADDER:+ ladder}"}
for p in $PARTS; do
  case $p in tests|check|throughput|ppo|ladder) ;; *) echo "PARTS: unknown part '$p' (tests check throughput ppo ladder)"; exit 2;; esac
done
[ -n "$(ls .whl/*.whl 2>/dev/null)" ] || { echo "no wheels in .whl/: run bash devtools/gpu_wheels.sh first and carry .whl"; exit 2; }
export PYTHONUNBUFFERED=1 OUT=${OUT:-/tmp/out} TF_CPP_MIN_LOG_LEVEL=3
mkdir -p "$OUT"
LOG="$OUT/log.txt"
t0=$(date +%s)
stamp() { echo "=== $1 ($(( $(date +%s) - t0 )) s)" | tee -a "$LOG"; }
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
  && export PYTHONPATH=/tmp/site:$PWD || { echo "wheel install failed" | tee -a "$LOG"; exit 1; }
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>&1 | tee -a "$LOG"
python3 -c "import numba, numba_cuda, numpy, torch, gymnasium; print('numba', numba.__version__, 'numba-cuda', numba_cuda.__version__, 'numpy', numpy.__version__, 'torch', torch.__version__, 'gymnasium', gymnasium.__version__)" 2>&1 | tee -a "$LOG"
part_tests() {
  stamp "gpu tests"
  timeout "${TESTS_SECONDS:-100}" python3 -m pytest -q -p no:cacheprovider -m gpu tests/backends/test_cuda.py -x 2>&1 | tail -25 >> "$LOG"
}
part_check() {
  stamp "CUDA against CPU, step by step"
  timeout "${CHECK_SECONDS:-45}" python3 tests/backends/cuda_sim_check.py 30 >> "$LOG" 2>&1; echo "exit $?" >> "$LOG"
}
part_throughput() {
  stamp "throughput"
  timeout "${THROUGHPUT_SECONDS:-150}" python3 -m devtools.throughput_gpu ${THROUGHPUT_ARGS:---variants} --out docs/throughput_gpu.md 2>&1 | tail -40 >> "$LOG"
  cp docs/throughput_gpu.md "$OUT/" 2>/dev/null
}
part_ppo() {
  stamp "PPO"
  if [ -n "${PPO_GRAPH_PROBE:-}" ]; then  # a short run with the rollout captured in a graph: its error in full
    timeout "${PROBE_SECONDS:-40}" python3 -m training.ppo_torch --env-backend cuda --device cuda --num-envs 4096 --total-timesteps 400000 \
        --eval-episodes 8 --cuda-graph on --out /tmp/ppo_probe 2>&1 | grep -v Warn | tail -25 >> "$LOG"
  fi
  timeout "${PPO_SECONDS:-90}" python3 -m studies.ppo_torch_report --config configs/train/ppo_torch_gpu.yaml --env-backend cuda \
      --device cuda --curve-points 5 ${PPO_ARGS:-} --report docs/ppo_torch_gpu.md --out /tmp/ppo 2>&1 | tail -6 >> "$LOG"
  cp docs/ppo_torch_gpu.md "$OUT/" 2>/dev/null
}
part_ladder() {
  stamp "ladder (configs/ladder/gpu.yaml)"
  timeout "${LADDER_SECONDS:-240}" python3 -m studies.ladder --config configs/ladder/gpu.yaml --runs runs/ladder_gpu \
      --out docs/ladder_gpu.md --workers 1 2>&1 | tail -8 >> "$LOG"
  cp docs/ladder_gpu.md "$OUT/" 2>/dev/null
  tar czf "$OUT/ladder_gpu.tgz" runs/ladder_gpu 2>/dev/null
}
for p in $PARTS; do "part_$p"; done
stamp "done"
ls -la "$OUT" >> "$LOG"
cat "$LOG"
