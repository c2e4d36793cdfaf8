"""Is what is left of a field random? Two tests against sampling noise, and the verdict.

The null hypothesis is the method's stopping point, "small vectors oriented randomly": each
valid voxel's vector is its own sampling noise, independent of the others. The tests read each
vector in units of that noise, the whitened vector w = C^-1/2 d of ``field.significance`` (C
the covariance of d from both clouds' spread in the voxel and, when the pair's sensors are
known, the phase of their scan patterns). Under the null every w has mean 0 and covariance at
most I, so both tests draw their null distribution as standard normal vectors, one per voxel
(``PERMUTATIONS`` draws from a fixed seed), correlated between grid neighbours by
``NULL_NEIGHBOUR_CORRELATION``: neighbouring voxels' sampling is not independent (they share
the scan lattice's phase and the smooth surface between them). Measured on fault-free pairs
that read random, neighbouring whitened vectors correlate by 0.05-0.20; where C bounds the
noise loosely (most simulated pairs, one place: the vectors at 0.2-0.5 of it) that hides inside an
independent null's spread, but on a real pair from two places whose vectors are at their full
modelled noise (the OS1-128 frames after ``realign``: 0.91) the same correlation read as a
pattern (p_coherence 0.011). See docs/diagnosis.md. A voxel holding one surface seen from two places is read by its
normal part alone (w along its normal n, ``significance``): its draw is the standard normal
vector's part along n, one degree of freedom.

- ``p_direction``: do the vectors share a resultant? Statistic |sum w|^2 (chi^2 with 3 degrees
  of freedom times the voxel count under an independent null; the neighbours' correlation
  spreads it wider). Catches a translation.
- ``p_coherence``: do neighbouring voxels' vectors agree? Statistic: the sum over pairs of
  grid neighbours of w_i . w_j. Catches patterns with no net resultant (a scale error's outward
  vectors, a rotation's swirl, opposing vectors in halves).

Why magnitudes and not only directions (the tests before these flipped the signs of unit
vectors, exact under a sign-symmetric null for any noise shape): a lidar's sampling is not
independent from voxel to voxel (two scans' ray lattices differ by the same phase everywhere),
so a sampling pattern far below its own noise has directions that agree, and a direction-only
test called every fault-free pair of simulated scans ``patterned`` (the simulated intersection,
two VLP-16 samplings from the same place: p_coherence 0.001-0.02). Measured in whitened units,
that agreement is noise-sized and the tests say ``random``, while 3 mm of shift or a range scale
of 1.003 stays ``patterned`` (p 0.001).

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
# The null draws' correlation between neighbouring voxels (module docstring): about the middle
# of the 0.05-0.20 measured on fault-free pairs that read random (docs/diagnosis.md).
NULL_NEIGHBOUR_CORRELATION = 0.1
_CHUNK = 16  # null draws evaluated at a time (bounds memory on grids of 10^5 voxels)


def randomness_tests(
    whitened: np.ndarray, neighbours: tuple[np.ndarray, np.ndarray], axes: np.ndarray | None = None, seed: int = SEED
) -> dict:
    """``p_direction``, ``p_coherence`` and ``verdict`` of (M, 3) whitened vectors with grid
    neighbour pairs (two index arrays into them); ``axes`` (M, 3): the unit normal of each
    vector read along it alone (``significance.surface_axes``), NaN for the others. See the
    module docstring."""
    m = len(whitened)
    if m < MIN_VOXELS:
        return {"p_direction": math.nan, "p_coherence": math.nan, "verdict": "undetermined"}
    first, second = neighbours
    along = None if axes is None else np.flatnonzero(np.all(np.isfinite(axes), axis=1))
    normals = None if along is None else axes[along]
    if along is not None:  # a vector read along its normal is tested along it (a no-op for the kernel's)
        whitened = whitened.copy()
        whitened[along] = normals * np.einsum("vi,vi->v", whitened[along], normals)[:, None]
    observed_direction = float(np.sum(np.sum(whitened, axis=0) ** 2))
    observed_coherence = float(np.einsum("ij,ij->", whitened[first], whitened[second]))
    rng = np.random.default_rng(seed)
    exceed_direction = exceed_coherence = 0
    # A relative tolerance so that a draw equal to the observed value up to rounding counts.
    tol_direction = 1e-9 * max(1.0, abs(observed_direction))
    tol_coherence = 1e-9 * max(1.0, abs(observed_coherence))
    mixing = neighbour_mixing(first, second, m)
    for start in range(0, PERMUTATIONS, _CHUNK):
        noise = rng.standard_normal(size=(min(_CHUNK, PERMUTATIONS - start), m, 3))
        if mixing is not None:
            noise = mix(mixing, noise)
        if along is not None:
            noise[:, along] = np.einsum("kv,vi->kvi", np.einsum("kvi,vi->kv", noise[:, along], normals), normals)
        direction = np.sum(noise.sum(axis=1) ** 2, axis=1)
        coherence = np.einsum("kij,kij->k", noise[:, first], noise[:, second])
        exceed_direction += int(np.count_nonzero(direction >= observed_direction - tol_direction))
        exceed_coherence += int(np.count_nonzero(coherence >= observed_coherence - tol_coherence))
    p_direction = (1 + exceed_direction) / (1 + PERMUTATIONS)
    p_coherence = (1 + exceed_coherence) / (1 + PERMUTATIONS) if len(first) else math.nan
    patterned = min(p_direction, p_coherence if len(first) else 1.0) <= LEVEL / 2
    return {"p_direction": p_direction, "p_coherence": p_coherence, "verdict": "patterned" if patterned else "random"}


def correlated_noise(noise: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """(K, M, 3) independent standard normal draws made to correlate by
    ``NULL_NEIGHBOUR_CORRELATION`` between grid neighbours (the pairs ``first``, ``second``):
    each voxel's draw plus beta times the sum of its neighbours', rescaled to unit variance.
    Two neighbours then share 2 beta / sqrt((1 + d_i beta^2)(1 + d_j beta^2)) (d their neighbour
    counts); beta is solved for the grid's usual four neighbours."""
    mixing = neighbour_mixing(first, second, noise.shape[1])
    return noise if mixing is None else mix(mixing, noise)


def neighbour_mixing(first: np.ndarray, second: np.ndarray, voxels: int):
    """The sparse (M, M) operator of ``correlated_noise``, or None where it is the identity
    (no correlation, no neighbours). Built once per test: a sparse product is ten times faster
    than scattering each chunk's neighbour sums (``np.add.at``) on grids of 10^4 voxels."""
    rho = NULL_NEIGHBOUR_CORRELATION
    if rho == 0 or len(first) == 0:
        return None
    from scipy.sparse import coo_matrix, diags

    beta = (1.0 - math.sqrt(1.0 - 4.0 * rho**2)) / (4.0 * rho)
    rows = np.concatenate([first, second])
    adjacency = coo_matrix((np.ones(len(rows)), (rows, np.concatenate([second, first]))), shape=(voxels, voxels))
    degree = np.bincount(rows, minlength=voxels)
    return diags(1.0 / np.sqrt(1.0 + degree * beta**2)) @ (diags(np.ones(voxels)) + beta * adjacency).tocsr()


def mix(mixing, noise: np.ndarray) -> np.ndarray:
    """``mixing`` (M, M) applied to every draw of (K, M, 3) ``noise``."""
    k, m, _ = noise.shape
    columns = np.ascontiguousarray(noise.transpose(1, 0, 2)).reshape(m, 3 * k)
    return np.ascontiguousarray((mixing @ columns).reshape(m, k, 3).transpose(1, 0, 2))


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
