"""Is what is left of a field random? Two randomisation tests and the verdict.

The null hypothesis is the method's stopping point, "small vectors oriented randomly": each
valid voxel's vector is sampling noise, independent of the others and as likely to point one
way as the opposite way (d and -d equally likely). Both tests draw their null distribution by
flipping the sign of every vector at random (``PERMUTATIONS`` draws from a fixed seed), which
is exact under that null for any number of voxels and any shape of the noise:

- ``p_direction``: do the directions share a resultant? Statistic |sum of unit vectors|^2 (the
  Rayleigh statistic). The classic Rayleigh p-value assumes directions uniform on the sphere,
  but noise on a flat patch of ground lies in that patch; sign flips need only the symmetry.
  Catches a translation (every vector the same way).
- ``p_coherence``: do neighbouring voxels' vectors agree? Statistic: the sum over pairs of
  grid neighbours of the dot product of their unit vectors. Catches patterns with no net
  resultant (a scale error's outward vectors, a rotation's swirl, opposing vectors in halves).
  Random signs rather than shuffling the vectors over the voxels: a shuffle is exact only for
  vectors exchangeable over the voxels, and noise is not (it lies in its surface's plane, which
  neighbours share); random signs keep each voxel's own axis. (On the calibration scenes of
  the tests a shuffle test was close too: 3% false rejections at 2.5% over 100 seeds.)

``verdict`` is ``patterned`` when either p-value is at most ``LEVEL / 2`` (Bonferroni over the
two tests, so the false ``patterned`` rate on pure noise is at most ``LEVEL``), ``random``
otherwise, and ``undetermined`` with fewer than ``MIN_VOXELS`` valid voxels. The verdict is
about pattern, not size: the share of significant voxels (``|z| >= grid.z_min``) says how many
vectors stand out of their own sampling noise.
"""

from __future__ import annotations

import math

import numpy as np

from ..field.grid import CARTESIAN_BITS

LEVEL = 0.05
PERMUTATIONS = 999
SEED = 0
MIN_VOXELS = 3
_CHUNK = 64  # sign-flip draws evaluated at a time (bounds memory on grids of 10^5 voxels)


def unit_vectors(uvw: np.ndarray) -> np.ndarray:
    """(M, 3) unit vectors of (M, 3) vectors; a zero vector stays zero (it has no direction)."""
    length = np.linalg.norm(uvw, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(length > 0, uvw / length, 0.0)


def randomness_tests(units: np.ndarray, neighbours: tuple[np.ndarray, np.ndarray], seed: int = SEED) -> dict:
    """``p_direction``, ``p_coherence`` and ``verdict`` of (M, 3) unit vectors with grid
    neighbour pairs (two index arrays into them). See the module docstring."""
    m = len(units)
    if m < MIN_VOXELS:
        return {"p_direction": math.nan, "p_coherence": math.nan, "verdict": "undetermined"}
    first, second = neighbours
    agreement = np.einsum("ij,ij->i", units[first], units[second])
    observed_direction = float(np.sum(np.sum(units, axis=0) ** 2))
    observed_coherence = float(agreement.sum())
    rng = np.random.default_rng(seed)
    exceed_direction = exceed_coherence = 0
    # A relative tolerance so that a draw equal to the observed value up to rounding counts.
    tol_direction = 1e-9 * max(1.0, abs(observed_direction))
    tol_coherence = 1e-9 * max(1.0, abs(observed_coherence))
    for start in range(0, PERMUTATIONS, _CHUNK):
        signs = rng.choice(np.array([-1.0, 1.0]), size=(min(_CHUNK, PERMUTATIONS - start), m))
        direction = np.sum((signs @ units) ** 2, axis=1)
        coherence = (signs[:, first] * signs[:, second]) @ agreement
        exceed_direction += int(np.count_nonzero(direction >= observed_direction - tol_direction))
        exceed_coherence += int(np.count_nonzero(coherence >= observed_coherence - tol_coherence))
    p_direction = (1 + exceed_direction) / (1 + PERMUTATIONS)
    p_coherence = (1 + exceed_coherence) / (1 + PERMUTATIONS) if len(agreement) else math.nan
    patterned = min(p_direction, p_coherence if len(agreement) else 1.0) <= LEVEL / 2
    return {"p_direction": p_direction, "p_coherence": p_coherence, "verdict": "patterned" if patterned else "random"}


def neighbour_pairs(grid, voxel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i < j positions in the sorted ``voxel`` ids) of face neighbours on ``grid``:
    azimuth (wrapping round), elevation and range shell for a spherical grid, the six faces
    for a Cartesian one. Each pair once."""
    voxel = np.asarray(voxel, dtype=np.int64)
    bins = grid.bins(voxel)
    if grid.kind == "spherical":
        sizes = (grid.azimuth_bins, grid.elevation_bins, max(1, grid.range_bins))
        axes = [bins["az_bin"], bins["el_bin"], np.maximum(bins["r_bin"], 0)]
        wraps = (True, False, False)
        strides = (1, grid.azimuth_bins, grid.azimuth_bins * grid.elevation_bins)
    else:
        sizes = (None, None, None)
        axes = [bins["ix"], bins["iy"], bins["iz"]]
        wraps = (False, False, False)
        strides = tuple(1 << (CARTESIAN_BITS * axis) for axis in range(3))
    firsts, seconds = [], []
    for size, index, wrap, stride in zip(sizes, axes, wraps, strides):
        step = np.full(len(voxel), stride, dtype=np.int64)
        has = np.ones(len(voxel), dtype=bool)
        if size is not None:
            last = index == size - 1
            if wrap and size > 2:
                step[last] = -(size - 1) * stride  # the last azimuth bin touches the first
            else:
                has &= ~last
        target = voxel + step
        position = np.searchsorted(voxel, target)
        position = np.minimum(position, len(voxel) - 1)
        found = has & (voxel[position] == target)
        firsts.append(np.flatnonzero(found))
        seconds.append(position[found])
    first, second = np.concatenate(firsts), np.concatenate(seconds)
    return np.minimum(first, second), np.maximum(first, second)
