"""No test asserts a wall time (issue 40, item 12): a check that a run took under N seconds fails on a slower or
busier machine (test_impact_quick_run_writes_outside_docs's 60 s failed at load 5). Tests bound work by counts
(intervals run, impacts recorded); a wait for a subprocess may give up after a hang detector's margin (at least ten
times the expected time on a slow machine), by a timeout or pytest.fail, never by an assert on the clock."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CLOCKS = {"perf_counter", "time", "monotonic", "perf_counter_ns", "monotonic_ns", "time_ns", "process_time"}


def _is_clock_call(node) -> bool:
    return (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in CLOCKS
            and isinstance(node.func.value, ast.Name) and node.func.value.id == "time")


def _is_wall_bound(node) -> bool:
    """``wall < 60``: a name holding a measured wall time (``wall``, ``wall_s``) compared with a constant."""
    if not (isinstance(node, ast.Compare) and len(node.ops) == 1 and isinstance(node.ops[0], (ast.Lt, ast.LtE))
            and isinstance(node.comparators[0], ast.Constant)):
        return False
    left = node.left
    return isinstance(left, ast.Name) and left.id.startswith("wall")


def wall_time_asserts(source: str) -> list[int]:
    """Line numbers of the asserts that read a clock, directly or through a name assigned from one (t0 =
    time.perf_counter()) in the same function, or bound a measured wall time (``wall < 60``)."""
    tree = ast.parse(source)
    found = []
    for func in [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Module))]:
        clocks = {t.id for n in ast.walk(func) if isinstance(n, ast.Assign) and _is_clock_call(n.value)
                  for t in n.targets if isinstance(t, ast.Name)}
        clocks |= {t.id for n in ast.walk(func) if isinstance(n, ast.Assign)
                   and any(_is_clock_call(c) for c in ast.walk(n.value)) for t in n.targets if isinstance(t, ast.Name)}
        for node in ast.walk(func):
            if isinstance(node, ast.Assert) and any(
                    _is_clock_call(c) or (isinstance(c, ast.Name) and c.id in clocks) or _is_wall_bound(c)
                    for c in ast.walk(node.test)):
                found.append(node.lineno)
    return sorted(set(found))


def test_the_scanner_finds_a_wall_time_assert():
    src = ("import time\ndef test_x():\n    t0 = time.perf_counter()\n    run()\n"
           "    assert time.perf_counter() - t0 < 60\n    deadline = time.monotonic() + 5\n    assert ok and deadline > 0\n")
    assert wall_time_asserts(src) == [5, 7]
    assert wall_time_asserts("def test_y():\n    n = count()\n    assert n <= 3\n") == []
    assert wall_time_asserts("def test_z():\n    for rs, wall in runs():\n        assert rs and wall < 60\n") == [3]


def test_no_test_asserts_a_wall_time():
    offenders = []
    for path in sorted((ROOT / "tests").rglob("*.py")):
        lines = wall_time_asserts(path.read_text())
        offenders += [f"{path.relative_to(ROOT)}:{n}" for n in lines]
    assert not offenders, f"tests asserting a wall time (bound the work by counts instead): {offenders}"
