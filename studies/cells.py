"""The cells of the controllability studies, named as in docs/witnesses.csv: (probe, table, law) and the env id
and field overrides that make each one (the registered probe id where there is one)."""
from __future__ import annotations

PROBES = ("Steer", "Drive", "Both")
TABLES = ("plane", "ellipse", "stadium", "circle", "rounded_rectangle")
TABLE_NAMES = {"plane": "Plane", "ellipse": "Ellipse", "stadium": "Stadium", "circle": "Circle",
               "rounded_rectangle": "RoundedRectangle"}
# tables no preset names (scene field overrides), run with the steer-only probe and e = 0.5 walls
EXTRA_TABLES = {"circle_r0.5": {"kind": "circle", "radius": 0.5}, "circle_r0.35": {"kind": "circle", "radius": 0.35}}
EXTRA_NAMES = {"circle_r0.5": "Circle r = 0.5 m", "circle_r0.35": "Circle r = 0.35 m"}
EXTRA_CELLS = (("Steer", "circle_r0.5", "0.5"), ("Steer", "circle_r0.35", "0.5"))
ALL_TABLES = TABLES + tuple(EXTRA_TABLES)
LAWS = {"elastic": "Elastic", "plastic": "Plastic", "0.5": "E05"}  # law value (as in ids' YAML) -> id suffix
PROBE_TASKS = {"Steer": "steer only, park", "Drive": "drive only, reach", "Both": "both controls, park"}

def law_value(law: str):
    return float(law) if law[0].isdigit() else law


def cell_spec(probe: str, table: str, law: str) -> tuple[str, dict]:
    """(env id, field overrides) of a cell: the registered probe id where there is one (plane, ellipse and
    stadium with the three laws), else the ellipse elastic id with scene and law overridden."""
    import gymnasium as gym
    import penny_env  # noqa: F401

    if table == "plane":
        return f"PennyProbe{probe}-Plane-v0", {}
    if table in EXTRA_TABLES:
        return f"PennyProbe{probe}-Ellipse-Elastic-v0", {"table": dict(EXTRA_TABLES[table]), "law": law_value(law)}
    env_id = f"PennyProbe{probe}-{TABLE_NAMES[table]}-{LAWS[law]}-v0"
    if env_id in gym.registry:
        return env_id, {}
    return f"PennyProbe{probe}-Ellipse-Elastic-v0", {"scene": table, "law": law_value(law)}


def all_cells():
    return [(p, t, "-" if t == "plane" else law) for p in PROBES for t in TABLES
            for law in (("-",) if t == "plane" else LAWS)] + list(EXTRA_CELLS)


def table_name(table: str) -> str:
    return TABLE_NAMES.get(table) or EXTRA_NAMES[table]
