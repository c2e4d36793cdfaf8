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
    "SensorModel": "sensors.models",
    "sensor_model": "sensors.models",
    # scans and poses
    "read_scan": "io",
    "write_scan": "io",
    "scan_count": "io",
    "describe_file": "io.describe",
    "write_bag": "io.rosbag.writer",
    "interpolate_pose": "poses",
    "read_pose": "io.pose_files",
    "read_kitti_poses": "io.pose_files",
    "pose_from_xyzrpy": "poses",
    "parse_pose_arg": "poses",
    "apply_pose": "poses",
    "relative_pose": "poses",
    "pose_error": "poses",
    # grids and the field
    "SphericalGrid": "field.grid",
    "CartesianGrid": "field.grid",
    "FieldSettings": "field.grid",
    "grid_from_config": "field.grid",
    "field_settings_from_config": "field.grid",
    "discrepancy_field": "field.kernel",
    "field_from_voxel_ids": "field.kernel",
    "read_field": "field.file",
    "write_field": "field.file",
    "discrepancy_field_reference": "field.reference",
    "field_statistics": "analysis.field_stats",
    "analyse_field": "analysis.field_stats",
    "suggestions": "analysis.suggest",
    # simulation
    "load_scene": "simulation.scene",
    "builtin_scenes": "simulation.scene",
    "Scene": "simulation.scene",
    "simulate_scan": "simulation.raycast",
    "arc_trajectory": "simulation.trajectory",
    # registration
    "register_pair": "registration",
    "translation_from_aligned_copy": "registration",
    # hypotheses and stages
    "available_hypotheses": "hypotheses",
    "validate_stack": "hypotheses",
    "apply_stack": "study.stack",
    "Stage": "study.stack",
    "read_stage_points": "storage.stage_points",
    "stage_files": "storage.stage_points",
    "run_pair": "commands.scans",
    "explain_pair": "study.explain_loop",
    "ExplainSettings": "analysis.stopping_rule",
    "explain_scans": "commands.scans",
    "stage_ids": "storage.stage_ids",
    "load_config": "study.config",
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
