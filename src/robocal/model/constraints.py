"""Data without a tracker: rows that touched the same unknown point or plane (MODEL §9).

A row labelled with a ``point`` (or a ``plane``) says that the robot's tool point stood at the
same unknown point (on the same unknown plane) as every other row of that label in the same
``setup`` (one placement of the artefact; without a setup column, one placement).  Nothing is
measured but the joints.  Known distances between two points of a setup (two sockets a
calibrated distance apart) give the length scale.

The unknowns are eliminated rather than estimated (variable projection, Golub & Pereyra): for
given robot parameters the best point is the mean of its rows' predicted tool points, the best
plane the least-squares plane through them.  Each row's error is its predicted point's offset
from that point, or from that plane along its normal (mm, the measuring frame), so every figure
and test that works on position errors works on these.  Their derivative is the rows' Jacobian
less its group mean (for a plane, along the normal: the normal's own change is second order at
a fit, Kaufman's approximation).  Each point or plane uses three of the data's values, which the
statistics count.

Tracker rows (x, y, z measured) and constraint rows may be mixed: a tracker row's error is as
ever its measured point less the predicted one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError

#: what a group of rows touched
KINDS = ("point", "plane")
#: the default standard uncertainty of a stated distance between two points (mm): a printed
#: two-socket tool measured to about 0.1 mm
DISTANCE_SIGMA_MM = 0.05
#: unknowns each group adds (a point: x, y, z; a plane: its normal's two angles and offset)
UNKNOWNS_PER_GROUP = 3


@dataclass(frozen=True)
class Constraints:
    """The constraint groups of a set of rows: per group its kind, label and setup; per row its
    group (−1: a tracker row); and the stated distances (group a, group b, mm)."""

    kind: tuple[str, ...]
    label: tuple[str, ...]
    setup: tuple[str, ...]
    group: np.ndarray
    distances: tuple[tuple[int, int, float], ...] = ()
    distance_sigma: float = DISTANCE_SIGMA_MM

    @property
    def n_groups(self) -> int:
        return len(self.kind)

    @property
    def rows(self) -> np.ndarray:
        """Mask (m,) of the constraint rows."""
        return self.group >= 0

    @property
    def only(self) -> bool:
        """True when no row carries a measured position."""
        return bool(np.all(self.group >= 0))

    def rows_of(self, kind: str) -> np.ndarray:
        kinds = np.array([k == kind for k in self.kind] + [False])
        return kinds[self.group]  # group −1 indexes the trailing False

    @property
    def n_unknowns(self) -> int:
        """The data's values the eliminated points and planes use."""
        return UNKNOWNS_PER_GROUP * self.n_groups

    def name(self, g: int) -> str:
        return f"{self.kind[g]} {self.label[g]}" + (f" of setup {self.setup[g]}" if self.setup[g] else "")

    def _onehot(self) -> np.ndarray:
        """(G, m) the mean over each group's rows."""
        M = np.zeros((self.n_groups, len(self.group)))
        rows = np.flatnonzero(self.group >= 0)
        M[self.group[rows], rows] = 1.0
        return M / np.maximum(M.sum(axis=1, keepdims=True), 1.0)

    def means(self, p: np.ndarray) -> np.ndarray:
        """Each group's mean predicted point (…, G, 3) of predicted points p (…, m, 3) mm."""
        return np.einsum("gm,...mc->...gc", self._onehot(), p)

    def normals(self, p: np.ndarray, centres: np.ndarray) -> np.ndarray:
        """Each group's least-squares plane normal (…, G, 3) (the direction of least spread);
        zeros for point groups."""
        n = np.zeros(centres.shape)
        for g in np.flatnonzero([k == "plane" for k in self.kind]):
            d = p[..., self.group == g, :] - centres[..., g:g + 1, :]
            w, v = np.linalg.eigh(np.einsum("...mi,...mj->...ij", d, d))
            n[..., g, :] = v[..., :, 0]
        return n

    def errors(self, p: np.ndarray) -> np.ndarray:
        """The constraint rows' errors (…, m, 3) mm of predicted points p (…, m, 3): the group's
        point less the row's, or the offset onto the group's plane along its normal; zeros at
        tracker rows."""
        c = self.means(p)
        g = np.maximum(self.group, 0)
        e = c[..., g, :] - p
        planes = self.rows_of("plane")
        if planes.any():
            n = self.normals(p, c)[..., g, :]
            e = np.where(planes[:, None], n * np.sum(n * e, axis=-1, keepdims=True), e)
        return np.where(self.rows[:, None], e, 0.0)

    def error_jacobian(self, J: np.ndarray, p: np.ndarray) -> np.ndarray:
        """∂(errors)/∂x (k, m, 3) of the constraint rows from the predicted points' Jacobian
        J (k, m, 3) at p (m, 3): the group mean of J less the row's (a plane: along its
        normal); zeros at tracker rows."""
        M = self._onehot()
        g = np.maximum(self.group, 0)
        dJ = np.einsum("gm,kmc->kgc", M, J)[:, g, :] - J
        planes = self.rows_of("plane")
        if planes.any():
            n = self.normals(p, self.means(p))[g]
            dJ = np.where(planes[None, :, None], n[None] * np.sum(n[None] * dJ, axis=-1, keepdims=True), dJ)
        return np.where(self.rows[None, :, None], dJ, 0.0)

    def distance_residuals(self, p: np.ndarray) -> np.ndarray:
        """(…, D) mm: each stated distance's miss, |c_a − c_b| − D."""
        if not self.distances:
            return np.zeros(p.shape[:-2] + (0,))
        c = self.means(p)
        a, b, d = (np.array(x) for x in zip(*self.distances))
        return np.linalg.norm(c[..., a, :] - c[..., b, :], axis=-1) - d

    def distance_jacobian(self, J: np.ndarray, p: np.ndarray) -> np.ndarray:
        """(k, D): ∂(distance residuals)/∂x, the unit vector between the two means on their
        mean Jacobians."""
        if not self.distances:
            return np.zeros((J.shape[0], 0))
        c = self.means(p)
        cJ = np.einsum("gm,kmc->kgc", self._onehot(), J)
        a, b, _ = (np.array(x) for x in zip(*self.distances))
        u = c[a] - c[b]
        u = u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-300)
        return np.einsum("dc,kdc->kd", u, cJ[:, a] - cJ[:, b])

    def figures(self, p: np.ndarray) -> dict[str, float]:
        """The constraint data's figures of predicted points p (m, 3) mm: ``point_spread_rms``
        (each point row's distance from its point's mean), ``plane_rms`` (each plane row's
        distance from its plane), ``distance_error_rms`` (each stated distance's miss), the
        ones these rows have."""
        e = np.linalg.norm(self.errors(p), axis=-1)
        out = {}
        for kind, key in (("point", "point_spread_rms"), ("plane", "plane_rms")):
            rows = self.rows_of(kind)
            if rows.any():
                out[key] = float(np.sqrt(np.mean(e[rows] ** 2)))
        if self.distances:
            out["distance_error_rms"] = float(np.sqrt(np.mean(self.distance_residuals(p) ** 2)))
        return out

    def subset(self, index: np.ndarray) -> Constraints | None:
        """The constraints of rows ``index`` (groups renumbered, distances kept where both
        groups remain), or None when no constraint row remains."""
        group = self.group[index]
        kept = np.unique(group[group >= 0])
        if not kept.size:
            return None
        new = -np.ones(self.n_groups, dtype=int)
        new[kept] = np.arange(len(kept))
        return Constraints(tuple(self.kind[g] for g in kept), tuple(self.label[g] for g in kept),
                           tuple(self.setup[g] for g in kept), np.where(group >= 0, new[np.maximum(group, 0)], -1),
                           tuple((int(new[a]), int(new[b]), d) for a, b, d in self.distances
                                 if new[a] >= 0 and new[b] >= 0), self.distance_sigma)


