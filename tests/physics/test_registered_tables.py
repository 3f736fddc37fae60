"""A table shape registered with register_table is held to what a ConvexTable is held to (issue 31, deliverable 1;
physics/tables/registered.py): its compiled formulas against its own h, grad and hessian, and its bounds, on a
grid, before a penny rolls on it; its formulas must compile. Also the table side of the stale-cache defect:
instances of a user class that does not define _fields() compared equal, so scalar_model's cache handed one
table another's constants (Table._key, the minimal fix of issue 29 item 1)."""
import numpy as np
import pytest

import penny_env as pe
import penny_env.batch as pb
from penny_env.envs.scene import ConfigError
from penny_env.physics import PennyParams, SolverSettings
from penny_env.physics import tables as T
from penny_env.physics.laws import make_law
from penny_env.physics.scalar import scalar_model
from penny_env.physics.tables.base import Table, length


def disc_terms(c, x, y):
    r2, inv = c[0], c[1]
    return (x * x + y * y - r2) * 0.5 * inv, x * inv, y * inv


def disc_terms_wrong(c, x, y):  # one wrong factor, as in the reliability trial (pennies left the table by 1.3 to 33 mm)
    r2, inv = c[0], c[1]
    return (x * x + y * y - r2) * 0.5 * inv, x * inv, 1.1 * y * inv


def disc_hess(c, x, y):
    return c[1], 0.0, c[1]


def disc_hess_wrong(c, x, y):
    return c[1], 0.0, 2.0 * c[1]


class Disc(Table):
    """docs/extending.md's example shape, without _fields() (so its equality comes from its constants)."""

    name = "disc"
    terms = staticmethod(disc_terms)
    hess = staticmethod(disc_hess)
    third_derivative_bound = 0.0
    hessian_jump = 0.0

    def __init__(self, r, hessian_bound=None):
        self.r = length("Disc", "r", r)
        self.grad_bound = 1.0
        self.hessian_bound = 1.0 / self.r if hessian_bound is None else hessian_bound
        self.inradius, self.extent = self.r, (-self.r, self.r, -self.r, self.r)

    def constants(self):
        return (self.r * self.r, 1.0 / self.r)

    def h(self, x, y):
        return (x * x + y * y - self.r * self.r) * 0.5 / self.r

    def grad(self, x, y):
        return x / self.r, y / self.r

    def hessian(self, x, y):
        return 1.0 / self.r + 0.0 * x, 0.0 * x, 1.0 / self.r + 0.0 * y


@pytest.fixture
def shapes():
    """register_table, with every registration undone afterwards."""
    n = len(T.COMPILED_FORMULAS)
    kinds = dict(T.TABLE_KINDS)

    def register(name, cls):
        pe.register_table(name, cls)
    yield register
    T.TABLE_KINDS.clear()
    T.TABLE_KINDS.update(kinds)
    del T.COMPILED_FORMULAS[n:]


def variant(name, **attrs):
    return type(name, (Disc,), attrs)


def test_a_sound_registered_shape_runs(shapes):
    shapes("disc", Disc)
    tr = pe.simulate([0, 0, 0, 1.0, 20.0, 0.5], table=Disc(0.1), t_final=2.0)
    assert tr.n_impacts > 3
    env = pe.PennyEnv("circle", "reach", table={"kind": "disc", "r": 0.1}, backend="python")
    env.reset(seed=0)
    env.step(np.zeros(2, np.float32))


def test_a_wrong_factor_in_the_formulas_is_refused_before_a_penny_rolls(shapes):
    shapes("bad_disc", variant("BadDisc", terms=staticmethod(disc_terms_wrong)))
    table = T.make_table({"kind": "bad_disc", "r": 0.1})
    match = r"table disc \(BadDisc\): the compiled formula terms gives dh/dy = .* where the table's own method gives"
    with pytest.raises(ValueError, match=match):
        pe.simulate([0, 0, 0, 1.0, 20.0, 0.5], table=table, t_final=0.5)
    with pytest.raises(ValueError, match=match):
        pb.simulate(np.zeros((1, 6)), table=table, t_final=0.5, backend="python")
    with pytest.raises(ConfigError, match=match):
        pe.PennyEnv("circle", "reach", table={"kind": "bad_disc", "r": 0.1})


