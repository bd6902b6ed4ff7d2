"""Figures of calibrations and reproductions.

Each function returns a matplotlib Figure built without pyplot, so no global backend or
figure registry is touched; :func:`png_bytes` renders one to PNG.
"""

from __future__ import annotations

import io

import numpy as np


def new_figure(width: float, height: float, ncols: int = 1):
    """A Figure and its axes, outside pyplot's registry."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    axes = fig.subplots(1, ncols)
    return fig, axes


def png_bytes(fig) -> bytes:
    """The figure as PNG; a figure laid out by its engine is drawn once (a tight bounding box would
    draw it twice to measure it)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches=None if fig.get_layout_engine() is not None else "tight")
    return buf.getvalue()


def save_png(fig, path) -> None:
    from ..io.atomic import atomic_write

    atomic_write(path, png_bytes(fig))


def _log_axis(axis, values=None) -> None:
    """Readable log ticks: 1-2-5 steps with plain numbers over up to three decades, else
    decades labelled 10ⁿ."""
    from matplotlib.ticker import FuncFormatter, LogFormatterSciNotation, LogLocator, NullFormatter

    v = None if values is None else np.asarray(values, float)
    v = None if v is None else v[np.isfinite(v) & (v > 0)]
    if v is not None and v.size and np.log10(v.max() / v.min()) <= 3:
        axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        axis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
    else:
        axis.set_major_locator(LogLocator(base=10, numticks=8))
        axis.set_major_formatter(LogFormatterSciNotation())
    axis.set_minor_formatter(NullFormatter())


def convergence(histories: dict[str, np.ndarray], title: str, ylabel: str = "best objective",
                xlabel: str = "iteration", marks: dict[float, str] | None = None):
    """Best objective against iteration, log scale, one line per method; the y label carries the
    unit; ``marks``: x positions → labels of vertical lines (where a phase starts)."""
    fig, ax = new_figure(7, 4)
    for x, text in (marks or {}).items():
        ax.axvline(x, color="0.5", ls="--", lw=1.0)
        ax.annotate(text, (x, 1.0), xycoords=("data", "axes fraction"), xytext=(4, -12), textcoords="offset points",
                    fontsize=8, color="0.3")
    for name, h in histories.items():
        h = np.asarray(h, dtype=float)
        if h.size == 0:
            continue
        ax.plot(np.arange(h.size), np.maximum(h, 1e-300), label=name, lw=1.4)
    ax.set_yscale("log")
    _log_axis(ax.yaxis, np.concatenate([np.ravel(h) for h in histories.values()]))
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend()
    return fig


