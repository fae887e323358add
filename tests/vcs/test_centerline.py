"""The lumen path search (paper Section 2.2.1, cost 1/d) against a plain heapq A* reference."""

from __future__ import annotations

import heapq

import numpy as np
import pytest
from scipy import ndimage

from vcs.centerline import _OFFSETS, VoxelLumen, lowest_cost_path
from vcs.errors import VCSInputError


def _reference_a_star(lumen: VoxelLumen, start, goal) -> np.ndarray:
    """The former implementation: A*, step cost |a - b| h (1/d_a + 1/d_b) / 2, heuristic |x - goal| / max d,
    heap entries (g + heuristic, g, flat index)."""
    shape = lumen.inside.shape
    strides = np.array([shape[1] * shape[2], shape[2], 1])
    inv = np.zeros(lumen.inside.size)
    inv[lumen.inside.ravel()] = 1.0 / lumen.distance.ravel()[lumen.inside.ravel()]
    inv = inv.tolist()
    nbr = list(zip((_OFFSETS @ strides).tolist(), (np.linalg.norm(_OFFSETS, axis=1) * lumen.h / 2.0).tolist()))
    s, g_idx = int(np.dot(start, strides)), int(np.dot(goal, strides))
    gx, gy, gz = (np.asarray(goal, float) * lumen.h).tolist()
    hs, h = 1.0 / float(lumen.distance.max()), lumen.h

    def heur(f):
        i, r = divmod(f, shape[1] * shape[2])
        j, k = divmod(r, shape[2])
        return ((i * h - gx) ** 2 + (j * h - gy) ** 2 + (k * h - gz) ** 2) ** 0.5 * hs

    best, parent = {s: 0.0}, {s: -1}
    heap = [(heur(s), 0.0, s)]
    while heap:
        _, g, f = heapq.heappop(heap)
        if f == g_idx:
            break
        if g > best[f]:
            continue
        for off, step in nbr:
            q = f + off
            if inv[q] == 0.0:
                continue
            ng = g + step * (inv[f] + inv[q])
            if ng < best.get(q, np.inf):
                best[q], parent[q] = ng, f
                heapq.heappush(heap, (ng + heur(q), ng, q))
    path = [g_idx]
    while parent[path[-1]] != -1:
        path.append(parent[path[-1]])
    return np.column_stack(np.unravel_index(np.array(path[::-1]), shape))


def _blob_lumen(seed: int, h: float = 0.5) -> tuple[VoxelLumen, np.ndarray, np.ndarray]:
    """Union of balls along a random walk (many voxels at equal distance d: tied path costs)."""
    rng = np.random.default_rng(seed)
    n = 28
    centres = np.cumsum(rng.normal(0, 1.5, (12, 3)), axis=0)
    centres = (centres - centres.min(0)) / max(np.ptp(centres), 1e-9) * (n - 12) + 6
    ijk = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1)
    inside = np.zeros((n, n, n), bool)
    for c in centres:
        inside |= np.linalg.norm(ijk - c, axis=-1) < rng.uniform(3.0, 4.5)
    inside[:2] = inside[-2:] = inside[:, :2] = inside[:, -2:] = inside[..., :2] = inside[..., -2:] = False
    dist = np.where(inside, np.maximum(ndimage.distance_transform_edt(inside, sampling=h), 0.5 * h), 0.0)
    lumen = VoxelLumen(inside, dist, np.zeros(3), h)
    vox = np.argwhere(inside)
    return (
        lumen,
        vox[np.argmin(np.linalg.norm(vox - centres[0], axis=1))],
        vox[np.argmin(np.linalg.norm(vox - centres[-1], axis=1))],
    )


@pytest.mark.parametrize("seed", range(8))
def test_lowest_cost_path_is_the_a_star_path(seed):
    lumen, start, goal = _blob_lumen(seed)
    path = lowest_cost_path(lumen, start, goal)
    ref = _reference_a_star(lumen, start, goal)
    assert path.shape == ref.shape and (path == ref).all()
    assert (path[0] == start).all() and (path[-1] == goal).all()
    assert np.abs(np.diff(path, axis=0)).max() == 1 and lumen.inside[tuple(path.T)].all()


def test_lowest_cost_path_from_a_voxel_to_itself():
    lumen, start, _ = _blob_lumen(0)
    assert (lowest_cost_path(lumen, start, start) == start[None]).all()


def test_lowest_cost_path_between_disconnected_parts_is_an_input_error():
    inside = np.zeros((12, 12, 20), bool)
    inside[4:8, 4:8, 3:8] = inside[4:8, 4:8, 11:17] = True
    lumen = VoxelLumen(inside, np.where(inside, 1.0, 0.0), np.zeros(3), 1.0)
    with pytest.raises(VCSInputError, match="not connected"):
        lowest_cost_path(lumen, np.array([5, 5, 4]), np.array([5, 5, 15]))