def test_a_wrong_hessian_formula_is_refused(shapes):
    shapes("bad_hess", variant("BadHess", hess=staticmethod(disc_hess_wrong)))
    with pytest.raises(ValueError, match=r"the compiled formula hess gives hyy"):
        pe.simulate([0, 0, 0, 1.0, 20.0, 0.5], table=T.make_table({"kind": "bad_hess", "r": 0.1}), t_final=0.5)


def test_bounds_below_what_the_grid_shows_are_refused(shapes):
    shapes("disc", Disc)
    with pytest.raises(ValueError, match=r"table disc \(Disc\)\.hessian_bound=2.0 is below"):
        pe.simulate([0, 0, 0, 1.0, 20.0, 0.5], table=Disc(0.1, hessian_bound=2.0), t_final=0.5)


def test_formulas_must_take_c_x_y_and_compile(shapes):
    with pytest.raises(TypeError, match=r"register_table: Two\.terms must take \(c, x, y\)"):
        shapes("two", variant("Two", terms=staticmethod(lambda x, y: (x, x, y))))
    pytest.importorskip("numba")

    def helper(v):
        return v

    def uses_helper(c, x, y):
        return helper(x) * c[0], x, y
    with pytest.raises(ValueError, match=r"register_table: Helped\.terms: numba cannot compile it.*TypingError"):
        shapes("helped", variant("Helped", terms=staticmethod(uses_helper)))
    with pytest.raises(ValueError, match=r"Pairs\.hess must return three numbers"):
        shapes("pairs", variant("Pairs", hess=staticmethod(lambda c, x, y: (c[0], c[1]))))
    assert "two" not in T.TABLE_KINDS and "helped" not in T.TABLE_KINDS


def test_the_built_in_shapes_cannot_be_replaced(shapes):
    with pytest.raises(ValueError, match="one of penny_env's own table shapes"):
        shapes("ellipse", Disc)
    assert T.TABLE_KINDS["ellipse"] is pe.Ellipse


def test_registering_a_name_again_replaces_the_class(shapes):
    shapes("disc", Disc)
    with pytest.warns(UserWarning, match="'disc' now builds Disc2"):
        shapes("disc", variant("Disc2"))
    assert type(T.make_table({"kind": "disc", "r": 0.1})).__name__ == "Disc2"


def test_instances_without_fields_are_told_apart_by_their_constants(shapes):
    # Table.__eq__ / __hash__ came from _fields(), {} by default: Disc(0.1) == Disc(0.2), and scalar_model's cache
    # gave the second the first one's constants (a penny on the 0.2 table bounced off the 0.1 wall)
    shapes("disc", Disc)
    a, b = Disc(0.1), Disc(0.2)
    assert a != b and a == Disc(0.1) and hash(a) == hash(Disc(0.1))
    P, L, S = PennyParams(), make_law("elastic"), SolverSettings()
    assert scalar_model(P, a, L, S) != scalar_model(P, b, L, S)
    assert scalar_model(P, b, L, S).table_c0 == pytest.approx(0.04)
    far = pe.simulate([0.15, 0, 0, 0.0, 10.0, 0.0], table=b, t_final=0.01)  # inside b, outside a
    assert far.n_impacts == 0


def test_a_class_whose_formulas_change_runs_the_new_ones(shapes):
    cls = variant("Mutable")
    shapes("mutable", cls)
    table = cls(0.1)
    P, L, S = PennyParams(), make_law("elastic"), SolverSettings()
    before = scalar_model(P, table, L, S)
    cls.terms = staticmethod(lambda c, x, y: ((x * x + y * y - c[0]) * 0.5 * c[1], x * c[1], y * c[1]))  # new formulas
    pe.register_table("mutable", cls)
    after = scalar_model(P, table, L, S)
    assert after.kind != before.kind and T.COMPILED_FORMULAS[after.kind][0] is cls.terms


