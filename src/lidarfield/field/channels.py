"""Channel-aware binning: no elevation band edge on a lidar channel, no azimuth column edge on
its firings.

A spinning lidar's points lie on one cone per channel and, where its firings are locked to its
encoder (the simulator, an Ouster), on a lattice of azimuths. A band edge on a channel puts every
point of that channel on the edge: the band each lands in is decided by floating-point rounding
and, for scan 2, by sub-millimetre differences in where its sensor stood, so a whole ring moves
between voxels and the field reads a pattern that is not there (issue 35).

So, where the channels are known, each edge of the field's spherical grid is moved to midway
between the two channels around it (bands of whole channels), and where a sensor model gives
the azimuth sampling and the scans' azimuths sit on its lattice (firings locked to the
encoder: the simulator, the shared OS1-128 frames; not a real Velodyne, whose firings drift
from sweep to sweep), each
column edge to midway between two firings. The channels come from
the scans' sensor models, else from their ``ring`` attribute (the median elevation of each
ring's points about its own sensor). Points are still binned by their measured angles, not by
their ring: the grid stays a function of coordinates, so the kernel, its plain reference, the
hypotheses and the plots bin alike, and scan 2's rings are cones about sensor 2, not about
sensor 1 where the grid is. A grid that gives no ``elevation_deg`` follows the sensor: its
span reaches half a gap beyond the outer channels, in ``elevation_bins`` bands of whole
channels.

Without a model or rings nothing moves; when the points' elevations cluster within
``NOISE_DEG`` of an edge, ``Binning.warning`` says so in one line.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from ..pair import RegisteredPair
from ..poses import in_sensor_frame
from .grid import SENSORLESS_ELEVATION_DEG, FieldSettings, SphericalGrid

# Elevation noise of one channel's points (deg): channels nearer than this are one channel, and
# the points within this of an edge are "on" it for the warning.
NOISE_DEG = 0.05
# The warning's test: at least this share of the points within NOISE_DEG of an edge, and this
# many times what the points' density within 10 x NOISE_DEG of the edge would put there.
CLUSTER_MIN_SHARE = 0.005
CLUSTER_RATIO = 2.5
# The firings of a cloud are on a lattice of azimuths when the mean resultant length of their
# phase on it is at least this (the simulator's: 1; the shared OS1-128 frame's: 0.98; the real
# VLP-16 and HDL-32E scans', whose firings drift from sweep to sweep: 0.02 and 0.08). Every
# PHASE_SUBSAMPLE-th point is enough to tell.
LOCKED_RESULTANT = 0.9
PHASE_SUBSAMPLE = 7
# A ring with fewer points than this does not count as a channel (a stray return).
MIN_RING_POINTS = 10
# A ring whose points lie farther than this from their median elevation (half of them at
# least; deg) is no channel: a driver's ring 0 for every point, or a rig's other lidar seen from
# this one. (The free-space rows drop a ring by another test, its distance from the channel it
# is matched to: field.free_space.channel_rows.)
RING_SPREAD_DEG = 0.5
# An edge within this of a channel (deg), or of a firing (in steps), is on it.
_ON = 1e-6


@dataclass(frozen=True)
class Binning:
    """The grid a pair's field uses (``settings``), why (``reason``), and a warning ('' or one
    line) when points cluster on an edge nobody could move."""

    settings: FieldSettings
    reason: str
    warning: str = ""

    def statistics(self) -> dict:
        """The summary columns: the edges used, the reason and the warning."""
        grid = self.settings.grid
        spherical = isinstance(grid, SphericalGrid)
        return {
            "elevation_edges_deg": [float(e) for e in grid.elevation_edges()] if spherical else None,
            "azimuth_edges_deg": [float(e) for e in grid.azimuth_edges()] if spherical else None,
            "binning": self.reason,
            "binning_warning": self.warning,
        }


def pair_binning(settings: FieldSettings, pair: RegisteredPair) -> Binning:
    """The grid of ``settings`` made channel-aware for ``pair`` (see the module docstring)."""
    grid = settings.grid
    if not isinstance(grid, SphericalGrid):
        return Binning(settings, "cartesian grid: no bands nor columns")
    elevation, elevation_reason, warning = _elevation_edges(grid, pair)
    azimuth, azimuth_reason = _azimuth_edges(grid, pair)
    effective = replace(settings, grid=grid.with_edges(elevation, azimuth))
    return Binning(effective, "; ".join(filter(None, (elevation_reason, azimuth_reason))), warning)


def _elevation_edges(grid: SphericalGrid, pair: RegisteredPair) -> tuple[np.ndarray, str, str]:
    """The band edges, why, and the warning ('' where the channels are known)."""
    channels, source = pair_channels(pair)
    if channels is None:
        edges = grid.elevation_edges()
        given = "the grid gives no elevation_deg" if grid.follows_sensor else "edges as given"
        reason = f"no sensor model nor rings: elevation [{edges[0]:g}, {edges[-1]:g}] deg, {given}"
        return edges, reason, edge_warning(edges, pair)
    if not grid.follows_sensor:
        edges = edges_between_channels(grid.elevation_edges(), channels)
        return edges, _moved("elevation", grid.elevation_edges(), edges, source), ""
    edges = edges_between_channels(sensor_span_edges(channels, grid.elevation_bins), channels)
    reason = (
        f"elevation [{edges[0]:.4g}, {edges[-1]:.4g}] deg from {source} (half a gap beyond the outer "
        f"channels; the grid gives no elevation_deg), {len(edges) - 1} bands of whole channels"
    )
    return edges, reason, ""


def _azimuth_edges(grid: SphericalGrid, pair: RegisteredPair) -> tuple[np.ndarray, str]:
    """The column edges and why ('' without a sensor model: the azimuth sampling is unknown)."""
    edges = grid.azimuth_edges()
    model = pair.sensor1 or pair.sensor2
    if model is None:
        return edges, ""
    step = 360.0 / model.firings_per_revolution
    phases = [firing_phase(xyz, step) for xyz in (pair.xyz1, pair.xyz2)]
    phase = edge_phase(phases, step)
    if phase is None:
        return edges, f"azimuth edges as given: the scans' azimuths are not on a lattice of {model.name}'s {step:g} deg"
    reference = next(p for p in phases if p is not None)  # scan 1's lattice where it has one
    moved = edges_at_phase(edges, phase, step, reference)
    return moved, _moved("azimuth", edges, moved, f"the firings, {step:g} deg apart")


def pair_channels(pair: RegisteredPair) -> tuple[np.ndarray | None, str]:
    """The channels' elevations (deg) about their sensors, and where they come from: both scans'
    sensor models, else their rings; (None, '') without either."""
    models = [m for m in (pair.sensor1, pair.sensor2) if m is not None]
    if models:
        channels = np.concatenate([np.asarray(m.elevation_deg, dtype=np.float64) for m in models])
        return channels, "the channels of " + " and ".join(dict.fromkeys(m.name for m in models))
    measured = [
        ring_elevations(xyz, attributes["ring"], pose)
        for xyz, attributes, pose in (
            (pair.xyz1, pair.attributes1, np.eye(4)),
            (pair.xyz2, pair.attributes2, pair.T_1_2),
        )
        if "ring" in attributes
    ]
    if not measured or not sum(len(m) for m in measured):
        return None, ""
    channels = np.concatenate(measured)
    return channels, f"{len(merged_channels(channels))} channels measured from the scans' rings"


@dataclass(frozen=True)
class Rings:
    """A scan's rings as its returns measure them. A ring's returns lie on its beam's cone, so
    their elevation about the sensor is the beam's but for noise and mixed returns (a footprint
    split across a depth edge, a return of the next beam's target): the median is the beam's,
    where the mean moves towards those."""

    names: np.ndarray  # the ring numbers present, ascending
    counts: np.ndarray  # each ring's number of returns
    elevation: np.ndarray  # the median elevation of each ring's returns (the unit given)
    index: np.ndarray  # each return's ring as an index into ``names``; -1: no ring
    groups: list[np.ndarray] = field(repr=False)  # each ring's elevations

    @cached_property
    def spread(self) -> np.ndarray:
        """The median distance of each ring's returns from its elevation: asked for by the
        binning's edges, not by the range images (half the cost of ``measured_rings`` there)."""
        return np.array([np.median(np.abs(g - m)) for g, m in zip(self.groups, self.elevation)])