def constraints_of(point: Sequence[str] | None, plane: Sequence[str] | None, setup: Sequence[str] | None, m: int,
                   distances: Mapping[tuple[str, str], float] | None = None,
                   distance_sigma: float = DISTANCE_SIGMA_MM, source: str = "<data>",
                   strict: bool = True) -> Constraints | None:
    """The groups of per-row labels (``point`` / ``plane``: "" where a row has none; ``setup``:
    the placement, "" for one), with the stated distances between point labels, applied in
    every setup that has both; None without constraint rows.  ``strict``: a distance whose two
    points no setup has is an error (else it is left out: a subset of the rows)."""
    point = tuple(point) if point is not None else ("",) * m
    plane = tuple(plane) if plane is not None else ("",) * m
    setup = tuple(setup) if setup is not None else ("",) * m
    keys: dict[tuple[str, str, str], int] = {}
    group = -np.ones(m, dtype=int)
    for i in range(m):
        kind, label = ("point", point[i]) if point[i] else ("plane", plane[i]) if plane[i] else (None, "")
        if kind is not None:
            group[i] = keys.setdefault((kind, label, setup[i]), len(keys))
    if not keys:
        return None
    kind, label, where = (tuple(x) for x in zip(*keys))
    pairs = []
    for (a, b), d in (distances or {}).items():
        found = [(keys[("point", a, s)], keys[("point", b, s)]) for s in dict.fromkeys(where)
                 if ("point", a, s) in keys and ("point", b, s) in keys]
        if not found and strict:
            raise InputError(f"{a},{b}={d:g}: no setup of {source} has both points {a!r} and {b!r}",
                             option="point_distance")
        pairs += [(ga, gb, float(d)) for ga, gb in found]
    return Constraints(kind, label, where, group, tuple(pairs), distance_sigma)