# -- formulas that differ from h between the grid's points: caught where the penny hits (issue 40, item 2) ------
def bump_terms(c, x, y):
    """The disc's h minus A sin^2(k (x + r)) sin^2(k (y + r)): zero on every line of the 41 x 41 comparison grid."""
    r2, inv, A, k, r = c[0], c[1], c[2], c[3], c[4]
    sx, sy = np.sin(k * (x + r)), np.sin(k * (y + r))
    cx, cy = np.cos(k * (x + r)), np.cos(k * (y + r))
    h = (x * x + y * y - r2) * 0.5 * inv - A * sx * sx * sy * sy
    return h, x * inv - 2.0 * A * k * sx * cx * sy * sy, y * inv - 2.0 * A * k * sy * cy * sx * sx


class BumpDisc(Disc):
    """repro_table_between_grid.py: terms lie up to A = 3 mm outside the table's own wall between the grid lines."""

    name = "bumpdisc"
    terms = staticmethod(bump_terms)

    def __init__(self, r, A=3e-3):
        super().__init__(r)
        self.A = float(A)
        k = np.pi / (2 * self.r / 40)
        self.grad_bound = 1.0 + 2 * self.A * k + 0.05  # bounds true for the formulas
        self.hessian_bound = 1.0 / self.r + 4 * self.A * k * k + 1.0

    def constants(self):
        return (self.r * self.r, 1.0 / self.r, self.A, float(np.pi / (2 * self.r / 40)), self.r)

    hessian = None  # (no third-order certificate: its bound would be false for the bumps, as in the repro)


def test_formulas_that_differ_from_h_between_the_grid_points_are_caught_at_impacts(shapes):
    from penny_env.physics.tables import registered
    shapes("bumpdisc", BumpDisc)
    table = BumpDisc(0.15)
    registered.check_registered(table)  # the grid check cannot see it...
    named = r"table bumpdisc \(BumpDisc\): at an impact at \(x, y\) = .* its formula terms gives h = .* where the " \
            r"table's own h and grad give h = .*differ from the table between the points of the 41 x 41 grid"
    rng = np.random.default_rng(1)  # the repro's first penny (its run raised nothing: 272 impacts, ended 3 mm out)
    s0 = [rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03), 0.0, rng.uniform(-np.pi, np.pi), rng.uniform(-40, 40),
          rng.uniform(-5, 5)]
    with pytest.raises(ValueError, match=r"simulate, t = [0-9.e-]+ s: " + named):  # ...the impacts can
        pe.simulate(s0, table=table, law="elastic", t_final=3.0)
    # (the check follows the run, whatever ran it: the batch's plain-Python loop here, the compiled step below)
    with pytest.raises(ValueError, match=r"penny 0, t = [0-9.e-]+ s: " + named):
        pb.simulate(np.array([s0]), table=table, t_final=3.0, backend="python")
    for backend in ("python", "numba"):
        env = pe.PennyEnv("circle", "reach", table={"kind": "bumpdisc", "r": 0.15}, backend=backend)
        env.reset(seed=0, options={"state": s0})
        with pytest.raises(ValueError, match=r"PennyEnv.step at t = [0-9.e-]+ s: " + named):
            for _ in range(400):
                env.step(np.zeros(2, np.float32))
        vec = pe.PennyVectorEnv(2, "circle", "reach", table={"kind": "bumpdisc", "r": 0.15}, backend=backend)
        vec.reset(seed=0, options={"state": s0})
        with pytest.raises(ValueError, match=r"PennyVectorEnv.step, env [01]: " + named):
            for _ in range(400):
                vec.step(np.zeros((2, 2)))


