"""The bouncing penny's physics: pure functions of (state, params, controls); no Gymnasium here."""
from .params import PennyParams, SolverSettings
from .tables import Table, Ellipse, Circle, Stadium, RoundedRectangle, ConvexTable, make_table
from .laws import ImpactLaw, make_law, apply_law
from .flows import flow, kinetic_energy, end_kinematics
from .simulation import simulate, impact_map, Trajectory

__all__ = ["PennyParams", "SolverSettings", "Table", "Ellipse", "Circle", "Stadium", "RoundedRectangle",
           "ConvexTable", "make_table", "ImpactLaw", "make_law", "apply_law",
           "flow", "kinetic_energy", "end_kinematics", "simulate",
           "impact_map", "Trajectory"]
