"""The study config: loaded from YAML, validated once against the JSON schema, defaults filled.

The schema (``workflow/schemas/config.schema.yaml``, shipped in the package as
``lidarfield/schemas/config.schema.yaml``) is the one source of truth: the Snakemake workflow
and ``lidarfield run`` both go through :func:`validate_config`. Relative paths in a config are
relative to the folder the study is run from (the working directory), as in Snakemake.

Validation also expands ``sequences`` into consecutive pairs and resolves every scan of the
study into a :class:`ScanSpec`, so that the workflow knows all its jobs when it is parsed.
"""

from __future__ import annotations

import copy
import glob
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import jsonschema
import numpy as np
import yaml

from .errors import ConfigError, LidarfieldError
from .poses import pose_from_xyzrpy
from .stages import stage_ids
from .yaml_file import read_yaml

SCHEMA_PATH = Path(__file__).parent / "schemas" / "config.schema.yaml"
# The results folder's own subfolders, beside one folder per pair: no pair may take their names.
RESULTS_FOLDERS = ("scans", "logs", "benchmarks", "assets", "study")


@dataclass(frozen=True)
class ScanSpec:
    """One scan of the study: simulated from a scene, or read from a file."""

    id: str  # unique in the study; the scan's file is results/scans/{kind}/{id}.parquet
    kind: str  # "simulated" | "recorded"
    spec: dict  # JSON-able settings of the simulate or ingest job


@dataclass(frozen=True)
class PairSpec:
    name: str
    scan1: ScanSpec
    scan2: ScanSpec
    register: str | dict

    def inputs(self) -> dict:
        """What ``hash_0`` of the pair's stage ids covers."""
        return {"scan1": self.scan1.spec, "scan2": self.scan2.spec, "register": self.register}


@dataclass
class Study:
    config: dict  # validated, defaults filled in
    base_dir: Path
    pairs: dict[str, PairSpec]
    grid: dict
    hypotheses: list[dict]  # normalised stack, defaults filled in
    plots: dict
    scans: dict[str, ScanSpec] = field(default_factory=dict)
    suggest: list[dict] | None = None  # the config's candidates, normalised; None: the default
    plot_pairs: list[str] = field(default_factory=list)  # the pairs that get per-stage figures
    rematch: dict | None = None  # the validated rematch section; None: no rematching

    def stage_ids(self, pair: str) -> list[str]:
        return stage_ids(self.pairs[pair].inputs(), self.hypotheses, self.base_dir)

    def candidates(self, level: int) -> list[dict]:
        """The normalised candidate hypotheses of stage ``level`` (see ``suggest``)."""
        from .analysis.suggest import candidate_steps

        return candidate_steps(self.suggest, self.hypotheses[:level], self.base_dir, self.grid)


@cache
def schema() -> dict:
    return yaml.safe_load(SCHEMA_PATH.read_text())


def _fill_defaults(instance, subschema: dict, validator: jsonschema.Draft7Validator) -> None:
    """Fill in the schema's defaults, in place, in a config that has validated.

    Done after validation, not during it (jsonschema's FAQ recipe), because inside a
    ``oneOf`` the branches that fail would leave their defaults behind.
    """
    if "$ref" in subschema:
        subschema = {**_resolve(subschema["$ref"]), **{k: v for k, v in subschema.items() if k != "$ref"}}
    for key in ("oneOf", "anyOf"):
        if key in subschema:
            for branch in subschema[key]:
                if validator.evolve(schema=branch).is_valid(instance):
                    _fill_defaults(instance, branch, validator)
                    break
    if isinstance(instance, dict):
        properties = subschema.get("properties", {})
        for name, prop in properties.items():
            if name not in instance and "default" in prop:
                instance[name] = copy.deepcopy(prop["default"])
            if name in instance:
                _fill_defaults(instance[name], prop, validator)
        extra = subschema.get("additionalProperties")
        if isinstance(extra, dict):
            for name, value in instance.items():
                if name not in properties:
                    _fill_defaults(value, extra, validator)
    elif isinstance(instance, list) and isinstance(subschema.get("items"), dict):
        for item in instance:
            _fill_defaults(item, subschema["items"], validator)


