#!/usr/bin/env bash
# One lent GPU session, in one call of the device tool (devtools/README.md): install what the image lacks (the
# wheels carried in .whl), the gpu tests, the throughput benchmark, a PPO run and the pure-RL scale study.
# Every part runs even if one before it failed; logs and reports go to $OUT.
#   part A (default): tests, throughput (with variants), PPO on PennyReach-Ellipse-v0
#   part B: the scale study (training.scale_rl) with the arguments after "B"
set -u
export PYTHONUNBUFFERED=1 OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
  && export PYTHONPATH=/tmp/site:$PWD || { echo "wheel install failed"; exit 1; }
export TF_CPP_MIN_LOG_LEVEL=3
part=${1:-A}; shift || true
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm --format=csv | tee "$OUT/gpu.txt"
python3 -c "import numba, numba_cuda, numpy, torch, gymnasium; print('numba', numba.__version__, 'numba-cuda', numba_cuda.__version__, 'numpy', numpy.__version__, 'torch', torch.__version__, 'gymnasium', gymnasium.__version__)" | tee -a "$OUT/gpu.txt"
if [ "$part" = A ]; then
  timeout 240 python3 -m pytest -q -p no:cacheprovider -m gpu tests/test_cuda.py 2>&1 | tail -30 | tee "$OUT/gpu_tests.txt"
  timeout 300 python3 -m devtools.throughput_gpu --variants --out "$OUT/throughput_gpu.md" 2>&1 | tail -25
  timeout 240 python3 -m training.ppo_torch --config configs/train/ppo_torch_gpu.yaml --env-backend cuda --device cuda \
      --curve-points 5 --out /tmp/ppo 2>&1 | tail -8 | tee "$OUT/ppo.txt"
  cp /tmp/ppo/results.json "$OUT/ppo_results.json" 2>/dev/null; cp /tmp/ppo/progress.csv "$OUT/ppo_progress.csv" 2>/dev/null
else
  timeout 560 python3 -m training.scale_rl --out "$OUT/scale_rl.md" "$@" 2>&1 | tail -20
fi
ls -la "$OUT"
