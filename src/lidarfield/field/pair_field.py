"""A pair's field as the field job computes it: binned channel-aware about sensor 1, with each
cloud's scan pattern and the change of viewpoint in its vectors' covariance. Here, below the
analysis and the hypotheses, so that both use the one computation (``realign`` refines its fit
on it)."""

from __future__ import annotations

import numpy as np

from ..pair import RegisteredPair
from .channels import Binning, pair_binning
from .free_space import shared_points
from .grid import FieldSettings
from .kernel import field_from_voxel_ids
from .significance import ScanPattern, Viewpoint


def pair_field(pair: RegisteredPair, settings: FieldSettings, binning: Binning | None = None):
    """The field's columns of a pair, binned about sensor 1 on the grid of ``settings`` made
    channel-aware for the pair (``field.channels``; ``binning``, when the caller has it), with
    each cloud's scan pattern and the change of viewpoint in its vectors' covariance; the
    binning and both clouds' voxel ids."""
    binning = binning or pair_binning(settings, pair)
    settings = binning.settings
    ids = settings.grid.assign(pair.xyz1), settings.grid.assign(pair.xyz2)  # binned once: the tags need them too
    shared = shared_points(pair)
    viewpoint = None if shared is None else Viewpoint(pair.origin2, *shared)
    columns = field_from_voxel_ids(
        ids[0], pair.xyz1, ids[1], pair.xyz2, settings, patterns=scan_patterns(pair), viewpoint=viewpoint
    )
    return columns, binning, ids


def scan_patterns(pair: RegisteredPair) -> tuple[ScanPattern | None, ScanPattern | None]:
    """Each cloud's lattice of rays in frame 1, from its sensor model (None without one)."""
    poses = (np.eye(4), pair.T_1_2)
    return tuple(
        None
        if sensor is None
        else ScanPattern(pose[:3, 3], pose[:3, 2], sensor.azimuth_resolution_deg, np.asarray(sensor.elevation_deg))
        for sensor, pose in zip((pair.sensor1, pair.sensor2), poses)
    )