def _resolve(ref: str) -> dict:
    """A local ``#/definitions/...`` reference of the config schema."""
    node = schema()
    for part in ref.removeprefix("#/").split("/"):
        node = node[part]
    return node


def _error_location(error: jsonschema.ValidationError) -> str:
    return ".".join(str(p) for p in error.absolute_path) or "(top level)"


def _non_finite_key(node, key: str = "") -> str | None:
    """The first key holding NaN or an infinity (JSON Schema's numbers admit them; the stage
    ids' canonical JSON cannot hold them)."""
    if isinstance(node, float) and not np.isfinite(node):
        return key or "(top level)"
    children = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for name, child in children:
        found = _non_finite_key(child, f"{key}.{name}" if key else str(name))
        if found:
            return found
    return None


def _check_schema(config: dict, source: str) -> None:
    validator = jsonschema.Draft7Validator(schema())
    errors = sorted(validator.iter_errors(config), key=lambda e: list(e.absolute_path))
    if not errors:
        key = _non_finite_key(config)
        if key:
            raise ConfigError(f"config key {key}: NaN or infinite; a finite number is needed", source)
        _fill_defaults(config, schema(), validator)
        return
    # oneOf failures bury the useful message: report the deepest one.
    error = errors[0]
    while error.context:
        error = max(error.context, key=lambda e: len(e.absolute_path))
    raise ConfigError(f"config key {_error_location(error)}: {error.message}", source)


def load_config(path: str | Path, base_dir: str | Path | None = None, require_pairs: bool = True) -> Study:
    """Read a study YAML file and validate it (paths relative to ``base_dir``, default: cwd).

    ``require_pairs=False`` accepts a config without pairs (``lidarfield run`` takes its pair
    from the command line and uses only the grid, the hypotheses and the plots)."""
    path = Path(path)
    config = read_yaml(path, "config")
    if not isinstance(config, dict):
        raise ConfigError("a study config is a YAML mapping (pairs, grid, hypotheses, ...)", path)
    return validate_config(config, base_dir, source=str(path), require_pairs=require_pairs)


def validate_config(
    config: dict, base_dir: str | Path | None = None, source: str = "config", require_pairs: bool = True
) -> Study:
    """Validate a config dict in place (defaults filled in) and resolve its pairs and stack."""
    from .grid import grid_from_config
    from .hypotheses import validate_stack

    base_dir = Path.cwd() if base_dir is None else Path(base_dir)
    _check_schema(config, source)
    try:
        grid_from_config(config["grid"])
        if "rematch" in config:
            _check_rematch(config["rematch"])
        hypotheses = validate_stack(config["hypotheses"], base_dir, study_grid=config["grid"])
        suggest = None
        if config["suggest"] is not None:
            from .analysis.suggest import candidate_steps

            suggest = candidate_steps(config["suggest"], hypotheses, base_dir, config["grid"])
        pairs: dict[str, PairSpec] = {}
        for name, entry in config["pairs"].items():
            pairs[name] = _pair(name, entry, base_dir)
        for name, entry in config["sequences"].items():
            for pair in _sequence_pairs(name, entry, base_dir):
                if pair.name in pairs:
                    raise ConfigError(f"sequences.{name}: pair name {pair.name!r} is also a pair of 'pairs'")
                pairs[pair.name] = pair
    except LidarfieldError as e:
        raise type(e)(str(e) if e.path else f"{source}: {e}") from None
    taken = sorted(set(pairs) & set(RESULTS_FOLDERS))
    if taken:
        raise ConfigError(f"pair name(s) {taken} are folders of the results folder; rename the pair(s)", source)
    if require_pairs and not pairs:
        raise ConfigError("the study has no pairs: add entries under 'pairs' or 'sequences'", source)
    scans = {}
    for pair in pairs.values():
        scans[pair.scan1.id] = pair.scan1
        scans[pair.scan2.id] = pair.scan2
    plotted = plot_pairs(config["plots"]["pairs"], sorted(pairs), source)
    return Study(config, base_dir, pairs, config["grid"], hypotheses, config["plots"], scans, suggest, plotted, config.get("rematch"))


# A study of up to this many pairs gets every pair's stage figures by default; a larger one
# gets this many, evenly spaced (a drive's pairs are named in driving order).
AUTO_PLOT_PAIRS = 12


