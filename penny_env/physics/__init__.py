"""The bouncing penny's physics: pure functions of (state, params, controls); no Gymnasium here."""
from .params import PennyParams, SolverSettings
from .tables import Table, Ellipse, Circle, Stadium, ConvexTable, make_table
from .laws import ImpactLaw, make_law, apply_law
from .flow import flow, kinetic_energy, end_kinematics
from .events import first_impact
from .advance import advance, EventLog
from .simulate import simulate, impact_map, Trajectory

__all__ = ["PennyParams", "SolverSettings", "Table", "Ellipse", "Circle", "Stadium", "ConvexTable",
           "make_table", "ImpactLaw", "make_law", "apply_law", "flow", "kinetic_energy", "end_kinematics",
           "first_impact", "advance", "EventLog", "simulate", "impact_map", "Trajectory"]
