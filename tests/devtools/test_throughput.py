"""The throughput benchmark command runs (--quick) and writes its Markdown report."""
from devtools import throughput


def test_throughput_quick(reports_untouched):
    out = reports_untouched / "reports" / "throughput.md"  # --out relative to the working directory
    report = throughput.main(["--quick", "--out", "reports/throughput.md"])
    text = out.read_text()
    assert text == report
    for needle in ("Pendulum-v1", "CartPole-v1", "PennyImpacts-Stadium-v0", "SyncVectorEnv", "| 256 |", "command:", "date:",
                   "best of 1 run", "## Targets", "5 M target", "30x target", "half of Pendulum-v1"):
        assert needle in text
