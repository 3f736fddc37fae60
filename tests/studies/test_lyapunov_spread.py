"""studies/lyapunov_spread.py: the bound on how far two correct computations of lambda1 can differ."""
import math

import numpy as np
import pytest

from penny_env.analysis import boundary_map as bm
from penny_env.physics import PennyParams
from studies import lyapunov_spread as ls


def test_a_copy_starts_at_the_same_place_with_the_same_energy_turned_by_the_angle():
    p = PennyParams()
    s = np.array([0.05, -0.02, 1.0, 0.3, 7.0, -2.0])
    t = ls.turned(s, 1e-3, p)
    assert np.array_equal(t[:4], s[:4])
    assert float(bm.metric_speed(t, p)) == pytest.approx(float(bm.metric_speed(s, p)), rel=1e-15)
    psi = [math.atan2(math.sqrt(p.J) * x[5], math.sqrt(p.rolling_inertia) * x[4]) for x in (s, t)]
    assert psi[1] - psi[0] == pytest.approx(1e-3, abs=1e-15)


@pytest.mark.slow  # (the batched boundary map's first use in a process compiles it: about 30 s on 2 busy cores)
def test_quick_run_writes_outside_docs(tmp_path):
    out, rows = ls.main(["--quick", "--out", str(tmp_path / "spread.md")])
    text = out.read_text()
    assert len(rows) == 2 and all(len(r["copies"]) == 1 and r["se"] > 0 for r in rows)
    assert "copies - orbit (in SE)" in text and "standard deviations of these differences" in text
    with pytest.raises(SystemExit):
        ls.main(["--quick", "--out", str(ls.ROOT / "docs" / "lyapunov_spread.md")])
