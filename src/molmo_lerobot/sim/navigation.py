"""Planar navigation geometry of a compiled scene: occupancy grids, path lengths and line of sight.

:func:`occupancy` rasterizes the world bounding boxes of a model's colliding geoms (planes and the
bodies left out aside) into a grid on the floor: ``blocked`` holds the geoms that reach into the
height band a mobile robot sweeps, ``tall`` those rising above eye height (walls), which hide what is
behind them. :func:`free_space` keeps the cells a robot of a given radius can stand on,
:func:`path_lengths` gives every cell's shortest 8-connected path length to a goal set (Dijkstra,
scipy), and :func:`descend` follows it back from a start cell.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

#: grid cell size (m)
RESOLUTION = 0.05
#: the height band a mobile robot sweeps (m above the floor) and the height above which a geom hides the view
SWEPT_BAND = (0.03, 1.8)
EYE_HEIGHT = 1.2
_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)


@dataclass(frozen=True)
class Grid:
    """Cells ``[i, j]`` cover ``x0 + i·res … x0 + (i+1)·res`` (and likewise in y)."""

    x0: float
    y0: float
    res: float
    blocked: np.ndarray  # bool (nx, ny): a geom in the swept band
    tall: np.ndarray  # bool (nx, ny): a geom rising above eye height

    def cell(self, xy: Iterable[float]) -> tuple[int, int]:
        x, y = xy
        i = int(np.clip(math.floor((x - self.x0) / self.res), 0, self.blocked.shape[0] - 1))
        j = int(np.clip(math.floor((y - self.y0) / self.res), 0, self.blocked.shape[1] - 1))
        return i, j

    def centre(self, i: int, j: int) -> np.ndarray:
        return np.array([self.x0 + (i + 0.5) * self.res, self.y0 + (j + 0.5) * self.res])

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """x and y of every cell centre, each (nx, ny)."""
        nx, ny = self.blocked.shape
        xs = self.x0 + (np.arange(nx) + 0.5) * self.res
        ys = self.y0 + (np.arange(ny) + 0.5) * self.res
        x, y = np.meshgrid(xs, ys, indexing="ij")
        return x, y

    def sees(self, a: Iterable[float], b: Iterable[float]) -> bool:
        """Whether the segment from ``a`` to ``b`` (x, y) crosses no tall cell."""
        a, b = np.asarray(list(a), dtype=np.float64), np.asarray(list(b), dtype=np.float64)
        n = max(2, int(np.linalg.norm(b - a) / (self.res / 2)) + 1)
        cells = {self.cell(a + (b - a) * t) for t in np.linspace(0.0, 1.0, n)}
        return not any(self.tall[c] for c in cells)


def geom_boxes(model: mujoco.MjModel, data: mujoco.MjData, exclude: Iterable[int] = ()) -> list[np.ndarray]:
    """World axis-aligned boxes ``[xmin, ymin, zmin, xmax, ymax, zmax]`` of the colliding geoms
    (``contype`` or ``conaffinity`` set), planes and the geoms of the ``exclude`` bodies left out."""
    skip = set(int(b) for b in exclude)
    out = []
    for g in range(model.ngeom):
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE or int(model.geom_bodyid[g]) in skip:
            continue
        if not (model.geom_contype[g] or model.geom_conaffinity[g]):
            continue
        centre, half = model.geom_aabb[g][:3], model.geom_aabb[g][3:]
        corners = (_CORNERS * half + centre) @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g]
        out.append(np.concatenate([corners.min(axis=0), corners.max(axis=0)]))
    return out


def occupancy(model: mujoco.MjModel, data: mujoco.MjData, bounds: tuple[float, float, float, float],
              exclude: Iterable[int] = (), res: float = RESOLUTION) -> Grid:
    """The grid over ``bounds`` (xmin, ymin, xmax, ymax) of a forwarded state (module docstring)."""
    xmin, ymin, xmax, ymax = bounds
    nx, ny = math.ceil((xmax - xmin) / res), math.ceil((ymax - ymin) / res)
    blocked = np.zeros((nx, ny), dtype=bool)
    tall = np.zeros((nx, ny), dtype=bool)
    for box in geom_boxes(model, data, exclude):
        i0, j0 = math.floor((box[0] - xmin) / res), math.floor((box[1] - ymin) / res)
        i1, j1 = math.ceil((box[3] - xmin) / res), math.ceil((box[4] - ymin) / res)
        i0, j0, i1, j1 = max(i0, 0), max(j0, 0), min(i1, nx), min(j1, ny)
        if i0 >= i1 or j0 >= j1:
            continue
        if box[2] < SWEPT_BAND[1] and box[5] > SWEPT_BAND[0]:
            blocked[i0:i1, j0:j1] = True
        if box[5] > EYE_HEIGHT:
            tall[i0:i1, j0:j1] = True
    return Grid(xmin, ymin, res, blocked, tall)


def free_space(grid: Grid, radius: float) -> np.ndarray:
    """Cells whose centre is farther than ``radius`` from every blocked cell (and inside the grid's edge)."""
    clear = ndimage.distance_transform_edt(~grid.blocked) * grid.res
    free = clear > radius + grid.res / 2
    margin = max(1, math.ceil(radius / grid.res))
    free[:margin], free[-margin:], free[:, :margin], free[:, -margin:] = False, False, False, False
    return free


def path_lengths(free: np.ndarray, goals: np.ndarray, res: float) -> np.ndarray:
    """Shortest 8-connected path length (m) from every cell to the nearest goal cell through free
    cells (``inf`` where none leads); ``goals`` is a bool mask (only its free cells count)."""
    nx, ny = free.shape
    index = np.arange(nx * ny).reshape(nx, ny)
    rows, cols, weights = [], [], []
    for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):  # each cell and its neighbour at (+di, +dj)
        sa = (slice(max(0, -di), nx - max(0, di)), slice(max(0, -dj), ny - max(0, dj)))
        sb = (slice(max(0, di), nx + min(0, di)), slice(max(0, dj), ny + min(0, dj)))
        both = free[sa] & free[sb]
        rows.append(index[sa][both])
        cols.append(index[sb][both])
        weights.append(np.full(int(both.sum()), res * math.hypot(di, dj)))
    r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(weights)
    graph = coo_matrix((w, (r, c)), shape=(nx * ny, nx * ny)).tocsr()
    sources = index[goals & free]
    if sources.size == 0:
        return np.full((nx, ny), np.inf)
    dist = dijkstra(graph, directed=False, indices=sources, min_only=True)
    return dist.reshape(nx, ny)


def descend(dist: np.ndarray, start: tuple[int, int]) -> list[tuple[int, int]]:
    """The cells from ``start`` down ``dist`` to a goal (distance 0); ``[]`` when ``start`` reaches none."""
    if not np.isfinite(dist[start]):
        return []
    path = [start]
    i, j = start
    nx, ny = dist.shape
    while dist[i, j] > 0:
        best = min(((dist[a, b], (a, b)) for a in range(max(0, i - 1), min(nx, i + 2))
                    for b in range(max(0, j - 1), min(ny, j + 2)) if (a, b) != (i, j)), key=lambda t: t[0])
        if best[0] >= dist[i, j]:
            break
        i, j = best[1]
        path.append((i, j))
    return path
