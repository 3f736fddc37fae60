"""The tasks: a registry of records (base.py), one module per task (reach, park, impacts). See base.py for
what a task is, and docs/extending.md to add one."""
from .base import TASKS, Task, TaskRecord, add_task, all_config_fields, check_task, config_fields, task_record
from . import reach, park, impacts  # noqa: F401  (they register the built-in tasks)
from .reach import ReachTask
from .park import ParkTask
from .impacts import ImpactsTask

__all__ = ["TASKS", "Task", "TaskRecord", "add_task", "check_task", "task_record", "config_fields", "all_config_fields",
           "ReachTask", "ParkTask", "ImpactsTask"]
