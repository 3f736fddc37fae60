"""Dynamics tools of the penny, on the exact physics (DynamicalBilliards.jl's counterparts):

* :mod:`penny_env.analysis.boundary_map` - the boundary (Birkhoff) map, its tangent maps and Lyapunov spectra,
  the invariant measure's sampler;
* :mod:`penny_env.analysis.periodic_orbits` - periodic orbits of the elastic boundary map, their stability, and
  finite-time exponents on slices of the map;
* :mod:`penny_env.analysis.dynamics` - reachable sets and finite-time Lyapunov exponents of batches of pennies;
* :mod:`penny_env.analysis.impact_geometry` - the impact laws in scaled speeds (the formulas of
  docs/controllability_theory.md);
* :mod:`penny_env.analysis.controllability_theorems` - which cells and start/target pairs a theorem of
  docs/controllability_theory.md makes impossible;
* :mod:`penny_env.analysis.one_input` - the formulas of the one-input theorems T7.1 and T7.2.

The reports built on them (and the mpmath reference, the other integrators, the studies) live in the
repository's ``studies/`` folder, not in the package: ``python -m studies.<name> --help``.
"""
