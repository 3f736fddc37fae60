#!/usr/bin/env bash
# The wheels that devtools/gpu_session.sh installs on a lent GPU machine, which reaches nothing outside itself: its
# image has Python 3.12, numpy, numba, numba-cuda and torch, not gymnasium. Run this once on a machine with PyPI
# (the folder .whl/ is git-ignored), then carry it to the device: the device tool's carry [".whl"].
#   usage: bash devtools/gpu_wheels.sh [FOLDER]   (default .whl)
set -euo pipefail
cd "$(dirname "$0")/.."
dest=${1:-.whl}
mkdir -p "$dest"
# pure-Python wheels, so the platform is the image's in name only; --no-deps: the image has numpy and typing-extensions
python3 -m pip download -q --only-binary=:all: --no-deps --python-version 3.12 --implementation cp \
    --platform manylinux2014_x86_64 -d "$dest" "gymnasium>=1.0" farama-notifications cloudpickle
# numpy 2.4.6: the image's numpy 2.5.2 removed np.row_stack, which numba-cuda 0.30.4 reads when it first compiles a
# kernel (AttributeError, seen on the H200 on 2026-11-28); the wheel on PYTHONPATH shadows the image's numpy
python3 -m pip download -q --only-binary=:all: --no-deps --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 -d "$dest" numpy==2.4.6
ls "$dest"
