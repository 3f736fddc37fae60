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
ls "$dest"
