"""Reproduce the figures of the paper's numerical section.

Figures 1-4: the first 20 impacts of the penny started at x = y = theta = 0, phi = pi/2,
theta_dot = 10, phi_dot = 0.2 on the circle (a = b = 0.2) and the ellipse (a = 0.15, b = 0.2),
with elastic and plastic impacts. Figure 5 ("hints of chaos"): 100 initial conditions whose
theta_dot and phi_dot are perturbed by less than 0.005, shown at several times (elastic ellipse),
advanced together with the batched physics.

    python -m penny_env.analysis.paper_figures [--quick] [--out docs/paper_figures.md]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import penny_env as pe
from penny_env.physics import advance, make_law
from penny_env.physics.params import SolverSettings
from penny_env.analysis.common import header, report_path

PAPER_STATE = np.array([0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2])
SCENES = [("circle", pe.Circle(0.2), "elastic"), ("circle", pe.Circle(0.2), "plastic"),
          ("ellipse", pe.Ellipse(0.15, 0.2), "elastic"), ("ellipse", pe.Ellipse(0.15, 0.2), "plastic")]


def draw_scene(ax, table, law, n_impacts=20, params=pe.PennyParams()):
    tr = pe.simulate(PAPER_STATE, params=params, table=table, law=law, n_impacts=n_impacts)
    wall = table.boundary(400)
    ax.plot(wall[:, 0], wall[:, 1], color="0.3", lw=1.2)
    path = tr.states_at(np.linspace(0.0, tr.final_time, 4000))
    ax.plot(path[:, 0], path[:, 1], color="tab:blue", lw=0.8, label="contact point")
    for s, end in zip(tr.impact_states, tr.impact_ends):
        c, sn = np.cos(s[3]), np.sin(s[3])
        ax.plot([s[0] - params.R * c, s[0] + params.R * c], [s[1] - params.R * sn, s[1] + params.R * sn],
                color="tab:red", lw=2)
        px, py = s[0] + end * params.R * c, s[1] + end * params.R * sn
        ax.plot(px, py, "o", ms=3, color="black" if end > 0 else "tab:orange")
    ax.set_aspect("equal")
    ax.set_title(f"{law}, {table!r}: {tr.n_impacts} impacts in {tr.final_time:.2f} s", fontsize=8)
    return tr


def chaos(times, n=100, seed=0, params=pe.PennyParams(), table=pe.Ellipse(0.15, 0.2)):
    """States of n perturbed copies of the paper's penny at the given times (batched)."""
    rng = np.random.default_rng(seed)
    S = np.repeat(PAPER_STATE[:, None], n, axis=1)
    S[4] += rng.uniform(-0.005, 0.005, n)
    S[5] += rng.uniform(-0.005, 0.005, n)
    out, t = [], 0.0
    law, settings = make_law("elastic"), SolverSettings()
    for target in times:
        if target > t:
            S, _, _ = advance(S, 0.0, 0.0, target - t, params, table, law, settings)
            t = target
        out.append(S.copy())
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer impacts and pennies (for tests)")
    ap.add_argument("--out", default=None,
                    help="Markdown report; PNGs go next to it (default: docs/paper_figures.md under the working directory; --quick: a new temporary directory)")
    args = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = report_path(args.out, args.quick, "paper_figures.md")
    out.parent.mkdir(parents=True, exist_ok=True)
    n_imp = 5 if args.quick else 20
    fig, axes = plt.subplots(2, 2, figsize=(9, 9))
    rows = []
    for ax, (name, table, law) in zip(axes.flat, SCENES):
        tr = draw_scene(ax, table, law, n_imp)
        rows.append(f"| {name} | {law} | {tr.n_impacts} | {tr.impact_times[0]:.12f} | {tr.impact_times[-1]:.12f} | "
                    f"{tr.energies()[-1] / tr.energies()[0] if tr.n_impacts else 1:.6f} |")
    fig.tight_layout()
    scenes_png = out.with_name(out.stem + "_scenes.png")
    fig.savefig(scenes_png, dpi=110)
    plt.close(fig)

    times = [0.0, 5.0, 10.0, 20.0] if not args.quick else [0.0, 2.0]
    snaps = chaos(times, n=20 if args.quick else 100)
    fig, axes = plt.subplots(1, len(times), figsize=(3.2 * len(times), 3.4))
    wall = pe.Ellipse(0.15, 0.2).boundary(400)
    for ax, t, S in zip(np.atleast_1d(axes), times, snaps):
        ax.plot(wall[:, 0], wall[:, 1], color="0.3", lw=1)
        ax.plot(S[0], S[1], ".", ms=3)
        ax.set_aspect("equal")
        ax.set_title(f"t = {t:g} s, spread {np.hypot(S[0] - S[0].mean(), S[1] - S[1].mean()).max() * 1e3:.2g} mm",
                     fontsize=8)
    fig.tight_layout()
    chaos_png = out.with_name(out.stem + "_chaos.png")
    fig.savefig(chaos_png, dpi=110)
    plt.close(fig)

    lines = header("The paper's figures, reproduced", "penny_env.analysis.paper_figures", argv or sys.argv[1:])
    lines += ["Figures 1-4 of the paper: the first impacts of the penny started at x = y = theta = 0, "
              "phi = pi/2, theta_dot = 10, phi_dot = 0.2. Red segments: the penny at each impact; "
              "black dots: front-end impacts, orange: back-end impacts.", "",
              f"![scenes]({scenes_png.name})", "",
              "| table | law | impacts | first impact [s] | last impact [s] | energy after / before |",
              "|---|---|---|---|---|---|", *rows, "",
              "Figure 5 (hints of chaos): copies of the elastic-ellipse penny with theta_dot and phi_dot "
              "perturbed by less than 0.005, at several times.", "", f"![chaos]({chaos_png.name})", ""]
    out.write_text("\n".join(lines))
    print("\n".join(lines))
    print(f"wrote {out}, {scenes_png} and {chaos_png}")
    return out


if __name__ == "__main__":
    main()
