"""Gymnasium environments of the controlled bouncing penny (see PennyEnv's docstring)."""
from .scene import Scene, Task, ConfigError, ConfigTypeError, resolve
from .penny_env import PennyEnv
from .vector_env import PennyVectorEnv
from .goal_env import PennyGoalEnv
from .registration import register_envs, env_ids, make_env

__all__ = ["Scene", "Task", "ConfigError", "ConfigTypeError", "resolve", "PennyEnv", "PennyGoalEnv", "PennyVectorEnv",
           "register_envs", "env_ids", "make_env"]