def convergence_phases(phases: list[tuple[str, np.ndarray]], title: str, ylabel: str, xlabel: str):
    """One panel per phase of a fit (the data alone, then with the prior), each its objective against
    the evaluations on its own log scale: two phases weigh their χ² differently, so one axis would show
    a step that is no divergence."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    phases = [(label, np.asarray(h, float)) for label, h in phases if np.size(h)]
    fig = Figure(figsize=(7 if len(phases) == 1 else 10, 4), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(phases)))
    start = 0
    for ax, (label, h) in zip(axes, phases):
        x = start + np.arange(h.size)
        ax.plot(x, np.maximum(h, 1e-300), lw=1.4, marker="o", ms=3)
        ax.set_yscale("log")
        _log_axis(ax.yaxis, h)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel(xlabel)
        ax.set_title(label, fontsize=10)
        ax.grid(True, which="major", alpha=0.3)
        start += h.size
    axes[0].set_ylabel(ylabel)
    fig.suptitle(title)
    return fig


def iteration_label(methods) -> str:
    """What one step of the x axis is: swarm generations, LM residual evaluations, or both."""
    from ..calibration.registry import METHODS

    swarm = any(METHODS[m].swarm is not None for m in methods)
    lm = any(METHODS[m].least_squares for m in methods)
    if swarm and lm:
        return "iteration (swarms: generation; LM: residual evaluation)"
    return "residual evaluation" if lm else "generation"


def error_distribution(errors: dict[str, np.ndarray], title: str, unit: str = "mm"):
    """Empirical distribution (ECDF) of position errors |δp| in mm (or reprojection errors in px,
    ``unit``), one curve per set, log x axis: before and after calibration differ by orders of
    magnitude, and 500 poses stay readable."""
    fig, ax = new_figure(7, 4)
    for (label, e), color in zip(errors.items(), ("tab:red", "tab:blue", "tab:green", "tab:purple", "tab:gray")):
        e = np.sort(np.maximum(np.asarray(e, float), 1e-9))
        ax.step(e, np.arange(1, e.size + 1) / e.size, where="post", color=color,
                label=f"{label}: median {np.median(e):.3g}, 95 % {np.percentile(e, 95):.3g} {unit}")
    ax.set_xscale("log")
    _log_axis(ax.xaxis, np.concatenate([np.ravel(e) for e in errors.values()]))
    ax.set_xlabel("reprojection error |δuv| (px)" if unit == "px" else "position error |δp| (mm)")
    ax.set_ylabel("fraction of poses with smaller error")
    ax.set_ylim(0, 1.02)
    ax.set_title(title)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncols=2, frameon=False)
    return fig


#: the colour scale of an error map runs to this percentile of its values; points above it are
#: drawn as outliers (ringed, in the top colour), so that one far pose does not darken every other
ROBUST_PERCENTILE = 98.0


#: values up to this factor above the percentile are no outliers: the scale then runs to the largest
OUTLIER_FACTOR = 1.25


def robust_limit(values: np.ndarray) -> float:
    """The top of a colour scale for ``values``: their :data:`ROBUST_PERCENTILE`th percentile
    where the largest lies more than :data:`OUTLIER_FACTOR` above it, else the largest (also
    for fewer than 50 values)."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 1.0
    top = float(np.percentile(v, ROBUST_PERCENTILE)) if v.size >= 50 else float(v.max())
    if top <= 0 or v.max() <= OUTLIER_FACTOR * top:  # no value far above the rest: the whole range
        return float(v.max()) or 1.0
    return top