def measured_rings(elevation: np.ndarray, ring: np.ndarray) -> Rings:
    """The rings of returns at ``elevation`` (about their sensor) carrying ``ring``; returns
    without a ring (NaN, negative) or without a finite elevation belong to none."""
    elevation = np.asarray(elevation, dtype=np.float64)
    ring = np.asarray(ring, dtype=np.float64)
    known = np.flatnonzero(np.isfinite(ring) & (ring >= 0) & np.isfinite(elevation))
    which = ring[known].astype(np.int64)  # rings are small whole numbers: counted, not sorted
    present = np.bincount(which) > 0
    names = np.flatnonzero(present)
    index = (np.cumsum(present) - 1)[which]
    counts = np.bincount(index, minlength=len(names))
    # grouped by ring: a stable sort of 16-bit keys is a radix sort
    order = np.argsort(index.astype(np.uint16 if len(names) <= 1 << 16 else np.int64), kind="stable")
    groups = np.split(elevation[known[order]], np.cumsum(counts)[:-1]) if len(names) else []
    median = np.array([np.median(g) for g in groups])
    every = np.full(len(ring), -1, dtype=np.int64)
    every[known] = index
    return Rings(names, counts, median, every, groups)


def ring_elevations(xyz: np.ndarray, ring: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """The elevation (deg) of each ring about the sensor at ``pose`` (the sensor's pose in the
    points' frame; :func:`measured_rings`), rings of at least MIN_RING_POINTS points whose
    points lie within RING_SPREAD_DEG of it (half of them at least)."""
    local = in_sensor_frame(np.asarray(xyz, dtype=np.float64), pose)
    rings = measured_rings(np.degrees(np.arctan2(local[:, 2], np.hypot(local[:, 0], local[:, 1]))), ring)
    return rings.elevation[(rings.counts >= MIN_RING_POINTS) & (rings.spread <= RING_SPREAD_DEG)]


def merged_channels(channels: np.ndarray) -> np.ndarray:
    """Sorted channels, those within NOISE_DEG of their neighbour merged into their mean (the
    same channel in a model and in measured rings, or of two scans)."""
    c = np.sort(np.asarray(channels, dtype=np.float64))
    if len(c) == 0:
        return c
    group = np.concatenate([[0], np.cumsum(np.diff(c) > NOISE_DEG)])
    return np.bincount(group, weights=c) / np.bincount(group)


def sensor_span_edges(channels: np.ndarray, bands: int) -> np.ndarray:
    """``bands`` + 1 even edges from half a channel gap below the lowest channel to half a gap
    above the highest (edges_between_channels then moves the inner ones between channels)."""
    c = merged_channels(channels)
    if len(c) < 2:
        return np.linspace(*SENSORLESS_ELEVATION_DEG, bands + 1)
    lo, hi = c[0] - (c[1] - c[0]) / 2, c[-1] + (c[-1] - c[-2]) / 2
    return np.linspace(lo, hi, bands + 1)


def edges_between_channels(edges: np.ndarray, channels: np.ndarray) -> np.ndarray:
    """Each edge within the channels' span (up to one gap beyond the outer channels, as wide as
    the outer gap) moved to midway between the two channels around it; edges farther out stay.
    Edges sharing a gap (bands narrower than a wide gap, as below a VLP-32C's -15.6 deg) are
    spread evenly across it. An edge on a channel moves down (the channel stays in the band above
    it, as a bin's lower edge belongs to it), the top edge up (the grid's last band holds its top)."""
    c = merged_channels(channels)
    edges = np.asarray(edges, dtype=np.float64)
    if len(c) < 2:
        return edges.copy()
    padded = np.concatenate([[2 * c[0] - c[1]], c, [2 * c[-1] - c[-2]]])
    gap = np.full(len(edges), -1)
    for i, edge in enumerate(edges):
        nearest = padded[np.argmin(np.abs(padded - edge))]
        edge = nearest if abs(nearest - edge) < _ON else edge
        if padded[0] < edge < padded[-1]:
            gap[i] = np.searchsorted(padded, edge, side="left" if i < len(edges) - 1 else "right") - 1
    moved = edges.copy()
    for j in np.unique(gap[gap >= 0]):
        sharing = np.flatnonzero(gap == j)
        moved[sharing] = padded[j] + (padded[j + 1] - padded[j]) * np.arange(1, len(sharing) + 1) / (len(sharing) + 1)
    return moved


def firing_phase(xyz: np.ndarray, step_deg: float) -> float | None:
    """Where (deg, in [0, step)) the points' azimuths about the origin sit on a lattice of
    ``step_deg``, or None when they do not (mean resultant length of the phase below
    LOCKED_RESULTANT: firings not locked to fixed azimuths, or a sensor elsewhere)."""
    xyz = np.asarray(xyz, dtype=np.float64)[::PHASE_SUBSAMPLE]
    angle = np.arctan2(xyz[:, 1], xyz[:, 0]) * (360.0 / step_deg)  # one lattice step = one turn
    angle = angle[np.isfinite(angle)]
    if not len(angle):
        return None
    resultant = np.mean(np.exp(1j * angle))
    if abs(resultant) < LOCKED_RESULTANT:
        return None
    return float(np.angle(resultant) / (2.0 * np.pi) * step_deg % step_deg)


def edge_phase(phases: list[float | None], step_deg: float) -> float | None:
    """The azimuth phase (deg, mod ``step_deg``) farthest from every given lattice phase: the
    middle of the widest gap between them (half a step from a single lattice); None without one."""
    known = np.sort([p % step_deg for p in phases if p is not None])
    if not len(known):
        return None
    gaps = np.diff(np.append(known, known[0] + step_deg))
    widest = int(np.argmax(gaps))
    return float((known[widest] + gaps[widest] / 2) % step_deg)


def edges_at_phase(edges: np.ndarray, phase_deg: float, step_deg: float, reference_deg: float = 0.0) -> np.ndarray:
    """Each azimuth edge moved to ``phase_deg`` (modulo ``step_deg``) inside its gap between the
    firings of the lattice at ``reference_deg``; an edge on one of those firings takes the gap
    above it. The gap depends on the reference lattice alone (scan 1's), so a small change of
    ``phase_deg`` (scan 2 turned by 0.01 deg) moves the edges a little, never to another gap."""
    k = (np.asarray(edges, dtype=np.float64) - reference_deg) / step_deg
    # on a firing within rounding: the same gap for edges 360 deg apart (360 / step is not
    # exact in floats, nor the firing count even)
    whole = np.round(k)
    gap = np.floor(np.where(np.abs(k - whole) < _ON, whole, k))
    return reference_deg + step_deg * gap + (phase_deg - reference_deg) % step_deg


def edge_warning(edges: np.ndarray, pair: RegisteredPair) -> str:
    """One line naming the elevation edges the points of both clouds (about sensor 1) cluster
    on, with the share of points within NOISE_DEG of each; '' when none."""
    xyz = np.vstack([pair.xyz1, pair.xyz2])
    if not len(xyz):
        return ""
    elevation = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
    elevation = elevation[np.isfinite(elevation)]
    clustered = []
    for edge in edges:
        distance = np.abs(elevation - edge)
        near = np.count_nonzero(distance <= NOISE_DEG) / len(elevation)
        around = np.count_nonzero(distance <= 10 * NOISE_DEG) / len(elevation) / 10
        if near >= CLUSTER_MIN_SHARE and near > CLUSTER_RATIO * around:
            clustered.append(f"{edge:g} deg ({near:.1%} of the points within {NOISE_DEG:g} deg)")
    if not clustered:
        return ""
    return (
        f"points cluster on elevation band edge(s) {', '.join(clustered)}: a lidar channel on an edge, "
        "which a sub-millimetre move shifts between bands; give the scans' sensor model or move the edge"
    )


def _moved(what: str, before: np.ndarray, after: np.ndarray, between: str) -> str:
    """Which ``what`` edges moved between ``between``, and by how much, in words."""
    shifted = np.flatnonzero(np.abs(after - before) > 1e-9)
    if not len(shifted):
        return f"{what} edges as given: each lies between {between}"
    pairs = ", ".join(f"{before[i]:.4g} -> {after[i]:.4g}" for i in shifted[:6])
    more = f" and {len(shifted) - 6} more" if len(shifted) > 6 else ""
    return f"{what} edges moved between {between}: {pairs}{more}"
