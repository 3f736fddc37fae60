"""Nonholonomic impact laws, batched.

On the constraint distribution the velocity is (theta_dot, phi_dot) with kinetic metric
diag(I + m R^2, J). When an end (sigma = +1 front, -1 back) is on the wall with wall gradient
(hx, hy), its outward normal velocity is the linear form

    n(v) = a theta_dot + b phi_dot,  a = R (hx cos phi + hy sin phi),  b = sigma R (hy cos phi - hx sin phi).

Every law moves v along the metric gradient of n, v+ = v - k (a / (I + m R^2), b / J):

* restitution e in [0, 1]: k = (1 + e) n(v) / (a^2/(I+mR^2) + b^2/J), so n(v+) = -e n(v);
* elastic = restitution 1. This is the unique nonzero solution of the paper's system
  var_impact: the momentum jump lies in span(w1, w2, dh), v+ is on the distribution and the
  energy is kept (a reflection in the kinetic metric restricted to the distribution);
* plastic = the paper's pi_Delta o P (var_penny, then the projection pi_Delta), which works out
  to k = 2 n(v) / (|grad h|^2 / m + b^2 / J), i.e. restitution with an effective coefficient
  e_p = 2 (a^2/(I+mR^2) + b^2/J) / (|grad h|^2/m + b^2/J) - 1 in (-1, 1). e_p < 0, an end still
  moving into the wall after the impact, happens exactly when
  2 m R^2 cos^2(beta) / (I + m R^2) + m R^2 sin^2(beta) / J < 1 (beta: heading vs wall normal), so
  for I > m R^2 head-on or J > m R^2 sideways. The simulator then removes the normal velocity
  (the e = 0 law), the limit of re-applying the plastic map at the same instant. Energy never increases.

Laws are an open registry: a law is a :class:`LawRecord`, whose map is one function
``update(W, w, a, b, grad2, e, Itot, J, m) -> (W+, w+)`` of the normal form (plain math, so that
numba compiles it into the event loop), with its Jacobian (or None) and whether it conserves the
kinetic energy, registered by name with ``penny_env.register_law`` (see docs/extending.md);
``make_law(name)`` then finds it. The derivatives (physics/sensitivity.py) use the record's Jacobian
and refuse (jacobian_valid False, with the reason) a law that has none; the event loop's Zeno rule
(physics/scalar.py) reads conserves_energy.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable

import numpy as np

from .flows import PHI, THETA_DOT, PHI_DOT, end_kinematics
from .kernels import SCALAR, law_update
from .law_checks import check_law
from .numbers import is_real


def restitution_update(W, w, a, b, grad2, e, Itot, J, m):
    """Restitution e in [0, 1] (elastic: e = 1): n(v+) = -e n(v) along the metric gradient of n."""
    return law_update(W, w, a, b, grad2, e, False, Itot, J, m, SCALAR)


def plastic_update(W, w, a, b, grad2, e, Itot, J, m):
    """The paper's plastic law pi_Delta o P (e ignored)."""
    return law_update(W, w, a, b, grad2, e, True, Itot, J, m, SCALAR)


def law_jacobian(W, w, a, b, grad2, e, plastic, Itot, J, m):
    """(W+, w+) of kernels.law_update and its 2 x 5 Jacobian w.r.t. (W, w, a, b, grad2), on the branch
    law_update takes (the plastic law's sticking rule included)."""
    vn = a * W + b * w
    metric = a * a / Itot + b * b / J
    dvn = np.array([a, b, W, w, 0.0])
    dmetric = np.array([0.0, 0.0, 2.0 * a / Itot, 2.0 * b / J, 0.0])
    if plastic:
        den = grad2 / m + b * b / J
        k = 2.0 * vn / den
        dk = 2.0 * (dvn / den - vn * np.array([0.0, 0.0, 0.0, 2.0 * b / J, 1.0 / m]) / den ** 2)
        if vn > 0.0 and vn - k * metric > 0.0:  # the end would still move outward: the e = 0 law
            k = vn / metric
            dk = dvn / metric - vn * dmetric / metric ** 2
    else:
        k = (1.0 + e) * vn / metric
        dk = (1.0 + e) * (dvn / metric - vn * dmetric / metric ** 2)
    D = np.zeros((2, 5))
    D[0] = -(dk * a) / Itot
    D[0, 0] += 1.0
    D[0, 2] -= k / Itot
    D[1] = -(dk * b) / J
    D[1, 1] += 1.0
    D[1, 3] -= k / J
    return (W - k * a / Itot, w - k * b / J), D


def restitution_jacobian(W, w, a, b, grad2, e, Itot, J, m):
    """(W+, w+) of restitution_update and its 2 x 5 Jacobian w.r.t. (W, w, a, b, grad2)."""
    return law_jacobian(W, w, a, b, grad2, e, False, Itot, J, m)