def workspace_errors(points: np.ndarray, errors: np.ndarray, title: str, label: str = "|δp| (mm)",
                     from_zero: bool = True):
    """Where in the workspace the error is: the points (mm) projected on XY, XZ and YZ, coloured
    by a value per point (|δp| mm, or another ``label``).  The colour scale runs to a robust
    limit (:func:`robust_limit`); the points above it are ringed and counted in the legend.
    ``from_zero=False``: it starts at the mirror percentile, so that values that all lie well above
    zero (an uncertainty map) are told apart."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    fig = Figure(figsize=(14, 4.4), layout="constrained")
    axes = fig.subplots(1, 3)
    vmax = robust_limit(errors)
    vmin = 0.0 if from_zero else min(float(np.percentile(errors, 100.0 - ROBUST_PERCENTILE)), vmax)
    vmax = vmax if vmax > vmin else vmin + 1e-12
    order = np.argsort(errors)  # the largest drawn last, on top
    points, errors = np.asarray(points)[order], np.asarray(errors)[order]
    above = errors > vmax
    for ax, (i, j) in zip(axes, ((0, 1), (0, 2), (1, 2))):
        sc = ax.scatter(points[:, i], points[:, j], c=np.clip(errors, vmin, vmax), s=10, cmap="viridis", vmin=vmin,
                        vmax=vmax)
        if above.any():
            ax.scatter(points[above, i], points[above, j], s=46, facecolors="none", edgecolors="tab:red",
                       linewidths=1.2, label=f"{int(above.sum())} above {vmax:.3g} (up to {errors.max():.3g})")
        ax.set_xlabel(f"{'xyz'[i]} (mm)")
        ax.set_ylabel(f"{'xyz'[j]} (mm)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.yaxis.set_major_locator(MaxNLocator(5))
        ax.grid(True, alpha=0.3)
    if above.any():
        axes[0].legend(fontsize=8, loc="best")
    low = f"{100 - ROBUST_PERCENTILE:g}nd"
    scale = f", scale from the {low} to the {ROBUST_PERCENTILE:g}th percentile" if not from_zero else \
        f", scale to the {ROBUST_PERCENTILE:g}th percentile" if above.any() else ""
    fig.colorbar(sc, ax=list(axes), label=label + scale, shrink=0.9)
    fig.suptitle(title)
    return fig


def residual_vs_joints(q: np.ndarray, errors: np.ndarray, title: str, bins: int = 12,
                       others: dict[str, np.ndarray] | None = None, ylabel: str = "|δp| (mm)"):
    """|δp| (mm) against each joint angle (deg), with the median per angle bin: a pattern here
    is what geometry leaves to compliance or gear errors.  others: further models' |δp| on the
    same poses, drawn as their medians only."""
    n = q.shape[1]
    cols = min(n, 3)
    rows = -(-n // cols)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.2 * cols, 3.0 * rows))
    axes = np.atleast_1d(fig.subplots(rows, cols, sharey=True)).ravel()
    for i in range(n):
        ax = axes[i]
        deg = np.degrees(q[:, i])
        ax.scatter(deg, errors, s=5, alpha=0.4, color="tab:blue")
        edges = np.linspace(deg.min(), deg.max(), bins + 1)
        idx = np.clip(np.digitize(deg, edges) - 1, 0, bins - 1)
        med = [np.median(errors[idx == b]) if np.any(idx == b) else np.nan for b in range(bins)]
        centres = 0.5 * (edges[1:] + edges[:-1])
        ax.plot(centres, med, color="tab:red", lw=1.5, label="median")
        for (label, other), colour in zip((others or {}).items(), ("tab:green", "tab:purple", "tab:orange")):
            ax.plot(centres, [np.median(other[idx == b]) if np.any(idx == b) else np.nan for b in range(bins)],
                    color=colour, lw=1.5, label=f"median, {label}")
        ax.set_xlabel(f"q{i + 1} (deg)")
        ax.grid(True, alpha=0.3)
        if i % cols == 0:
            ax.set_ylabel(ylabel)
    for ax in axes[n:]:
        ax.set_visible(False)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def _round_down(value: float) -> float:
    """The largest of 1, 2, 5 × a power of ten at most ``value`` (> 0)."""
    power = 10 ** np.floor(np.log10(value))
    return float(power * max(f for f in (1, 2, 5) if f * power <= value * (1 + 1e-12)))


def image_planes(views: list[dict], title: str):
    """What each camera saw, on its image (px; y down as the image has it): each row's measured pixel
    coloured by the calibrated model's reprojection error, and that error drawn as an arrow from it,
    magnified to be seen (a legend arrow says by how much); the image's cells no row fell in shaded
    (the lens untested there).  views: per camera ``name``, ``width``, ``height`` (None: not stated),
    ``uv`` (m, 2), ``before`` and ``after`` (m, 2) measured less predicted pixels, ``cells`` (the grid
    of :meth:`robocal.model.views.Views.coverage`, or None)."""
    from matplotlib.figure import Figure

    n = len(views)
    fig = Figure(figsize=(6.2 * min(n, 2), 4.6 * -(-n // 2)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(-(-n // 2), min(n, 2))).ravel()
    for ax, v in zip(axes, views):
        uv, after, before = (np.asarray(v[k], float) for k in ("uv", "after", "before"))
        norm = np.linalg.norm(after, axis=1)
        width = v["width"] or float(np.nanmax(uv[:, 0])) * 1.05
        height = v["height"] or float(np.nanmax(uv[:, 1])) * 1.05
        cells = v.get("cells")
        if cells is not None:  # the image's cells no marker fell in: the lens is untested there
            rows_, columns = cells.shape
            ax.imshow(~cells, extent=(-0.5, width - 0.5, height - 0.5, -0.5), cmap="Greys", vmin=0, vmax=4,
                      interpolation="nearest", aspect="auto", zorder=0)
        typical = float(np.median(norm)) if norm.size else 0.0
        # arrows a typical error long are about 5 % of the image wide: seen above the dots
        gain = _round_down(0.07 * width / typical) if typical > 0 else 1.0
        vmax = robust_limit(norm)
        sc = ax.scatter(uv[:, 0], uv[:, 1], c=np.minimum(norm, vmax), s=4, cmap="viridis", vmin=0.0, vmax=vmax,
                        zorder=2)
        shown = np.arange(len(uv)) if len(uv) <= 600 else np.random.default_rng(0).choice(len(uv), 600, False)
        # (a sample of 600 where there are more: arrows on arrows hide what they show)
        arrows = ax.quiver(uv[shown, 0], uv[shown, 1], gain * after[shown, 0], gain * after[shown, 1], angles="xy",
                           scale_units="xy", scale=1, width=0.004, headwidth=3, color="tab:red", alpha=0.85, zorder=3)
        if typical > 0:  # a legend arrow of a round length near the typical error
            key = _round_down(typical)
            ax.quiverkey(arrows, 0.80, 1.015, gain * key, f"{key:g} px error (drawn ×{gain:g})", labelpos="W",
                         coordinates="axes", fontproperties={"size": 7})
        ax.plot([0, width, width, 0, 0], [0, 0, height, height, 0], color="black", lw=0.8)
        ax.set_xlim(-0.02 * width, 1.02 * width)
        ax.set_ylim(1.02 * height, -0.02 * height)
        ax.set_aspect("equal")
        rms = lambda e: float(np.sqrt(np.mean(np.sum(e * e, axis=1))))  # noqa: E731
        covered = "" if cells is None else f", {100 * cells.mean():.0f} % of the image covered"
        ax.set_title(f"camera {v['name']}: {len(uv)} rows, RMS {rms(before):.3g} → {rms(after):.3g} px{covered}",
                     fontsize=9, pad=14)
        ax.set_xlabel("u (px)")
        ax.set_ylabel("v (px)")
        fig.colorbar(sc, ax=ax, label="reprojection error after (px)", shrink=0.8)
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.suptitle(title)
    return fig


def parameter_bars(names: list[str], values: np.ndarray, sigmas: np.ndarray | None, angle: np.ndarray, title: str):
    """Identified deviations with ±2σ bars: lengths in mm, angles in degrees and compliances in
    rad/(N·m), side by side."""
    from matplotlib.figure import Figure

    compliance = np.array([n.startswith("compliance") for n in names], bool)
    groups = [(np.flatnonzero(~angle & ~compliance), "deviation (mm)", 1.0),
              (np.flatnonzero(angle), "deviation (deg)", 180.0 / np.pi),
              (np.flatnonzero(compliance), "compliance (µrad/(N·m))", 1e6)]
    groups = [g for g in groups if g[0].size]
    fig = Figure(figsize=(11, 0.3 * max(len(g[0]) for g in groups) + 1.5))
    axes = np.atleast_1d(fig.subplots(1, len(groups)))
    for ax, (idx, label, scale) in zip(axes, groups):
        y = np.arange(idx.size)
        err = None if sigmas is None else np.where(np.isfinite(sigmas[idx]), 2 * sigmas[idx] * scale, 0.0)
        ax.errorbar(values[idx] * scale, y, xerr=err, fmt="o", ms=4, capsize=3, color="tab:blue")
        ax.axvline(0, color="black", lw=0.6)
        ax.set_yticks(y, [names[i] for i in idx])
        ax.invert_yaxis()
        ax.set_xlabel(label + (" ± 2σ" if sigmas is not None else ""))
        ax.grid(True, axis="x", alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def position_errors(before: np.ndarray, after: dict[str, np.ndarray], title: str):
    """|δp| per pose before and after calibration (Wen 2019 Fig. 3): before (m, 3), after {method: (m, 3)} mm."""
    fig, ax = new_figure(7, 4)
    idx = np.arange(1, len(before) + 1)
    ax.plot(idx, np.linalg.norm(before, axis=1), "o-", label="before", color="tab:red")
    for name, dp in after.items():
        ax.plot(idx, np.linalg.norm(dp, axis=1), "s-", ms=3, label=f"after {name}")
    ax.set_yscale("log")
    ax.set_xlabel("pose")
    ax.set_ylabel("position error |δp| (mm)")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return fig


def axis_errors(dp: np.ndarray, title: str):
    """Position error per axis and pose (Kou 2022 Fig. 2–4), mm."""
    fig, ax = new_figure(7, 4)
    idx = np.arange(1, len(dp) + 1)
    width = 0.28
    for k, (axis, color) in enumerate(zip("XYZ", ("tab:blue", "tab:orange", "tab:green"))):
        ax.bar(idx + (k - 1) * width, dp[:, k], width, label=axis, color=color)
    ax.axhline(0, color="black", lw=0.6)
    ax.set_xlabel("pose")
    ax.set_ylabel("position error (mm)")
    ax.set_title(f"{title} — max |X| {np.abs(dp[:, 0]).max():.3g}, |Y| {np.abs(dp[:, 1]).max():.3g}, "
                 f"|Z| {np.abs(dp[:, 2]).max():.3g} mm", fontsize=9)
    ax.legend()
    return fig


def orientation_errors(before: np.ndarray, after: np.ndarray, title: str):
    """Orientation error about X, Y, Z per pose, before and after (Wen 2019 Fig. 4–5); rad in, deg shown."""
    fig, axes = new_figure(10, 3.8, ncols=2)
    idx = np.arange(1, len(before) + 1)
    for ax, d, label in ((axes[0], before, "before"), (axes[1], after, "after")):
        for k, axis in enumerate("XYZ"):
            ax.plot(idx, np.degrees(d[:, k]), "o-", ms=3, label=f"about {axis}")
        ax.axhline(0, color="black", lw=0.6)
        ax.set_xlabel("pose")
        ax.set_ylabel("orientation error (deg)")
        ax.set_title(f"{title}: {label}")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def sensitivity_bars(table: dict[str, list[float]], title: str):
    """Mean |E| per parameter: position components (mm) and orientation components (rad in, deg shown)."""
    labels = list(table)
    vals = np.array([table[k] for k in labels])
    fig, (a1, a2) = new_figure(11, 3.8, ncols=2)
    x = np.arange(len(labels))
    w = 0.27
    for k, (name, color) in enumerate(zip(("dx", "dy", "dz"), ("tab:blue", "tab:orange", "tab:green"))):
        a1.bar(x + (k - 1) * w, vals[:, k], w, label=name, color=color)
    for k, (name, color) in enumerate(zip(("dα", "dβ", "dγ"), ("tab:red", "tab:purple", "tab:gray"))):
        a2.bar(x + (k - 1) * w, np.degrees(vals[:, 3 + k]), w, label=name, color=color)
    for ax, unit in ((a1, "mean |E| (mm)"), (a2, "mean |E| (deg)")):
        ax.set_xticks(x, labels, rotation=30)
        ax.set_ylabel(unit)
        ax.grid(True, axis="y", alpha=0.3)
        ax.legend(fontsize=8, ncols=3, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    fig.suptitle(title, y=1.06)
    fig.tight_layout()
    return fig


def per_pose_errors(errors: dict[str, np.ndarray], title: str, ylabel: str = "|position error| (mm)"):
    """One line per method or parameter: a per-pose magnitude (log scale)."""
    fig, ax = new_figure(7, 4)
    for name, e in errors.items():
        e = np.asarray(e, float)
        mag = np.linalg.norm(e, axis=1) if e.ndim == 2 else e
        ax.plot(np.arange(1, len(mag) + 1), np.maximum(mag, 1e-16), "o-", ms=3, label=name)
    ax.set_yscale("log")
    _log_axis(ax.yaxis)
    ax.set_xlabel("pose")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


def study_boxes(rows: list[dict], study, column: str, ylabel: str):
    """Box plots of one column of a study's runs: one box per method, grouped by cell (poses,
    noise); log scale when the values span more than a decade."""
    import itertools
    import math

    from matplotlib.figure import Figure

    cells = list(itertools.product(study.poses, study.noise))
    fig = Figure(figsize=(max(8.0, 1.5 + 0.9 * len(cells) * len(study.methods)), 5.2), dpi=110)
    ax = fig.subplots()
    colours = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple"]
    labels, ticks = [], []
    all_values = []
    for c, (p, n) in enumerate(cells):
        for k, m in enumerate(study.methods):
            values = [float(r[column]) for r in rows if r["method"] == m and int(r["poses"]) == p
                      and math.isclose(float(r["noise"]), n, abs_tol=1e-12) and math.isfinite(float(r[column]))]
            if not values:
                continue
            x = c * (len(study.methods) + 1) + k
            box = ax.boxplot(values, positions=[x], widths=0.7, patch_artist=True, showfliers=True,
                             medianprops={"color": "black", "linewidth": 2.2})
            for patch in box["boxes"]:
                patch.set_facecolor(colours[k % len(colours)])
                patch.set_alpha(0.6)
            all_values += values
        ticks.append(c * (len(study.methods) + 1) + (len(study.methods) - 1) / 2)
        labels.append(f"{p} poses\nnoise {n:g} mm")
    positive = [v for v in all_values if v > 0]
    if positive and max(positive) / min(positive) > 10:
        ax.set_yscale("log")
        _log_axis(ax.yaxis, positive)
    ax.set_xticks(ticks, labels)
    ax.set_ylabel(ylabel)
    ax.grid(True, axis="y", alpha=0.3)
    from matplotlib.patches import Patch

    ax.legend(handles=[Patch(facecolor=colours[k % len(colours)], alpha=0.6, label=m)
                       for k, m in enumerate(study.methods)], fontsize=8)
    ax.set_title(f"{study.name}: {ylabel} over {study.seeds} seeds")
    fig.tight_layout()
    return fig


def iso9283_bars(results: list, title: str):
    """AP_p and RP_l (mm) per pose, one bar per campaign side by side (ISO 9283 pose characteristics)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 3.8), layout="constrained")
    axes = fig.subplots(1, 2)
    labels = [p.pose for p in results[0].poses]
    x = np.arange(len(labels))
    width = 0.8 / len(results)
    for ax, key, ylabel in ((axes[0], "AP_p", "pose accuracy AP (mm)"), (axes[1], "RP_l", "repeatability RP (mm)")):
        every = []
        for k, r in enumerate(results):
            values = np.maximum([getattr(p, key) for p in r.poses], 1e-6)
            every.append(values)
            bars = ax.bar(x + (k - (len(results) - 1) / 2) * width, values, width, label=r.name)
            ax.bar_label(bars, labels=[f"{v:.3g}" for v in values], fontsize=7, padding=1)
        # log scale: a compensated campaign is tens of times below the one before, and on a linear
        # axis its bars vanish
        ax.set_yscale("log")
        _log_axis(ax.yaxis, np.concatenate(every))
        ax.set_ylim(float(np.min(np.concatenate(every))) / 2.5, float(np.max(np.concatenate(every))) * 3.0)
        ax.set_xticks(x, labels)
        ax.set_ylabel(ylabel)
        ax.grid(True, axis="y", which="major", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    return fig
