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
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .flow import PHI, THETA_DOT, PHI_DOT, end_kinematics
from .kernels import law_update


@dataclass(frozen=True)
class ImpactLaw:
    """An impact law: kind "elastic", "plastic" or "restitution" (coefficient e)."""

    kind: str
    e: float = 1.0

    def __str__(self) -> str:
        return self.kind if self.kind != "restitution" else f"restitution(e={self.e:g})"


def make_law(law) -> ImpactLaw:
    """Parse a law: "elastic", "plastic", a float restitution coefficient e in [0, 1], or an ImpactLaw."""
    if isinstance(law, ImpactLaw):
        return law
    if isinstance(law, str):
        key = law.strip().lower()
        if key == "elastic":
            return ImpactLaw("elastic", 1.0)
        if key == "plastic":
            return ImpactLaw("plastic", 0.0)
        raise ValueError(f"law must be 'elastic', 'plastic' or a restitution coefficient in [0, 1], got {law!r}")
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
    out[THETA_DOT], out[PHI_DOT] = law_update(s[THETA_DOT], s[PHI_DOT], a, b, g2, law.e, law.kind == "plastic",
                                              params.rolling_inertia, params.J, params.m)
    return out
