"""The paper's figures (Wei et al. 2022, Figs. 7-13) for one interpolated curve, on one PNG.

The only module that imports matplotlib (the optional `plot` extra); `cli.plot` imports it when
the command runs. It draws on an Agg canvas of its own: no display, no pyplot global state.

Panels: the path coloured by the planned feed with the key points marked by kind; then over time
the feed (planned, and actual = chord / T), tangential and normal acceleration, tangential and
normal jerk, chord error and feed fluctuation, each with its limit as a dashed red line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from nurbsfeed.analysis import PAPER_TABLE2, RunSeries
from nurbsfeed.files import atomic_output
from nurbsfeed.interpolate.stepping import Interpolation
from nurbsfeed.planning.plan import KIND_NAMES, Plan

LIMIT_STYLE = {"color": "tab:red", "linestyle": "--", "linewidth": 1.2}
KIND_MARKERS = {"end": ("s", "black"), "peak": ("^", "tab:red"), "corner": ("X", "black"),
                "cusp": ("P", "black"), "feed": ("D", "tab:blue"), "hold": ("o", "tab:orange")}
DPI = 110
LEGEND_HEADROOM = 1.3  # the y axis reaches this far above the limit: the legend sits there


def _limit(ax, value: float, label: str, symmetric: bool = False) -> None:
    """The limit as a dashed line (both signs if symmetric), with room above it for the legend."""
    ax.axhline(value, label=label, **LIMIT_STYLE)
    bottom, top = ax.get_ylim()
    if symmetric:
        ax.axhline(-value, **LIMIT_STYLE)
        bottom = min(bottom, -1.1 * value)
    ax.set_ylim(bottom, max(top, LEGEND_HEADROOM * value))


def _finish(ax, ylabel: str, title: str) -> None:
    ax.set_title(title, fontsize=11, loc="left")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)


def plot_run(target: Path, plan: Plan, result: Interpolation, series: RunSeries,
             machine_name: str) -> None:
    """Write the figure of one run to `target` (PNG, written atomically)."""
    lim = plan.limits
    u = "mm"  # every length below, an inch program's too (CurveBlock.in_mm)
    fig = Figure(figsize=(15, 17), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    (path_ax, feed_ax), (at_ax, an_ax), (jt_ax, jn_ax), (chord_ax, ff_ax) = fig.subplots(4, 2)
    t, tm = series.t_s, series.t_mid_s

    # path, coloured by the planned feed, with the key points
    xy = result.points[:, :2]
    segments = np.stack([xy[:-1], xy[1:]], axis=1)
    lines = LineCollection(list(segments), cmap="viridis", linewidths=2.0)
    lines.set_array(0.5 * (series.planned_v_mm_s[:-1] + series.planned_v_mm_s[1:]))
    path_ax.add_collection(lines)
    fig.colorbar(lines, ax=path_ax, label=f"planned feed [{u}/s]", shrink=0.85)
    kinds = [KIND_NAMES[int(k)] for k in series.key_kind]
    for kind in KIND_MARKERS:
        chosen = [i for i, name in enumerate(kinds) if name == kind]
        if chosen:
            marker, colour = KIND_MARKERS[kind]
            path_ax.scatter(series.key_points[chosen, 0], series.key_points[chosen, 1],
                            marker=marker, color=colour, s=36, zorder=3,
                            label=f"{kind} key points ({len(chosen)})")
    path_ax.autoscale()
    path_ax.set_aspect("equal", adjustable="datalim")
    path_ax.set_xlabel(f"x [{u}]")
    path_ax.set_ylabel(f"y [{u}]")
    flat = np.ptp(result.points[:, 2]) == 0.0
    path_ax.set_title("path and key points" + ("" if flat else " (x-y projection)"),
                      fontsize=11, loc="left")
    path_ax.grid(True, alpha=0.3)
    path_ax.legend(loc="best", fontsize=8, framealpha=0.9)

    feed_ax.plot(t, series.planned_v_mm_s, color="tab:blue", linewidth=3.0, alpha=0.4,
                 label="planned")
    feed_ax.plot(tm, series.chord_v_mm_s, color="tab:orange", linewidth=0.8,
                 label="actual: chord / T")
    cap = series.feed_cap_mm_s
    if np.all(cap == lim.feed_mm_s):
        _limit(feed_ax, lim.feed_mm_s, f"max feed {lim.feed_mm_s:g} {u}/s")
    else:
        feed_ax.plot(t, cap, drawstyle="steps-post", label=f"min(max feed {lim.feed_mm_s:g}, "
                     f"programmed F) {u}/s", **LIMIT_STYLE)
        feed_ax.set_ylim(top=LEGEND_HEADROOM * float(cap.max()))
    _finish(feed_ax, f"feed [{u}/s]", "feed")

    at_ax.plot(t, series.tangential_acc_mm_s2, color="tab:blue", linewidth=1.0, label="planned")
    _limit(at_ax, lim.acc_mm_s2, f"limit ±{lim.acc_mm_s2:g} {u}/s²", symmetric=True)
    _finish(at_ax, f"acceleration [{u}/s²]", "tangential acceleration")

    an_ax.plot(t, series.normal_acc_mm_s2, color="tab:green", linewidth=1.0, label="v² κ")
    _limit(an_ax, lim.normal_acc_mm_s2, f"limit {lim.normal_acc_mm_s2:g} {u}/s²")
    _finish(an_ax, f"acceleration [{u}/s²]", "normal acceleration")

    jt_ax.plot(t, series.tangential_jerk_mm_s3, color="tab:blue", linewidth=0.7,
               drawstyle="steps-post", label="planned")
    _limit(jt_ax, lim.jerk_mm_s3, f"limit ±{lim.jerk_mm_s3:g} {u}/s³", symmetric=True)
    _finish(jt_ax, f"jerk [{u}/s³]", "tangential jerk")

    jn_ax.plot(t, series.normal_jerk_mm_s3, color="tab:green", linewidth=1.0, label="v³ κ²")
    _limit(jn_ax, lim.normal_jerk_mm_s3, f"limit {lim.normal_jerk_mm_s3:g} {u}/s³")
    _finish(jn_ax, f"jerk [{u}/s³]", "normal jerk")

    micro = "µm"
    chord_ax.plot(tm, 1e3 * series.chord_error_mm, color="tab:purple", linewidth=0.8,
                  label="chord error on the true curve")
    chord_ax.set_ylim(bottom=0.0)
    _limit(chord_ax, 1e3 * lim.chord_mm, f"limit {1e3 * lim.chord_mm:g} {micro}")
    _finish(chord_ax, f"chord error [{micro}]", "chord error")

    ff = series.feed_fluctuation_pct
    shown = np.where(ff > 0.0, ff, np.nan)
    ff_ax.semilogy(tm, shown, color="tab:brown", linewidth=0.6,
                   label=f"{result.method}: max {np.nanmax(ff):.3g} %, mean {np.nanmean(ff):.3g} %")
    paper = PAPER_TABLE2[result.method][0]
    ff_ax.axhline(paper, label=f"paper Table 2 max ({result.method}) {paper:g} %", **LIMIT_STYLE)
    ff_ax.set_ylim(top=100.0 * paper)
    _finish(ff_ax, "feed fluctuation [%]", "feed fluctuation | |ΔP| − Δs | / Δs")

    fig.suptitle(f"{plan.curve.name or 'curve'} — {result.method} — cycle "
                 f"{plan.cycle_time_s:.3f} s, {result.n_points:,} points, T = "
                 f"{lim.period_s * 1e3:g} ms, length {plan.length_mm:.3f} {u}, "
                 f"machine {machine_name}", fontsize=14)
    with atomic_output(target) as out:
        fig.savefig(out, format="png", dpi=DPI)
