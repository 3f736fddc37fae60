"""The work-per-step diagnostics (issue 10.6) run in --quick mode and report every preset."""
import pytest

from penny_env.backends.choice import available

pytestmark = pytest.mark.skipif(not available(), reason="numba is not installed")


def test_step_work_quick_reports_every_preset(capsys):
    from devtools import step_work
    step_work.counters(8, 2)
    step_work.penny_costs(16, 3)
    out = capsys.readouterr().out
    for preset in step_work.PRESETS:
        assert out.count(preset) == 2, preset
    assert "search iterations" in out and "99.99th percentile" in out
