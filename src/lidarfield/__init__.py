"""lidarfield: discrepancy-vector fields between registered lidar scans, and hypotheses that
explain them.

The public API is flat (``lidarfield.read_scan``, ``lidarfield.discrepancy_field``,
``lidarfield.apply_stack``, ...). Names are imported on first use, so that ``import
lidarfield`` and every workflow job stay fast: Open3D alone takes over a second to import.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

# public name -> module that defines it
_EXPORTS = {
    # errors and data types
    "LidarfieldError": "errors",
    "InputError": "errors",
    "ConfigError": "errors",
    "HypothesisError": "errors",
    "RegistrationError": "errors",
    "Scan": "scan",
    "RegisteredPair": "pair",
    "read_pair": "pair",
    "write_pair": "pair",
    "SensorModel": "sensors",
    "sensor_model": "sensors",
    # scans and poses
    "read_scan": "io",
    "write_scan": "io",
    "scan_count": "io",
    "describe_file": "describe",
    "write_bag": "io.bag_writer",
    "interpolate_pose": "poses",
    "read_pose": "poses",
    "read_kitti_poses": "poses",
    "pose_from_xyzrpy": "poses",
    "parse_pose_arg": "poses",
    "apply_pose": "poses",
    "relative_pose": "poses",
    "pose_error": "poses",
    # grids and the field
    "SphericalGrid": "grid",
    "CartesianGrid": "grid",
    "FieldSettings": "grid",
    "grid_from_config": "grid",
    "field_settings_from_config": "grid",
    "discrepancy_field": "field",
    "field_from_voxel_ids": "field",
    "read_field": "field",
    "write_field": "field",
    "discrepancy_field_reference": "field_reference",
    "field_statistics": "analysis.field_stats",
    "analyse_field": "analysis.field_stats",
    "suggestions": "analysis.suggest",
    # simulation
    "load_scene": "scene",
    "builtin_scenes": "scene",
    "Scene": "scene",
    "simulate_scan": "simulate",
    "arc_trajectory": "trajectory",
    # registration
    "register_pair": "registration",
    "translation_from_aligned_copy": "registration",
    # hypotheses and stages
    "available_hypotheses": "hypotheses",
    "validate_stack": "hypotheses",
    "apply_stack": "stack",
    "Stage": "stack",
    "run_pair": "pipeline",
    "stage_ids": "stages",
    "load_config": "config",
    # figures and reports
    "plot_stage": "plots",
    "plot_pair": "plots",
    "write_report": "report",
    "compare_studies": "report",
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'lidarfield' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__():
    return __all__
