"""Reproduce the figures of the paper's numerical section.

Figures 1-4: the first 20 impacts of the penny started at x = y = theta = 0, phi = pi/2,
theta_dot = 10, phi_dot = 0.2 on the circle (a = b = 0.2) and the ellipse (a = 0.15, b = 0.2),
with elastic and plastic impacts. Figure 5 ("hints of chaos"): 100 initial conditions whose
theta_dot and phi_dot are perturbed by less than 0.005, shown at several times (elastic ellipse),
advanced together with the batched physics.

    python -m studies.paper_figures [--quick] [--out docs/paper_figures.md]
"""
from __future__ import annotations


import numpy as np

import penny_env as pe
import penny_env.batch as pb
from lab.common import report_command

PAPER_STATE = np.array([0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2])
SCENES = [("circle", pe.Circle(0.2), "elastic"), ("circle", pe.Circle(0.2), "plastic"),
          ("ellipse", pe.Ellipse(0.15, 0.2), "elastic"), ("ellipse", pe.Ellipse(0.15, 0.2), "plastic")]


def _draw_path(ax, tr, table, params, path, lw=0.8, ms=3):
    wall = table.boundary(400)
    ax.plot(wall[:, 0], wall[:, 1], color="0.3", lw=1.2, label="table's edge")
    ax.plot(path[:, 0], path[:, 1], color="tab:blue", lw=lw, label="contact point")
    for k, (s, end) in enumerate(zip(tr.impact_states, tr.impact_ends)):
        c, sn = np.cos(s[3]), np.sin(s[3])
        ax.plot([s[0] - params.R * c, s[0] + params.R * c], [s[1] - params.R * sn, s[1] + params.R * sn],
                color="tab:red", lw=2, label="penny at an impact" if k == 0 else None)
    ends = np.asarray(tr.impact_ends)
    for sign, color, marker, label in ((1, "black", "o", "front end hits"), (-1, "tab:orange", "s", "back end hits")):
        S = np.asarray(tr.impact_states)[ends == sign] if tr.n_impacts else np.zeros((0, 6))
        ax.plot(S[:, 0] + sign * params.R * np.cos(S[:, 3]), S[:, 1] + sign * params.R * np.sin(S[:, 3]),
                marker, ms=ms, color=color, ls="none", label=label, zorder=4)


def draw_scene(ax, table, law, n_impacts=20, params=pe.PennyParams(), inset=False):
    """One of the paper's figures 1-4 on ax; inset: enlarge the impacts (they crowd where a plastic
    penny comes to rest against the wall)."""
    from matplotlib.ticker import MaxNLocator

    tr = pe.simulate(PAPER_STATE, params=params, table=table, law=law, n_impacts=n_impacts)
    path = tr.states_at(np.linspace(0.0, tr.final_time, 4000))
    _draw_path(ax, tr, table, params, path)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.xaxis.set_major_locator(MaxNLocator(5, steps=[1, 2, 5, 10]))  # readable tick labels on the narrow panels
    ax.set_title(f"{law}, {table!r}: {tr.n_impacts} impacts in {tr.final_time:.2f} s", fontsize=9)
    if inset and tr.n_impacts:
        S = np.asarray(tr.impact_states)
        pad = 2.5 * params.R
        x0, x1 = S[:, 0].min() - pad, S[:, 0].max() + pad
        y0, y1 = S[:, 1].min() - pad, S[:, 1].max() + pad
        half = 0.5 * max(x1 - x0, y1 - y0)
        cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        sub = ax.inset_axes([0.2, 0.05, 0.6, 0.42])  # the lower half: the path runs in the upper one
        _draw_path(sub, tr, table, params, path, lw=1.0, ms=5)
        sub.set_xlim(cx - half, cx + half)
        sub.set_ylim(cy - half, cy + half)
        sub.set_aspect("equal")
        sub.tick_params(labelsize=7)
        sub.xaxis.set_major_locator(MaxNLocator(4, steps=[1, 2, 5, 10]))
        sub.yaxis.set_major_locator(MaxNLocator(5, steps=[1, 2, 5, 10]))
        sub.set_title(f"enlarged ({2 * half * 100:.1f} cm across)", fontsize=8)
        ax.indicate_inset_zoom(sub, edgecolor="0.4")
    return tr


