"""Gymnasium environments of the controlled bouncing penny (see PennyEnv's docstring)."""
from .scene import Scene, Task, ConfigError, ConfigTypeError, resolve
from .penny_env import PennyEnv
from .vector_env import PennyVectorEnv
from .registration import register_envs, env_ids

__all__ = ["Scene", "Task", "ConfigError", "ConfigTypeError", "resolve", "PennyEnv", "PennyVectorEnv", "register_envs", "env_ids"]
