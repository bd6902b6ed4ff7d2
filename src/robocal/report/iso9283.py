"""The ISO 9283 report: the pose and distance characteristics of one or more campaigns side by side."""

from __future__ import annotations

import html
from pathlib import Path

from ..io.atomic import atomic_write
from . import figures
from .html import _CSS, _img

#: the pose characteristics shown, with their units
POSE_COLUMNS = (("AP_p", "mm"), ("AP_x", "mm"), ("AP_y", "mm"), ("AP_z", "mm"), ("RP_l", "mm"), ("AP_a", "deg"),
                ("AP_b", "deg"), ("AP_c", "deg"), ("RP_a", "deg"), ("RP_b", "deg"), ("RP_c", "deg"))


def _cell(v) -> str:
    return "—" if v is None else f"{v:.4f}"


def pose_rows(results: list) -> tuple[list[str], list[list[str]]]:
    """Header and rows: per pose and campaign, every characteristic the data give."""
    keys = [(k, u) for k, u in POSE_COLUMNS if any(getattr(p, k) is not None for r in results for p in r.poses)]
    head = ["pose", "campaign", *(f"{k} ({u})" for k, u in keys)]
    rows = [[p.pose, r.name, *(_cell(getattr(p, k)) for k, _ in keys)]
            for j in range(len(results[0].poses)) for r in results for p in (r.poses[j],)]
    return head, rows


def distance_rows(results: list) -> tuple[list[str], list[list[str]]]:
    head = ["poses", "campaign", "D_c (mm)", "AD_p (mm)", "AD_x (mm)", "AD_y (mm)", "AD_z (mm)", "RD (mm)"]
    rows = [[f"{d.poses[0]}–{d.poses[1]}", r.name, *(f"{v:.4f}" for v in (d.D_c, d.AD_p, d.AD_x, d.AD_y, d.AD_z, d.RD))]
            for j in range(len(results[0].distances)) for r in results for d in (r.distances[j],)]
    return head, rows


#: the test conditions an ISO 9283 report states (ISO 9283:1998 §6), in the order shown
CONDITIONS = (("payload", "load at the TCP (the standard: 100 % of the rated load)"),
              ("speed", "speed of the moves (100 %, 50 % and 10 % of the rated speed)"),
              ("warmup", "warm-up before the test"), ("temperature", "ambient temperature"),
              ("instrument", "measuring system"), ("tcp", "measuring point's offset from the flange"))


def parse_conditions(items) -> dict[str, str]:
    """``KEY=VALUE[,KEY=VALUE…]`` items (repeatable) as an ordered dict; a key is a word."""
    import re

    from ..exceptions import InputError

    out: dict[str, str] = {}
    for item in items or ():
        for part in str(item).split(","):
            key, eq, value = part.partition("=")
            key = key.strip().lower()
            if not eq or not re.fullmatch(r"[a-z][a-z0-9_-]*", key) or not value.strip():
                raise InputError(f"expected KEY=VALUE (payload=5 kg, speed=100 %, …), got {part.strip()!r}",
                                 option="conditions")
            out[key] = value.strip()
    return out


def _conditions(conditions: dict[str, str]) -> str:
    """The test-conditions block: each stated one, and the standard's that were not stated."""
    known = dict(CONDITIONS)
    rows = [[key, known.get(key, ""), value] for key, value in conditions.items()]
    missing = [key for key, _ in CONDITIONS if key not in conditions]
    said = (f"<p>Not stated: {', '.join(missing)} (<code>--conditions KEY=VALUE</code>); an ISO 9283 report "
            "states every one.</p>") if missing else ""
    head = "".join(f"<th>{c}</th>" for c in ("condition", "what", "value"))
    body = "".join("<tr>" + "".join(f"<td class='l'>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows)
    return "<h2>Test conditions</h2>" + (f"<table><tr>{head}</tr>{body}</table>" if rows else "") + said


def _table(head, rows) -> str:
    h = "".join(f"<th>{html.escape(c)}</th>" for c in head)
    b = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{h}</tr>{b}</table>"


def iso9283_html(results: list, sources: list[str], command: str | None = None, requirements=(),
                 robot: str | None = None, conditions: dict[str, str] | None = None) -> str:
    """The report of one or more campaigns side by side, headed like calibrate's (version, date,
    command, each campaign's file with its SHA-256) and, with ``requirements``, the verdict of the
    last campaign against them."""
    from ..requirements import unmet
    from .header import run_header

    campaigns = ", ".join(f"{html.escape(r.name)} (<code>{html.escape(s)}</code>, {r.poses[0].cycles} cycles)"
                          for r, s in zip(results, sources))
    rows = [("robot", robot)] if robot else []
    rows.append(("campaigns", ", ".join(f"{r.name}: {len(r.poses)} poses × {r.poses[0].cycles} cycles"
                                        for r in results)))
    verdict = []
    if requirements:
        last = results[-1]
        failed = unmet(requirements, last.figures())
        rows.append(("specification", ", ".join(str(r) for r in requirements) + f" (campaign {last.name})"))
        rows.append(("verdict", "met" if not failed else "not met: " + "; ".join(
            f.removeprefix("requirement not met: ") for f in failed)))
        figures_of = last.figures()

        def listed(group):
            return ", ".join(f"{html.escape(str(r))} ({r.figure} = {figures_of[r.figure]:.4g} mm)" for r in group)

        missed = [r for r in requirements if not r.met(figures_of)]
        kept = [r for r in requirements if r.met(figures_of)]
        verdict = [f"<p class='{'next' if not missed else 'warn'}'>Specification "
                   + (f"met by {html.escape(last.name)}: {listed(kept)}" if not missed else
                      f"not met by {html.escape(last.name)}: {listed(missed)}" + (f"; met: {listed(kept)}" if kept
                                                                                  else "")) + ".</p>"]
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>ISO 9283</title><style>{_CSS}</style>"
             "</head><body><h1>ISO 9283 pose and distance characteristics</h1>",
             run_header(command, "robocal.iso9283", [(f"campaign {r.name}", s) for r, s in zip(results, sources)],
                        rows),
             *verdict,
             _conditions(conditions or {}),
             f"<p>Campaigns: {campaigns}. Pose accuracy AP is the distance from the commanded pose to the "
             "barycentre of the attained ones; repeatability RP_l = l̄ + 3 S_l about that barycentre (ISO "
             "9283:1998 §7.2); distance accuracy AD and repeatability RD between each pair of poses (§7.3). "
             "The bars are on a log scale, each labelled with its value.</p>",
             *(f"<p class='warn'>{html.escape(n)}</p>" for r in results for n in r.notes),
             _img(figures.iso9283_bars(results, "pose accuracy and repeatability")),
             "<h2>Pose characteristics</h2>", _table(*pose_rows(results)),
             "<h2>Distance characteristics</h2>", _table(*distance_rows(results)),
             "<p>Generated by robocal.</p></body></html>"]
    return "".join(parts)


def write_iso9283_report(results: list, sources: list[str], path: str | Path, command: str | None = None,
                         requirements=(), robot: str | None = None, conditions: dict[str, str] | None = None) -> None:
    atomic_write(path, iso9283_html(results, sources, command, requirements, robot, conditions))
