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

The scan pattern. A lidar's points in a voxel are not independent draws: they sit on the
sensor's lattice of rays (one azimuth step by one beam spacing), and where that lattice falls on
the surface (its phase) decides which points the voxel holds. Two samplings of the same surface
with different phases have means that differ by up to a lattice cell along the surface, whatever
the number of points (measured on the simulated intersection, two VLP-16 scans from the same
place: single-ring voxels whose means differ by 1-2 cm vertically along a wall, where S/n says
2 mm). So, given each cloud's ``ScanPattern`` (its sensor's origin, axis and angular steps),
C gains that cloud's **pattern covariance**: the lattice phase uniform over one cell, the
cell's two sides (r cos(el) d_az along the azimuth, r d_el along the elevation, at the cloud's
mean range r) carried onto the voxel's surface along the ray (longer on a surface seen
obliquely), variance side^2 / 12 along each. It lies in the surface's plane, so the part of d
along the normal, which a misregistration or a range error moves, keeps its own standard error.
A voxel holding one ring (its points spread less across the ray than a beam gap's side^2 / 12,
a uniform phase's variance) shows no surface: its points' thin direction is across the ring,
not the surface's normal (a ring on the ground seen from 11 m gave a "normal" 8 deg off
vertical; a sensor moved 5 cm shifted that ring's mean 4 cm along the ground, 5 mm off that
false plane: |w| = 9). There the beam gap's side stays across the ray and also runs along the
ray, up to its length at grazing incidence (1 / ``GRAZING_MIN`` times): the ring may lie on any
surface through it.

``whitened_vectors`` gives w = C^-1/2 d (symmetric root): under the null each w has mean 0 and
covariance at most I (C is an upper estimate), which is what the randomness tests assume.

