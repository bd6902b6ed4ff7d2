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
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    return buf.getvalue()


def save_png(fig, path) -> None:
    from ..io.atomic import atomic_write

    atomic_write(path, png_bytes(fig))


def convergence(histories: dict[str, np.ndarray], title: str, ylabel: str = "best objective"):
    """Best objective against iteration, log scale, one line per method."""
    fig, ax = new_figure(7, 4)
    for name, h in histories.items():
        h = np.asarray(h, dtype=float)
        if h.size == 0:
            continue
        ax.plot(np.arange(h.size), np.maximum(h, 1e-300), label=name, lw=1.4)
    ax.set_yscale("log")
    ax.set_xlabel("iteration (LM: residual evaluation)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
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
        ax.legend(fontsize=8)
    fig.suptitle(title)
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
    ax.set_xlabel("pose")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig
