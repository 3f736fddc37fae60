import os

import numpy as np
import pytest
from hypothesis import settings


os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
settings.register_profile("ci", deadline=None, max_examples=60, derandomize=True)
settings.load_profile("ci")

PAPER_STATE = np.array([0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2])


def random_inside_state(rng, params, table, speed=10.0, spin=2.0, margin=0.0):
    """A state with both ends strictly inside the table (rejection sampling)."""
    xmin, xmax, ymin, ymax = table.extent
    for _ in range(10_000):
        x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
        phi = rng.uniform(-np.pi, np.pi)
        ok = True
        for s in (1, -1):
            px, py = x + s * params.R * np.cos(phi), y + s * params.R * np.sin(phi)
            if table.h(px, py) >= -margin * table.size:
                ok = False
        if ok:
            return np.array([x, y, rng.uniform(-3, 3), phi, rng.uniform(-speed, speed), rng.uniform(-spin, spin)])
    raise RuntimeError("no inside state found")


@pytest.fixture
def paper_state():
    return PAPER_STATE.copy()