On a surface seen from two places, the normal part only. A voxel whose points lie on one
surface that spans it
(planarity at least ``SURFACE_PLANARITY_MIN``: ten times thinner, in variance, along the
normal than across the patch) sees any motion of that surface, a misregistration's or a range
error's, through its normal part a = n . d alone: the voxel (a cone from sensor 1) cuts the
moved surface elsewhere, its mean moving by a / (n . s) along the line of sight s, whose part in
the surface's plane says nothing that a does not. What lies in the plane besides is sampling:
which part of the surface each sensor hit (the lattice's phase, the change of density with the
viewpoint), bounded above by the pattern and viewpoint terms but not known. From one place the
density is the same and the pattern term models the phase, so there the whole vector is read
(a field-of-view cut ending a surface inside a voxel shows only in-plane: read by the normal
part, six 90-deg cuts of the diagnosis zoo's pairs from one place read ``random``). Measured on the
simulated drives' pairs 3 m apart (exact poses): their ground voxels' whitened vectors of 6 to 9
lay in the plane with normal parts under 2, and made five of six patterned (p_coherence
0.001; one of six read so). So for such a voxel of a pair from two places (sensor 2's origin not sensor 1's) w =
(n . d) / sqrt(n^T C n) n: the normal part in units of its own standard error, along the normal
(the field's ``read_normal``; its ``se_normal``, sqrt(n^T C n), is kept for every surface voxel:
the field's rigid fit weighs the normal parts by it). Under the null it has variance at most 1 whatever n is
(C bounds every direction's), and the randomness tests draw its null along n alone.

Only where the line of sight crosses the surface. The argument needs the cone to cut the surface
across: a / (n . s) is a move along the ray only while n . s is not near 0. Planarity does not
say so: a surface that ends inside the voxel with another seen past it (the own car's roof 1-2 m
from the sensor and the ground 8 m beyond its edge, in one cone) is two flat patches at two
depths, which lie on one plane holding the rays (planarity 0.9-0.99, |n . s| 0.01-0.06 on the
diagnosis zoo's drives), and there the mean moves with the share of each patch (a carried roof's
edge moved 0.3 m in its plane: metres along that plane, a normal part under 1 standard error).
Such a voxel (|n . s| < ``GRAZING_MIN``, the grazing bound the pattern term stretches its
cell to, s from sensor 1, the cone's apex, to the voxel's centre) is read whole: its depth
along the rays is in C (the pattern's stretch along the ray, the content's spread in the
viewpoint term). Measured on the zoo (2026-11-28): the car body 0.3 m below the sensor reads
``patterned`` at stage 0 on the VLP-16's two drives and the VLP-32C's canyon drive (it read
``random``), with no control of the drives or the canyon lost; a roof spanning its voxels from
0.3 m apart (in-plane offsets 0.11-0.18 m, sampling) is still read by its normal part
(``test_significance.py``).

The viewpoint. Two sensors at different places sample the same surfaces with different
densities: per unit area a sensor's density is cos(incidence) / range^2 =
|n.(x - o)| / |x - o|^3 (n the surface's normal, o the sensor). A voxel's mean is the
density-weighted mean of its content, so when the weights change by a factor exp(g(x)) the mean
moves by Cov(x, g(x)) to first order, which by Cauchy-Schwarz lies in the ellipsoid
d^T S^-1 d <= Var(g) (S the spread of that content: of the voxel's shared points, below,
``surface.shared_spread``). Moving the sensor by b changes log |x - o| by at most |b| / r and
log |n.(x - o)| by at most |b| / (r facing) (facing = |ray . n|, capped at ``GRAZING_MIN`` like
the pattern's), so |g| <= (3 + 1 / facing) |b| / r =: k, Var(g) <= k^2, and C gains the
**viewpoint covariance** min(k, 1)^2 S, r the voxel's nearer range from the two sensors and n
its normal (none: grazing). The cap: the bound is first order, valid while the weights change
little; beyond, a voxel's mean is taken to move by at most its content's own spread (without it
the vehicle body a scan carries, 1-2 m from both sensors, hid in its own spread). The term
vanishes for one place (b = 0) and follows the voxel's content: a voxel mixing a wall's foot
and the ground spreads off the surface and gets variance there, a flat patch only in its plane,
so a misregistration or a range error keeps its standard error along the normal.

It bounds the change of density on what both sensors could see, and only there: S is the
spread of the voxel's **shared** points (``free_space.shared_points``: in the other sensor's
view and range limits, neither hidden from it by something it measured in front, nor where its
rays passed through), times the square of their share of the voxel's points (their mean makes
up that share of the voxel's mean). What only one sensor saw (beyond the other's field of view
or range limits, in its shadow, an object that moved) is no change of viewpoint on one surface
but content the other sensor lacks: it adds no variance, and its discrepancy stays significant,
which is what the hypotheses that prune it (``field_of_view``, ``shadow``, ``moving_objects``)
are for.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

SPREAD_MIN_POINTS = 5
# Rays meeting a surface at a grazing angle: the lattice cell's stretch along the surface is
# capped at 1 / GRAZING_MIN times its side (84 deg incidence); beyond that the voxel's in-plane
# mean says nothing either way.
GRAZING_MIN = 0.1
SPREAD_FLOOR_M = 0.001
# A sensor's sampling density per unit area is |n.(x - o)| / |x - o|^3: the exponent of the
# range, in the bound on how much a move of the sensor reweights a voxel's points.
VIEWPOINT_DENSITY_EXPONENT = 3.0
# The first-order bound holds while the reweighting is small; beyond it a voxel's mean is taken
# to move by at most its content's own spread (standard deviation 1 in units of S).
VIEWPOINT_MAX_REWEIGHT = 1.0
# A voxel this planar ((l2 - l3) / l2, ``surface``) holds one surface spanning it: the
# randomness tests read its normal part only (module docstring).
SURFACE_PLANARITY_MIN = 0.9
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


class Viewpoint(NamedTuple):
    """Sensor 2's origin (3,) in the field's frame, and per cloud the mask of its points the
    other sensor could have seen (``free_space.shared_points``)."""

    origin2: np.ndarray
    shared1: np.ndarray
    shared2: np.ndarray


class ScanPattern(NamedTuple):
    """Where a cloud's lattice of rays comes from, in the field's frame: the sensor's origin (3,)
    and rotation axis (3,, unit), its azimuth step and its beam elevations (degrees)."""

    origin: np.ndarray
    axis: np.ndarray
    azimuth_step_deg: float
    elevation_deg: np.ndarray


def beam_spacing_deg(elevation_deg: np.ndarray, at_deg: np.ndarray) -> np.ndarray:
    """The gap between neighbouring beams at elevations ``at_deg`` (interpolated between the
    gaps' centres; the nearest gap beyond the outermost beams); 0 for a single beam."""
    beams = np.sort(np.asarray(elevation_deg, dtype=np.float64))
    if len(beams) < 2:
        return np.zeros_like(at_deg)
    return np.interp(at_deg, 0.5 * (beams[1:] + beams[:-1]), np.diff(beams))


def pattern_covariance(mean: np.ndarray, normal: np.ndarray, spread: np.ndarray, pattern: ScanPattern) -> np.ndarray:
    """(6, V) covariance of a cloud's voxel means (3, V) from the phase of its lattice of rays,
    carried onto the surfaces with normals (3, V) (NaN normal: no surface, the cell's sides as
    they are, across the ray). Where the voxel's points, of (V, 3, 3) pooled ``spread``, span
    less than one beam gap across the ray (one ring), their thin direction is not the
    surface's: no surface either. See the module docstring."""
    relative = mean - np.asarray(pattern.origin, dtype=np.float64).reshape(3, 1)
    r = np.linalg.norm(relative, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ray = relative / r
        axis = np.asarray(pattern.axis, dtype=np.float64).reshape(3, 1)
        across = np.cross(axis, ray, axis=0)  # along the azimuth: |across| = cos(elevation)
        cos_el = np.linalg.norm(across, axis=0)
        along_azimuth = across / cos_el
        along_elevation = np.cross(ray, along_azimuth, axis=0)
        elevation = np.degrees(np.arctan2(np.einsum("ij,ij->j", axis, ray), cos_el))
        beam_gap_m = r * np.radians(beam_spacing_deg(pattern.elevation_deg, elevation))
        across_rings = np.einsum("ij,jik,kj->j", along_elevation, spread, along_elevation)
        one_ring = across_rings < beam_gap_m**2 / 12.0
        has_surface = np.all(np.isfinite(normal), axis=0) & ~one_ring
        surface = np.where(has_surface, normal, 0.0)
        facing = np.einsum("ij,ij->j", ray, surface)
        facing = np.where(np.abs(facing) < GRAZING_MIN, np.copysign(GRAZING_MIN, facing), facing)
        sides = []
        for tangent, side_m in (
            (along_azimuth, r * cos_el * np.radians(pattern.azimuth_step_deg)),
            (along_elevation, beam_gap_m),
            # One ring on a surface it does not show: the beam gap along the ray, up to grazing.
            (ray, np.where(one_ring, beam_gap_m / GRAZING_MIN, 0.0)),
        ):
            # A ray turned by the angle moves its hit point along the surface: t - (t.n / ray.n) ray.
            onto = tangent - np.where(has_surface, np.einsum("ij,ij->j", tangent, surface) / facing, 0.0) * ray
            sides.append(np.nan_to_num(onto * side_m))
    return np.stack([sum(side[a] * side[b] for side in sides) / 12.0 for a, b in COVARIANCE_ENTRIES])


def viewpoint_covariance(centre: np.ndarray, normal: np.ndarray, spread: np.ndarray, origins: tuple) -> np.ndarray:
    """(6, V) covariance of a vector from the change of viewpoint between the two sensors'
    ``origins`` ((3,) each), for voxels with (3, V) ``centre``s, normals (3, V; NaN: none,
    taken as grazing) and (V, 3, 3) pooled spreads (NaN: none). See the module docstring."""
    origin1, origin2 = (np.asarray(origin, dtype=np.float64).reshape(3, 1) for origin in origins)
    baseline = float(np.linalg.norm(origin2 - origin1))
    range1 = np.linalg.norm(centre - origin1, axis=0)
    r = np.minimum(range1, np.linalg.norm(centre - origin2, axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        facing = np.abs(np.einsum("ij,ij->j", (centre - origin1) / range1, normal))
        facing = np.maximum(np.where(np.isfinite(facing), facing, GRAZING_MIN), GRAZING_MIN)
        reweight = (VIEWPOINT_DENSITY_EXPONENT + 1.0 / facing) * baseline / r
        scale = np.minimum(reweight, VIEWPOINT_MAX_REWEIGHT) ** 2
    return np.nan_to_num(np.stack([scale * spread[:, a, b] for a, b in COVARIANCE_ENTRIES]))


def vector_covariance(
    n1: np.ndarray, covariance1: np.ndarray, n2: np.ndarray, covariance2: np.ndarray, terms: tuple = ()
) -> np.ndarray:
    """(6, V) covariance C of each vector: S1/n1 + S2/n2 (a cloud below ``SPREAD_MIN_POINTS``
    borrows the other's spread), the per-axis floor, and the further ``terms`` ((6, V) each:
    ``pattern_covariance``, ``viewpoint_covariance``). NaN where both counts are below ``SPREAD_MIN_POINTS``."""
    n1, n2 = n1.astype(np.float64), n2.astype(np.float64)
    own1, own2 = n1 >= SPREAD_MIN_POINTS, n2 >= SPREAD_MIN_POINTS
    spread1 = np.where(own1, covariance1, covariance2)
    spread2 = np.where(own2, covariance2, covariance1)
    with np.errstate(invalid="ignore", divide="ignore"):
        combined = spread1 / n1 + spread2 / n2
        combined[:3] += SPREAD_FLOOR_M**2 * (1.0 / n1 + 1.0 / n2)
    for term in terms:
        combined = combined + term
    combined[:, ~(own1 | own2)] = np.nan
    return combined


def surface_axes(normal: np.ndarray, planarity: np.ndarray) -> np.ndarray:
    """(3, V): the normal of each voxel holding one surface (planarity at least
    ``SURFACE_PLANARITY_MIN``), whose normal part alone the randomness tests read for a pair
    from two places; NaN elsewhere. See the module docstring."""
    with np.errstate(invalid="ignore"):
        surface = np.all(np.isfinite(normal), axis=0) & (np.asarray(planarity) >= SURFACE_PLANARITY_MIN)
    return np.where(surface, normal, np.nan)


def crosses_line_of_sight(normal: np.ndarray, centre: np.ndarray, origin) -> np.ndarray:
    """(V,) whether each voxel's surface, of normal (3, V; NaN: none) through its (3, V)
    ``centre``, meets the line of sight from ``origin`` (3,, sensor 1: the voxel's apex) at more
    than grazing, |n . s| >= ``GRAZING_MIN``: only there is its normal part all a motion of it
    shows (module docstring)."""
    sight = np.asarray(centre, dtype=np.float64) - np.asarray(origin, dtype=np.float64).reshape(3, 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        facing = np.abs(np.einsum("ij,ij->j", normal, sight)) / np.linalg.norm(sight, axis=0)
        return facing >= GRAZING_MIN


def read_by_normal_part(axes: np.ndarray, centre: np.ndarray, origins: tuple | None) -> np.ndarray:
    """(V,) whether the randomness tests read each voxel by its normal part alone: a surface
    (finite axis, 3 x V, ``surface_axes``) of a pair from two places (``origins``: both sensors'
    (3,) origins, None for one place) that the line of sight from sensor 1 to the voxel's (3, V)
    ``centre`` crosses (``crosses_line_of_sight``). See the module docstring."""
    if origins is None or not np.any(np.asarray(origins[0]) != np.asarray(origins[1])):
        return np.zeros(axes.shape[1], dtype=bool)
    return crosses_line_of_sight(axes, centre, origins[0])


def whitened_vectors(uvw: np.ndarray, combined: np.ndarray, axes: np.ndarray | None = None) -> np.ndarray:
    """C^-1/2 d (3, V) of vectors (3, V) with covariances (6, V, ``vector_covariance``); where
    ``axes`` (3, V, ``surface_axes``) is finite, (n . d) / sqrt(n^T C n) n instead; NaN where
    the vector or C is."""
    out = np.full(uvw.shape, np.nan)
    # Only where both are finite (a fine Cartesian grid has far more voxels than valid ones).
    good = np.flatnonzero(np.all(np.isfinite(uvw), axis=0) & np.all(np.isfinite(combined), axis=0))
    if len(good):
        matrix = np.empty((len(good), 3, 3))
        for row, (a, b) in enumerate(COVARIANCE_ENTRIES):
            matrix[:, a, b] = matrix[:, b, a] = combined[row, good]
        values, vectors = np.linalg.eigh(matrix)
        # C^-1/2 d = V diag(1 / sqrt(l)) V^T d, as matrix products (einsum's loops cost 4x more)
        along = (vectors.transpose(0, 2, 1) @ uvw[:, good].T[:, :, None])[:, :, 0]
        along /= np.sqrt(np.maximum(values, 1e-30))
        out[:, good] = (vectors @ along[:, :, None])[:, :, 0].T
    if axes is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            part = np.einsum("iv,iv->v", axes, uvw) / normal_standard_error(axes, combined)
        surface = np.isfinite(part)
        out[:, surface] = axes[:, surface] * part[surface]
    return out


def normal_standard_error(axes: np.ndarray, combined: np.ndarray) -> np.ndarray:
    """(V,) sqrt(n^T C n): the standard error of the normal part n . d of each vector with a
    finite axis n (3, V, ``surface_axes``) and covariance C (6, V, ``vector_covariance``);
    NaN elsewhere."""
    return np.sqrt(np.maximum(quadratic_form(combined, axes), 1e-30))


def quadratic_form(combined: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """(V,) v^T C v of vectors (3, V) with covariances (6, V) in ``COVARIANCE_ENTRIES`` order
    (the off-diagonal entries count twice)."""
    quadratic = np.zeros(vectors.shape[1])
    for row, (a, b) in enumerate(COVARIANCE_ENTRIES):
        quadratic += (1.0 if a == b else 2.0) * combined[row] * vectors[a] * vectors[b]
    return quadratic


def vector_standard_error(uvw: np.ndarray, combined: np.ndarray) -> np.ndarray:
    """se (V,) of each vector (3, V) along its own direction from its covariance (6, V,
    ``vector_covariance``); NaN where it is undefined. See the module docstring."""
    with np.errstate(invalid="ignore", divide="ignore"):
        length2 = np.einsum("ij,ij->j", uvw, uvw)
        along = quadratic_form(combined, uvw) / length2
        # A zero vector has no direction: its se is the mean of the three axes' variances.
        along = np.where(length2 > 0, along, (combined[0] + combined[1] + combined[2]) / 3.0)
        se = np.sqrt(np.maximum(along, 0.0))
    se[~np.isfinite(length2)] = np.nan
    return se


def z_score(magnitude: np.ndarray, se: np.ndarray) -> np.ndarray:
    """|d| / se (NaN where either is)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return magnitude / se