def test_a_sound_shape_and_penny_envs_own_pass_the_impact_check(shapes, monkeypatch):
    from penny_env.physics.tables import registered
    shapes("disc", Disc)
    assert registered.audited(Disc(0.1)) and not registered.audited(pe.Ellipse(0.15, 0.2)) and not registered.audited(None)
    tr = pe.simulate([0, 0, 0, 1.0, 20.0, 0.5], table=Disc(0.1), t_final=8.0)
    assert tr.n_impacts > 10
    registered.check_impacts(Disc(0.1), tr.impact_states, tr.impact_ends, pe.PennyParams().R)  # every impact passes
    # penny_env's own shapes: never compared (nothing spent on them)
    calls = []
    monkeypatch.setattr(registered, "check_impacts", lambda *a, **k: calls.append(a))
    pe.simulate([0, 0, 0, 1.0, 20.0, 0.5], table=pe.Ellipse(0.15, 0.2), t_final=2.0)
    pb.simulate(np.array([[0, 0, 0, 1.0, 20.0, 0.5]]), table=pe.Ellipse(0.15, 0.2), t_final=2.0, backend="python")
    assert pe.PennyEnv("ellipse", "reach", backend="python")._core.audit is None and calls == []


def test_the_environments_sample_their_impacts():
    from penny_env.physics.tables.registered import AUDIT_EVERY, AUDIT_FIRST, ImpactAudit
    seen = []
    audit = ImpactAudit(None, 0.01)
    import penny_env.physics.tables.registered as registered

    def record(table, states, ends, R, where=""):
        seen.extend(states[:, 0].tolist())
    orig = registered.check_impacts
    registered.check_impacts = record
    try:
        for start in range(0, 2 * AUDIT_FIRST + 10 * AUDIT_EVERY, 7):  # steps of 7 impacts each
            states = np.zeros((7, 6))
            states[:, 0] = np.arange(start, start + 7)
            audit.check(states, np.ones(7))
    finally:
        registered.check_impacts = orig
    n = 2 * AUDIT_FIRST + 10 * AUDIT_EVERY
    assert [int(v) for v in seen if v < n] == [i for i in range(n) if i < AUDIT_FIRST or i % AUDIT_EVERY == 0]


EDITABLE_TABLE = '''
SCALE = 1.0


def disc_terms(c, x, y):
    r2, inv = c[0], c[1]
    return (x * x + y * y - r2) * 0.5 * inv, x * inv, SCALE * y * inv
'''


def _editable_disc():
    module = {"__name__": "users_tables"}
    exec(compile(EDITABLE_TABLE, "users_tables.py", "exec"), module)  # noqa: S102 (the test's own source)
    return module, variant("EditableDisc", terms=staticmethod(module["disc_terms"]))


def test_a_table_edited_after_registration_is_checked_again_on_the_plain_python_step(shapes):
    # accepted and run as registered; its module constant then edited: the plain-Python step ran the edited,
    # wrong formula (dh/dy 10 % off) with no new check
    module, cls = _editable_disc()
    shapes("editable_disc", cls)
    table = T.make_table({"kind": "editable_disc", "r": 0.1})
    start = np.array([[0, 0, 0, 1.0, 20.0, 0.5]])
    pb.simulate(start, table=table, t_final=0.5, backend="python")
    module["SCALE"] = 1.1
    with pytest.raises(ValueError, match=r"table disc \(EditableDisc\): the compiled formula terms \(as it is now: .*"
                                         r"register_table\) gives dh/dy"):
        pb.simulate(start, table=table, t_final=0.5, backend="python")


def test_a_table_edited_before_its_first_build_is_checked_on_what_the_build_compiled(shapes):
    # registered (its formulas compiled and compared then), edited before the first compiled build: the build
    # compiled the edited formula, and only the registration's copy had been compared
    pytest.importorskip("numba")
    module, cls = _editable_disc()
    shapes("editable_disc_cpu", cls)
    table = T.make_table({"kind": "editable_disc_cpu", "r": 0.1})
    start = np.array([[0, 0, 0, 1.0, 20.0, 0.5]])
    pb.simulate(start, table=table, t_final=0.5, backend="python")  # (the table checked as it was)
    module["SCALE"] = 1.1
    with pytest.raises(ValueError, match=r"the compiled formula terms \(as this build compiled it: register the table "
                                         r"again after editing its module\) gives dh/dy"):
        pb.simulate(start, table=table, t_final=0.5, backend="numba")
