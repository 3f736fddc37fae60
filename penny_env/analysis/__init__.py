"""Accuracy, speed and dynamics analysis of penny_env: reference data, other integrators, reports.

Modules (each report is a command, ``python -m penny_env.analysis.<name> --help``):

* :mod:`penny_env.analysis.reference`  - the mpmath reference data (reference_data/, made by
  tests/reference/make_reference.py) as float64 numpy;
* :mod:`penny_env.analysis.integrators` - scipy ``solve_ivp`` hybrid integrator and fixed-step RK4 with a
  linear event locator (the impact maps are penny_env's, only the integration differs);
* :mod:`penny_env.analysis.matching`   - impact matching (found / missed / spurious) and error measures;
* :mod:`penny_env.analysis.bench_solvers`  - speed and accuracy against solve_ivp (DOP853) on the paper's scenes;
* :mod:`penny_env.analysis.work_precision` - work-precision diagram over several methods and scenes;
* :mod:`penny_env.analysis.stability`  - stress cases with pass/fail;
* :mod:`devtools.throughput` - environment steps per second next to Gymnasium's own environments;
* :mod:`penny_env.analysis.paper_figures` - the paper's figures;
* :mod:`penny_env.analysis.dynamics`   - reachable sets and Lyapunov exponents of batches of pennies;
* :mod:`penny_env.analysis.controllability` - does controllability of the penny need impacts? (sampled reachable sets).
* :mod:`penny_env.analysis.impact_geometry` - the impact laws in scaled speeds and the formulas of docs/controllability_theory.md.
* :mod:`penny_env.analysis.controllability_theorems` - which probe cells and start/target pairs a theorem makes impossible.

scipy, matplotlib and tqdm are imported only inside these modules (never at ``import penny_env``).
"""