def plastic_jacobian(W, w, a, b, grad2, e, Itot, J, m):
    """(W+, w+) of plastic_update and its 2 x 5 Jacobian (its sticking rule's branch included)."""
    return law_jacobian(W, w, a, b, grad2, e, True, Itot, J, m)


@dataclass(frozen=True)
class LawRecord:
    """A registered impact law: its map ``update(W, w, a, b, grad2, e, Itot, J, m) -> (W+, w+)``, the
    coefficient e it receives by default, its Jacobian ``jacobian(same arguments) -> ((W+, w+), D)``
    with D the 2 x 5 derivative of (W+, w+) w.r.t. (W, w, a, b, grad2), or None (then no derivative
    through its impacts exists: simulate(..., sensitivities=True) says so), and whether it conserves
    the kinetic energy (then an accumulation of impacts never brings the penny to rest)."""

    name: str
    update: Callable
    e: float = 1.0
    jacobian: Callable | None = None
    conserves_energy: bool = False


LAW_KINDS: dict = {}      # name -> LawRecord
COMPILED_LAWS: list = []  # the distinct update functions; Model.law indexes it
BUILTIN_LAWS = ("elastic", "restitution", "plastic")  # names no user registration may replace


def is_builtin_law(update) -> bool:
    """update is one of penny_env's own functions (compiled in the package's namespace, cached on disk)."""
    return getattr(update, "__module__", None) is not None and update.__module__.startswith("penny_env.")


def law_record(name: str, update, e: float = 1.0, *, jacobian=None, conserves_energy: bool = False) -> LawRecord:
    """The LawRecord of a law that passes the plain-Python checks (physics/law_checks.py), before it is
    registered: ``update(W, w, a, b, grad2, e, Itot, J, m) -> (W+, w+)`` (W, w: theta_dot, phi_dot before;
    n = a W + b w the end's outward normal velocity, grad2 = |grad h|^2; Itot = I + m R^2) must be plain math
    (numba compiles it into the event loop), must not increase the kinetic energy and must not leave the end
    moving outward; e is the coefficient it receives (a finite real number).
    jacobian: ``jacobian(W, w, a, b, grad2, e, Itot, J, m) -> ((W+, w+), D)`` (D: 2 x 5, derivatives
    w.r.t. (W, w, a, b, grad2)) for the sensitivities, or None (they then report jacobian_valid
    False). conserves_energy: True only for a law that keeps the kinetic energy exactly (the event
    loop then never stops an accumulation of impacts). TypeError / ValueError naming the law otherwise; the
    built-in names (BUILTIN_LAWS) are refused. Users register laws with ``penny_env.register_law``, which
    also compiles the law (backends/checks.py) and then calls :func:`add_law`."""
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"register_law: name must be an identifier, got {name!r}")
    if not callable(update):
        raise TypeError("register_law: update must be a function")
    if jacobian is not None and not callable(jacobian):
        raise TypeError("register_law: jacobian must be a function or None")
    if not isinstance(conserves_energy, bool):
        raise TypeError(f"register_law: conserves_energy must be a bool, got {type(conserves_energy).__name__}")
    if not is_real(e):
        raise TypeError(f"register_law({name!r}): e must be a real number, got {type(e).__name__} {e!r}")
    if not math.isfinite(float(e)):
        raise ValueError(f"register_law({name!r}): e must be finite, got {e!r}")
    if name.strip().lower() in BUILTIN_LAWS and not is_builtin_law(update):
        raise ValueError(f"register_law: {name!r} is a built-in law and cannot be replaced (every environment id "
                         "runs it); register yours under another name")
    check_law(name, update, float(e), conserves_energy)
    return LawRecord(name, update, float(e), jacobian, conserves_energy)


def add_law(record: LawRecord) -> None:
    """Make ``make_law(record.name)`` the law of a record that :func:`law_record` made. Registering a name again
    replaces its law for everything built afterwards (make_law, simulate, the batch API, new environments; the
    compiled code is built anew), with a UserWarning: environments and batches built before keep the law they
    were built with."""
    old = LAW_KINDS.get(record.name)
    _register(record)
    if old is not None and old != record:
        import warnings
        warnings.warn(f"register_law: {record.name!r} now names the new law for everything built from here on; "
                      "environments and batches built before keep the law they were built with (build them again)",
                      UserWarning, stacklevel=3)


def _register(record: LawRecord) -> None:
    """The record into the registry (its update function compiled once, under its index in COMPILED_LAWS)."""
    LAW_KINDS[record.name] = record
    if law_index(record.update) < 0:
        COMPILED_LAWS.append(record.update)


def law_index(update) -> int:
    """Index of a law's update function in COMPILED_LAWS, or -1."""
    for k, f in enumerate(COMPILED_LAWS):
        if f is update:
            return k
    return -1


