"""The environment step as pure functions: its stages (functional.py), the episodes' counter-based draws
(draws.py), the tasks' registry (tasks/) and the configuration checks that scenes and tasks share
(config.py). Plain Python on floats, tuples and NamedTuples over the physics; it imports neither numba nor
Gymnasium. The backends (penny_env/backends/) compile it for the CPU and CUDA; the environments
(penny_env/envs/) run it."""
