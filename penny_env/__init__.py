"""penny_env: an exact event-driven simulator of the bouncing penny and Gymnasium environments on it."""
from .physics import (PennyParams, SolverSettings, Table, Ellipse, Circle, Stadium, RoundedRectangle, ConvexTable,
                      simulate, impact_map, Trajectory)
from .registries import register_law, register_table, register_task
from .envs import PennyEnv, PennyGoalEnv, PennyVectorEnv, register_envs, make_env
from . import batch  # penny_env.batch after `import penny_env` (the physics it uses is imported above anyway)

__version__ = "0.1.0"
__all__ = ["PennyParams", "SolverSettings", "Table", "Ellipse", "Circle", "Stadium", "RoundedRectangle", "ConvexTable",
           "register_table", "register_law", "register_task", "simulate", "impact_map", "Trajectory", "PennyEnv",
           "PennyGoalEnv", "PennyVectorEnv", "register_envs", "make_env", "batch"]


# the Gymnasium ids (penny_env/presets/envs.yaml): gymnasium.make("penny_env:PennyReach-Ellipse-v0") works
register_envs()