def builtin_law_indices() -> tuple:
    """Indices in COMPILED_LAWS of penny_env's own laws: every compiled build holds them (and, besides them, only
    the one user law its Model runs: backends/physics.py's variant_key), so that a user's law never enters
    the code of an environment that does not use it."""
    return tuple(k for k, f in enumerate(COMPILED_LAWS) if is_builtin_law(f))


# (penny_env's own laws: registered without the trials, which tests/physics/test_law_checks.py runs on them)
_register(LawRecord("elastic", restitution_update, 1.0, restitution_jacobian, True))
_register(LawRecord("restitution", restitution_update, 1.0, restitution_jacobian))  # (e = 1 is "elastic")
_register(LawRecord("plastic", plastic_update, 0.0, plastic_jacobian))
# penny_env's own laws are kernels.law_update with the plastic flag off or on: COMPILED_LAWS[0] and [1]
BUILTIN_LAW_UPDATES = (restitution_update, plastic_update)
PLASTIC_LAW = 1
assert tuple(COMPILED_LAWS) == BUILTIN_LAW_UPDATES


@dataclass(frozen=True)
class ImpactLaw:
    """An impact law: a registered kind ("elastic", "plastic", "restitution" with coefficient e, ...)."""

    kind: str
    e: float = 1.0

    def __str__(self) -> str:
        return self.kind if self.kind != "restitution" else f"restitution(e={self.e:g})"

    @property
    def record(self) -> LawRecord:
        """The law's registered LawRecord."""
        return LAW_KINDS[self.kind]

    @property
    def update(self):
        """The law's registered update function."""
        return self.record.update

    @property
    def conserves_energy(self) -> bool:
        """The record's conserves_energy (restitution with e = 1 too, however it was built)."""
        return self.record.conserves_energy or (self.record.update is restitution_update and self.e == 1.0)


def make_law(law) -> ImpactLaw:
    """Parse a law: "elastic", "plastic", a float restitution coefficient e in [0, 1], or an ImpactLaw."""
    if isinstance(law, ImpactLaw):
        return law
    if isinstance(law, str):
        if law in LAW_KINDS and law not in BUILTIN_LAWS:  # a registered name as given (names are case-sensitive)
            return ImpactLaw(law, LAW_KINDS[law].e)
        key = law.strip().lower()
        if key == "elastic":
            return ImpactLaw("elastic", 1.0)
        if key == "plastic":
            return ImpactLaw("plastic", 0.0)
        if key in LAW_KINDS and key != "restitution":
            return ImpactLaw(key, LAW_KINDS[key].e)
        raise ValueError(f"law must be one of {sorted(k for k in LAW_KINDS if k != 'restitution')} or a restitution "
                         f"coefficient in [0, 1], got {law!r}")
    if isinstance(law, bool) or not isinstance(law, (int, float, np.integer, np.floating)):
        raise TypeError(f"law must be 'elastic', 'plastic' or a float in [0, 1], got {type(law).__name__}")
    e = float(law)
    if not math.isfinite(e) or not 0.0 <= e <= 1.0:
        raise ValueError(f"law: restitution coefficient must be in [0, 1], got {law!r}")
    return ImpactLaw("elastic", 1.0) if e == 1.0 else ImpactLaw("restitution", e)


def normal_form(s, sigma, params, table):
    """(a, b, |grad h|^2) of the normal-velocity form of end sigma for (6, N) states."""
    px, py, _, _ = end_kinematics(s, sigma, params.R)
    hx, hy = table.grad(px, py)
    c, sn = np.cos(s[PHI]), np.sin(s[PHI])
    a = params.R * (hx * c + hy * sn)
    b = sigma * params.R * (hy * c - hx * sn)
    return a, b, hx * hx + hy * hy


def apply_law(s, sigma, params, table, law: ImpactLaw):
    """Post-impact states (a new (6, N) array) for end sigma (scalar or (N,) array of +-1)."""
    s = np.asarray(s, dtype=float)
    a, b, g2 = normal_form(s, sigma, params, table)
    out = s.copy()
    if law.kind not in ("elastic", "restitution", "plastic"):  # a registered law: its scalar function
        a, b, g2 = (np.broadcast_to(v, s.shape[1:]) for v in (a, b, g2))
        for i in range(s.shape[1]):
            out[THETA_DOT, i], out[PHI_DOT, i] = law.update(s[THETA_DOT, i], s[PHI_DOT, i], a[i], b[i], g2[i], law.e,
                                                            params.rolling_inertia, params.J, params.m)
        return out
    out[THETA_DOT], out[PHI_DOT] = law_update(s[THETA_DOT], s[PHI_DOT], a, b, g2, law.e, law.kind == "plastic",
                                              params.rolling_inertia, params.J, params.m)
    return out