def figure_settings(plots: dict | None) -> dict:
    """The ``plots`` section without ``pairs``: which pairs get figures is the workflow's
    choice, not a figure's setting, so changing it redraws no figure."""
    return {k: v for k, v in (plots or {}).items() if k != "pairs"}


def plot_pairs(setting: str | list[str], names: list[str], source: str = "config") -> list[str]:
    """The pairs that get per-stage figures, in name order, for the ``plots.pairs`` setting.

    Decided when the config is read (the workflow knows its jobs when it is parsed), so
    ``auto`` goes by the number of pairs, not by any result."""
    if setting == "all" or (setting == "auto" and len(names) <= AUTO_PLOT_PAIRS):
        return list(names)
    if setting == "none":
        return []
    if setting == "auto":
        picks = np.unique(np.round(np.linspace(0, len(names) - 1, AUTO_PLOT_PAIRS)).astype(int))
        return [names[i] for i in picks]
    unknown = [name for name in setting if name not in names]
    if unknown and names:
        raise ConfigError(f"config key plots.pairs: unknown pair(s) {unknown}; the study's pairs are {names[:20]}", source)
    return [name for name in names if name in setting]


def _check_rematch(section: dict) -> None:
    """The rematch parameters are those of a register method: checked by the same parser."""
    from .registration.settings import parse_settings

    if {"method", "guess"} & set(section["parameters"]):
        raise ConfigError("rematch.parameters: method and guess are not parameters (see rematch.methods)")
    try:
        parse_settings({"method": section["methods"][0], **section["parameters"]})
    except LidarfieldError as e:
        message = str(e).replace("register: ", "").replace("register.", "")
        raise ConfigError(f"rematch.parameters: {message}") from None


# --- pairs -------------------------------------------------------------------------------------


def _existing_file(path: str, key: str, base_dir: Path) -> str:
    """A scan reference ``file``, ``file#k`` or ``bag#/topic#k`` whose file (or bag folder) exists."""
    from .io.rosbag import is_bag_folder

    file = base_dir / path.split("#", 1)[0]
    if not (file.is_file() or is_bag_folder(file)):
        raise ConfigError(f"{key}: file not found: {file}")
    return path


def _sensor(setting, key: str, base_dir: Path):
    """A scan's sensor setting (preset, YAML file, model, or none), checked now so that a bad
    one fails before any job."""
    from .sensors import sensor_model

    if isinstance(setting, str) and setting.endswith((".yaml", ".yml")):
        _existing_file(setting, f"{key}.sensor", base_dir)
        setting = str(base_dir / setting)
    try:
        sensor_model(setting)
    except LidarfieldError as e:
        raise ConfigError(f"{key}.sensor: {e}") from None


def _register(setting, key: str, base_dir: Path):
    """A pair's ``register`` setting, checked now so that a bad one fails before any job."""
    from .registration.settings import parse_settings

    if isinstance(setting, dict) and "transform" in setting:
        _existing_file(setting["transform"], f"{key}.register.transform", base_dir)
    try:
        parse_settings(setting, base_dir)
    except LidarfieldError as e:
        raise ConfigError(f"{key}.{e}") from None
    return setting


def _rounded(values) -> list:
    # Specs are hashed into stage ids: rounding keeps trigonometric last-bit noise out of them.
    return np.asarray(values, dtype=float).round(12).tolist()


def _simulated_scan(scan_id: str, sim: dict, pose, time_s: float, velocity, angular_velocity) -> ScanSpec:
    spec = {
        "scene": sim["scene"],
        "sensor": sim["sensor"],
        "pose": _rounded(pose),
        "time_s": float(time_s),
        "velocity_mps": _rounded(velocity),
        "angular_velocity_rps": _rounded(angular_velocity),
        **sim["options"],
    }
    return ScanSpec(scan_id, "simulated", spec)


def _recorded_scan(scan_id: str, entry: dict, path: str, pose=None) -> ScanSpec:
    spec = {"path": path, "format": entry.get("format"), "sensor": entry.get("sensor"), "pose": pose}
    if isinstance(entry.get("poses"), dict):  # from a topic of the bag, when the scan is read
        spec["poses"] = entry["poses"]
    return ScanSpec(scan_id, "recorded", spec)


