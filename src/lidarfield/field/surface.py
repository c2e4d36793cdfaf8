"""The local surface in each voxel: its normal and how planar it is, from the points' spread.

A voxel mean sees only the part of a motion normal to the surface inside the voxel (moving
points along a wall changes which points fall in the voxel, not their mean), so the field's
rigid part is fitted point-to-plane (``field.rigid_fit``) along these normals.

The spread is the **pooled within-cloud covariance** of the voxel,
S = ((n1 - 1) S1 + (n2 - 1) S2) / (n1 + n2 - 2): both clouds sample the same surface patch, so
pooling doubles the points behind the normal and treats the clouds alike, and each cloud is
taken about its *own* mean, so the discrepancy being diagnosed (cloud 2 shifted along the
normal) does not thicken the patch. A cloud with fewer than 2 points adds nothing.

With eigenvalues l1 >= l2 >= l3 of S and unit eigenvectors e1, e2, e3:

- the **normal** is e3 (the direction the points are thinnest in), oriented towards the
  binning origin (sensor 1): n . (centre - origin) <= 0;
- the **planarity** is (l2 - l3) / l2, in [0, 1]: how much thinner the points are along the
  normal than across the patch's narrower side. 1 for points on a plane (whatever the patch's
  aspect: a long strip of ground counts as fully planar), about 0 when the normal is
  undetermined (a blob, or a line: l2 = l3). It is the weight a voxel's normal gets in the
  point-to-plane fit. (The ratio is to l2, not to l1 as in the planarity of Demantke et al.,
  so that a strip elongated by the voxel's shape is not mistaken for a line.)

Computed for every voxel with at least 3 points in all and l2 above ``MIN_SPREAD_M2`` (NaN
otherwise: no surface to speak of) by one batched
``np.linalg.eigh`` over (V, 3, 3) matrices; the kernel keeps them for valid voxels only.
"""

from __future__ import annotations

import numpy as np

from .significance import COVARIANCE_ENTRIES

# A patch narrower than this (variance across its narrower side, m^2: 1 mm standard deviation)
# has no normal: its points lie on a line, or coincide.
MIN_SPREAD_M2 = 1e-6


def pooled_covariance(n1: np.ndarray, covariance1: np.ndarray, n2: np.ndarray, covariance2: np.ndarray) -> np.ndarray:
    """(V, 3, 3) pooled within-cloud covariance from (6, V) sample covariances in
    ``COVARIANCE_ENTRIES`` order (NaN where a count is below 2); NaN where n1 + n2 < 3."""
    n1, n2 = np.asarray(n1, np.float64), np.asarray(n2, np.float64)
    scatter = np.zeros((len(n1), 3, 3))
    for n, covariance in ((n1, covariance1), (n2, covariance2)):
        dof = np.where(n >= 2, n - 1.0, 0.0)
        for row, (a, b) in enumerate(COVARIANCE_ENTRIES):
            term = np.where(n >= 2, covariance[row], 0.0) * dof
            scatter[:, a, b] += term
            if a != b:
                scatter[:, b, a] += term
    dof = n1 + n2 - 2.0
    with np.errstate(invalid="ignore", divide="ignore"):
        pooled = scatter / dof[:, None, None]
    pooled[dof < 1] = np.nan
    return pooled


def normals_from_covariance(covariance: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normals (3, V) and planarity (V,) of (V, 3, 3) covariances, normals oriented towards the
    origin from the (3, V) ``centre``s; NaN where a covariance is NaN or l2 <= ``MIN_SPREAD_M2``."""
    finite = np.all(np.isfinite(covariance), axis=(1, 2))
    normal = np.full((3, len(covariance)), np.nan)
    planarity = np.full(len(covariance), np.nan)
    if not finite.any():
        return normal, planarity
    values, vectors = np.linalg.eigh(covariance[finite])  # ascending eigenvalues
    values = np.maximum(values, 0.0)
    e3 = vectors[:, :, 0]
    flip = np.einsum("ij,ji->i", e3, centre[:, finite]) > 0
    e3[flip] *= -1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        flat = np.where(values[:, 1] > MIN_SPREAD_M2, (values[:, 1] - values[:, 0]) / values[:, 1], np.nan)
    good = np.isfinite(flat)
    normal[:, np.flatnonzero(finite)[good]] = e3[good].T
    planarity[np.flatnonzero(finite)[good]] = flat[good]
    return normal, planarity


def shared_spread(
    n: np.ndarray, shared1: np.ndarray, covariance1: np.ndarray, shared2: np.ndarray, covariance2: np.ndarray
) -> np.ndarray:
    """(V, 3, 3) pooled covariance of the points both sensors could see, of counts ``shared1``,
    ``shared2`` and (6, V) covariances, times the square of their share of the voxel's ``n``
    points: the part of a voxel's mean that they make up moves by that share of their own
    mean's move. Zero where fewer than 3 are shared."""
    share = (shared1 + shared2) / np.maximum(np.asarray(n, np.float64), 1.0)
    pooled = pooled_covariance(shared1, covariance1, shared2, covariance2)
    return np.nan_to_num(pooled * (share**2)[:, None, None])
