"""The standard error of a field vector and its z score, from both clouds' spread in the voxel.

A field vector is d = mean2 - mean1. If each cloud's points in a voxel were independent draws
from that cloud's distribution there, d would have covariance C = S1/n1 + S2/n2 (S_k the
sample covariance of cloud k's points in the voxel, n_k its count). The scalar ``se`` is the
standard error of d along its own direction, sqrt(d^T C d) / |d|, and ``z = |d| / se``. Then
z^2 = |d|^4 / (d^T C d) <= d^T C^-1 d (Cauchy-Schwarz), the squared Mahalanobis length, which
is chi^2 with 3 degrees of freedom when both clouds sample the same surfaces: so under that
null P(z > 3) <= 2.9% and P(z > 4) <= 0.11%, whatever the shape of the spread (a flat patch
of ground gives a flat C, and vectors that lie in it).

Small counts: a cloud with fewer than ``SPREAD_MIN_POINTS`` points in a voxel has no usable
covariance of its own; it borrows the other cloud's (the same surface patch, seen by the other
sensor). With both below it, ``se`` and ``z`` are NaN. With the default ``min_points`` of 30 a
valid voxel never needs this. Every per-axis variance has a floor of ``SPREAD_FLOOR_M``^2 so
that a noise-free simulation (points exactly on a plane, a vector exactly in it) or rounding
in the sums cannot give se = 0.

What this does not know: a lidar's points in a voxel are not independent draws (the scan
pattern is regular, and the two sensors see a surface from different places), so se measures
sampling spread only; a real discrepancy with a consistent cause has z far above any threshold.
"""

from __future__ import annotations

import numpy as np

SPREAD_MIN_POINTS = 5
SPREAD_FLOOR_M = 0.001
# The order of the six distinct entries of a 3x3 covariance, as rows of a (6, V) array.
COVARIANCE_ENTRIES = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def covariance_from_sums(counts: np.ndarray, sums: np.ndarray, products: np.ndarray) -> np.ndarray:
    """(6, V) sample covariances (ddof 1) from per-voxel counts (V,), coordinate sums (3, V)
    and sums of products (6, V) in ``COVARIANCE_ENTRIES`` order; NaN where counts < 2.

    The sums are of coordinates relative to the binning origin (tens of metres), so the
    cancellation in sum(xy) - n mean_x mean_y costs about 1e-12 m^2: far below the floor.
    """
    counts = counts.astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = sums / counts
        covariance = np.empty_like(products)
        for row, (a, b) in enumerate(COVARIANCE_ENTRIES):
            covariance[row] = (products[row] - counts * mean[a] * mean[b]) / (counts - 1.0)
    covariance[:, counts < 2] = np.nan
    return covariance


def vector_standard_error(
    uvw: np.ndarray, n1: np.ndarray, covariance1: np.ndarray, n2: np.ndarray, covariance2: np.ndarray
) -> np.ndarray:
    """se (V,) of each vector (3, V) along its own direction; NaN where it is undefined (a NaN
    vector, or both counts below ``SPREAD_MIN_POINTS``). See the module docstring."""
    n1, n2 = n1.astype(np.float64), n2.astype(np.float64)
    own1, own2 = n1 >= SPREAD_MIN_POINTS, n2 >= SPREAD_MIN_POINTS
    spread1 = np.where(own1, covariance1, covariance2)
    spread2 = np.where(own2, covariance2, covariance1)
    with np.errstate(invalid="ignore", divide="ignore"):
        combined = spread1 / n1 + spread2 / n2
        length2 = np.einsum("ij,ij->j", uvw, uvw)
        # d^T C d / |d|^2 from the six distinct entries (off-diagonal ones count twice).
        quadratic = np.zeros(uvw.shape[1])
        for row, (a, b) in enumerate(COVARIANCE_ENTRIES):
            quadratic += (1.0 if a == b else 2.0) * combined[row] * uvw[a] * uvw[b]
        along = quadratic / length2
        # A zero vector has no direction: its se is the mean of the three axes' variances.
        along = np.where(length2 > 0, along, (combined[0] + combined[1] + combined[2]) / 3.0)
        floor = SPREAD_FLOOR_M**2 * (1.0 / n1 + 1.0 / n2)
        se = np.sqrt(np.maximum(along, 0.0) + floor)
    se[~(own1 | own2) | ~np.isfinite(length2)] = np.nan
    return se


def z_score(magnitude: np.ndarray, se: np.ndarray) -> np.ndarray:
    """|d| / se (NaN where either is)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return magnitude / se