def chaos(times, n=100, seed=0, params=pe.PennyParams(), table=pe.Ellipse(0.15, 0.2)):
    """States of n perturbed copies of the paper's penny at the given times (batched)."""
    rng = np.random.default_rng(seed)
    S = np.repeat(PAPER_STATE[None, :], n, axis=0)  # rows (N, 6)
    S[:, 4] += rng.uniform(-0.005, 0.005, n)
    S[:, 5] += rng.uniform(-0.005, 0.005, n)
    out, t = [], 0.0
    for target in times:
        if target > t:
            S = pb.simulate(S, params=params, table=table, law="elastic", t_final=target - t).final_states
            t = target
        out.append(S.T.copy())  # (6, N): x = out[k][0], y = out[k][1]
    return out


def main(argv=None):
    rep = report_command("studies.paper_figures", "paper_figures.md", __doc__, argv,
                         quick="fewer impacts and pennies (for tests)")
    args = rep.args
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    n_imp = 5 if args.quick else 20
    fig, axes = plt.subplots(2, 2, figsize=(10, 10.5))
    rows = []
    for ax, (name, table, law) in zip(axes.flat, SCENES):
        tr = draw_scene(ax, table, law, n_imp, inset=law == "plastic")
        rows.append(f"| {name} | {law} | {tr.n_impacts} | {tr.impact_times[0]:.12f} | {tr.impact_times[-1]:.12f} | "
                    f"{tr.energies()[-1] / tr.energies()[0] if tr.n_impacts else 1:.6f} |")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=9)
    scenes_png = rep.figure(fig, "_scenes.png", rect=(0, 0.04, 1, 1))

    times = [0.0, 5.0, 10.0, 20.0] if not args.quick else [0.0, 2.0]
    snaps = chaos(times, n=20 if args.quick else 100)
    fig, axes = plt.subplots(1, len(times), figsize=(3.3 * len(times), 3.8), sharey=True)
    wall = pe.Ellipse(0.15, 0.2).boundary(400)
    for k, (ax, t, S) in enumerate(zip(np.atleast_1d(axes), times, snaps)):
        ax.plot(wall[:, 0], wall[:, 1], color="0.3", lw=1)
        ax.plot(S[0], S[1], ".", ms=3, color="tab:blue")
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.xaxis.set_major_locator(MaxNLocator(4, steps=[1, 2, 5, 10]))
        if k == 0:
            ax.set_ylabel("y [m]")
        spread = np.hypot(S[0] - S[0].mean(), S[1] - S[1].mean()).max() * 1e3
        ax.set_title(f"t = {t:g} s: {S.shape[1]} pennies, spread {spread:.3g} mm", fontsize=8)
    chaos_png = rep.figure(fig, "_chaos.png")

    lines = rep.header("The paper's figures, reproduced")
    lines += ["Figures 1-4 of the paper: the first impacts of the penny started at x = y = theta = 0, "
              "phi = pi/2, theta_dot = 10, phi_dot = 0.2. Red segments: the penny at each impact; "
              "black dots: front-end impacts, orange squares: back-end impacts. In the plastic panels the impacts "
              "crowd on a few centimetres of the wall; an inset enlarges them.", "",
              f"![scenes]({scenes_png.name})", "",
              "| table | law | impacts | first impact [s] | last impact [s] | energy after / before |",
              "|---|---|---|---|---|---|", *rows, "",
              "Figure 5 (hints of chaos): copies of the elastic-ellipse penny with theta_dot and phi_dot "
              "perturbed by less than 0.005, at several times (contact points; spread: the largest distance from "
              "their mean).", "", f"![chaos]({chaos_png.name})", ""]
    return rep.write(lines, echo=True)


if __name__ == "__main__":
    main()