def _pair(name: str, entry: dict, base_dir: Path) -> PairSpec:
    key = f"pairs.{name}"
    if "simulate" in entry:
        sim = _checked_simulation(entry["simulate"], f"{key}.simulate", base_dir)
        still = [[0.0, 0.0, 0.0]] * 2
        scans = [
            _simulated_scan(
                f"{name}-{i + 1}",
                sim,
                pose_from_xyzrpy(sim[f"pose{i + 1}"]),
                sim["time_s"][i],
                sim.get("velocity_mps", still)[i],
                sim.get("angular_velocity_rps", still)[i],
            )
            for i in (0, 1)
        ]
    else:
        _sensor(entry.get("sensor"), key, base_dir)
        scans = [
            _recorded_scan(f"{name}-{i}", entry, _existing_file(entry[f"scan{i}"], f"{key}.scan{i}", base_dir))
            for i in (1, 2)
        ]
    return PairSpec(name, scans[0], scans[1], _register(entry["register"], key, base_dir))


def _checked_simulation(sim: dict, key: str, base_dir: Path) -> dict:
    """A ``simulate`` section whose sensor and scene file (a built-in scene is the schema's
    business) are checked."""
    _sensor(sim["sensor"], key, base_dir)
    if sim["scene"].endswith((".yaml", ".yml")):
        _existing_file(sim["scene"], f"{key}.scene", base_dir)
    return sim


def _sequence_pairs(name: str, entry: dict, base_dir: Path) -> list[PairSpec]:
    key = f"sequences.{name}"
    scans = (
        _simulated_sequence(name, entry, base_dir) if "simulate" in entry else _recorded_sequence(name, entry, base_dir)
    )
    register = _register(entry["register"], key, base_dir)
    stride = entry["stride"]
    return [
        PairSpec(f"{name}-{i:03d}", scans[j], scans[j + stride], register)
        for i, j in enumerate(range(0, len(scans) - stride, stride))
    ]


def _simulated_sequence(name: str, entry: dict, base_dir: Path) -> list[ScanSpec]:
    from .trajectory import arc_trajectory

    sim = _checked_simulation(entry["simulate"], f"sequences.{name}.simulate", base_dir)
    rate_hz = sim["trajectory"]["rate_hz"]
    # The schema's trajectory keys are arc_trajectory's parameters.
    return [
        _simulated_scan(f"{name}-s{k:03d}", sim, pose, k / rate_hz, velocity, angular_velocity)
        for k, (pose, velocity, angular_velocity) in enumerate(arc_trajectory(**sim["trajectory"]))
    ]


def _recorded_sequence(name: str, entry: dict, base_dir: Path) -> list[ScanSpec]:
    from .io import scan_count
    from .poses import read_kitti_poses

    key = f"sequences.{name}.scans"
    _sensor(entry.get("sensor"), f"sequences.{name}", base_dir)
    scans = entry["scans"]
    if isinstance(scans, list):
        files = [_existing_file(s, key, base_dir) for s in scans]
    elif any(ch in scans for ch in "*?["):
        files = sorted(str(Path(p).relative_to(base_dir)) for p in glob.glob(str(base_dir / scans)))
        if not files:
            raise ConfigError(f"{key}: no file matches {scans!r} (relative to {base_dir})")
    else:
        _existing_file(scans, key, base_dir)
        container = scans if entry.get("topic") is None else f"{scans}#{entry['topic']}"
        files = [f"{container}#{k}" for k in range(scan_count(base_dir / container, sensor=entry.get("sensor")))]
    last = len(files) - 1 if entry["last"] is None else entry["last"]
    if not entry["first"] <= last < len(files):
        raise ConfigError(f"sequences.{name}: first/last ({entry['first']}, {last}) outside the {len(files)} scans")
    poses = None
    if isinstance(entry.get("poses"), str):
        _existing_file(entry["poses"], f"sequences.{name}.poses", base_dir)
        poses = read_kitti_poses(base_dir / entry["poses"], expected=len(files))
    return [
        _recorded_scan(f"{name}-s{k:03d}", entry, files[k], None if poses is None else poses[k].tolist())
        for k in range(entry["first"], last + 1)
    ]
