"""The tasks: a registry of records (base.py), one module per task (reach, park, impacts). See base.py for
what a task is, and docs/extending.md to add one."""
from .base import TASKS, Task, TaskRecord, all_config_fields, config_fields, register_task, task_record
from . import reach, park, impacts  # noqa: F401  (they register the built-in tasks)
from .reach import ReachTask
from .park import ParkTask
from .impacts import ImpactsTask

__all__ = ["TASKS", "Task", "TaskRecord", "register_task", "task_record", "config_fields", "all_config_fields",
           "ReachTask", "ParkTask", "ImpactsTask"]
