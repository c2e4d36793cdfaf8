"""Scenes to simulate: triangle meshes (trimesh) built from primitives or mesh files, each
object static or moving at a constant velocity.

A scene YAML::

    name: my-street                 # optional; defaults to the file's stem
    extends: paper-intersection     # optional: a built-in scene or a YAML path to add objects to
    objects:
      - {kind: plane, size: [40, 40]}                             # in the xy plane, normal +z
      - {kind: box, size: [4, 6, 8], center: [10, 0, 4]}
      - {kind: cylinder, radius: 0.3, height: 5, center: [3, 3, 2.5], sections: 32}
      - {kind: mesh, file: car.glb, transform: {translation: [5, -2, 0], rpy: [0, 0, 1.57]},
         velocity_mps: [-3, 0, 0]}
      - {kind: box, size: [5, 2, 2.3], center: [-1.5, 0, -1.65], frame: sensor}   # own vehicle body

Primitives are centred on their own origin; ``center`` (primitives only) and
``transform: {translation, rpy}`` (radians, R = Rz(yaw) Ry(pitch) Rx(roll)) place them, and
``scale`` scales a mesh file before the transform. Mesh files (OBJ, STL, PLY, GLB, ...) are
read by trimesh, relative to the YAML file. An object with ``frame: sensor`` is placed in the
sensor's frame and moves with it (the vehicle that carries the sensor): every scan sees it at the
same place, whatever the sensor's pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
import trimesh

from ..errors import ConfigError, InputError
from ..poses import pose_from_xyzrpy
from ..yaml_file import read_yaml

_KEYS = {
    "box": {"size"},
    "cylinder": {"radius", "height", "sections"},
    "plane": {"size"},
    "mesh": {"file", "scale"},
}
_COMMON_KEYS = {"name", "kind", "center", "transform", "velocity_mps", "frame"}
FRAMES = ("world", "sensor")
_REQUIRED = {"box": {"size"}, "cylinder": {"radius", "height"}, "plane": {"size"}, "mesh": {"file"}}


@dataclass(frozen=True)
class SceneObject:
    """One rigid object: its triangle mesh at time 0 and its velocity, in the world frame, or
    in the sensor's frame for an object the sensor carries (``frame == "sensor"``)."""

    name: str
    mesh: trimesh.Trimesh
    velocity_mps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    frame: str = "world"

    @property
    def carried(self) -> bool:
        return self.frame == "sensor"

    @property
    def moving(self) -> bool:
        return bool(np.any(self.velocity_mps != 0))

    def mesh_at(self, time_s: float) -> trimesh.Trimesh:
        """The mesh where the object is at ``time_s`` (moved by velocity x time)."""
        if not self.moving or time_s == 0:
            return self.mesh
        return self.mesh.copy().apply_translation(self.velocity_mps * time_s)


@dataclass(frozen=True)
class Scene:
    name: str
    objects: tuple[SceneObject, ...]
    source: str  # "builtin:NAME" or the YAML path

    def labelled_objects(self) -> list[tuple[int, SceneObject]]:
        """The objects a simulated point is labelled with (its ``object`` attribute), each with
        its label: its 1-based place in ``objects`` for one that moves in the world, minus that
        for one the sensor carries (its own vehicle: neither a moving object nor the static
        scene). Every other object is the static scene, label 0."""
        return [
            (-number if o.carried else number, o)
            for number, o in enumerate(self.objects, start=1)
            if o.moving or o.carried
        ]

    def mesh_at(self, time_s: float = 0.0) -> trimesh.Trimesh:
        """The world's objects (not those the sensor carries) as one mesh, each where it is at ``time_s``."""
        return trimesh.util.concatenate([o.mesh_at(time_s) for o in self.objects if not o.carried])


def builtin_scenes() -> list[str]:
    """The names of the built-in scenes (YAML files shipped in ``lidarfield/scenes``)."""
    folder = resources.files("lidarfield.simulation") / "scenes"
    return sorted(p.name.removesuffix(".yaml") for p in folder.iterdir() if p.name.endswith(".yaml"))


def load_scene(name_or_path: str | Path) -> Scene:
    """A built-in scene by name, or a scene YAML file."""
    spec = str(name_or_path)
    if spec in builtin_scenes():
        with resources.as_file(resources.files("lidarfield.simulation") / "scenes" / f"{spec}.yaml") as path:
            return _scene_from_file(Path(path), source=f"builtin:{spec}")
    path = Path(spec)
    if path.suffix in (".yaml", ".yml"):
        if not path.is_file():
            raise InputError("scene file not found", path)
        return _scene_from_file(path, source=str(path))
    raise ConfigError(f"unknown scene {spec!r}; built-in scenes: {', '.join(builtin_scenes())} (or a YAML file)")


def _scene_from_file(path: Path, source: str) -> Scene:
    spec = read_yaml(path, "scene")
    return scene_from_dict(spec, base_dir=path.parent, name=path.stem, source=source)


def scene_from_dict(spec: dict, base_dir: Path = Path("."), name: str = "scene", source: str | None = None) -> Scene:
    """A scene from its YAML description (see the module doc); mesh files relative to ``base_dir``."""
    where = source or name
    if not isinstance(spec, dict) or not isinstance(spec.get("objects", []), list):
        raise ConfigError("a scene is a mapping with a list 'objects'", where)
    unknown = set(spec) - {"name", "extends", "objects"}
    if unknown:
        raise ConfigError(f"unknown scene key(s) {sorted(unknown)}", where)
    base = ()
    if spec.get("extends") is not None:
        extends = str(spec["extends"])
        is_file = extends.endswith((".yaml", ".yml"))
        base = load_scene(Path(base_dir) / extends if is_file else extends).objects
    objects = tuple(_build_object(o, i, Path(base_dir), where) for i, o in enumerate(spec.get("objects") or []))
    if not base + objects:
        raise ConfigError("the scene has no objects", where)
    return Scene(str(spec.get("name", name)), base + objects, source or name)


def _build_object(spec: dict, index: int, base_dir: Path, where: str) -> SceneObject:
    if not isinstance(spec, dict):
        raise ConfigError(f"object {index}: expected a mapping, got {spec!r}", where)
    label = f"object {spec.get('name', index)!r}"
    kind = spec.get("kind")
    if kind not in _KEYS:
        raise ConfigError(f"{label}: kind must be one of {sorted(_KEYS)}, got {kind!r}", where)
    unknown = set(spec) - _COMMON_KEYS - _KEYS[kind]
    missing = _REQUIRED[kind] - set(spec)
    if unknown or missing:
        raise ConfigError(f"{label} ({kind}): unknown key(s) {sorted(unknown)}, missing {sorted(missing)}", where)
    try:
        mesh = _primitive_mesh(kind, spec, base_dir) if kind != "mesh" else _mesh_file(spec, base_dir)
        mesh.apply_transform(_placement(kind, spec))
        velocity = np.asarray(spec.get("velocity_mps", (0.0, 0.0, 0.0)), dtype=float).reshape(3)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{label} ({kind}): {e}", where) from None
    frame = spec.get("frame", "world")
    if frame not in FRAMES or (frame == "sensor" and np.any(velocity != 0)):
        raise ConfigError(
            f"{label} ({kind}): frame must be one of {list(FRAMES)}, and an object the sensor carries has no velocity",
            where,
        )
    return SceneObject(str(spec.get("name", f"{kind}-{index}")), mesh, velocity, frame)


def _primitive_mesh(kind: str, spec: dict, base_dir: Path) -> trimesh.Trimesh:
    if kind == "box":
        size = _positive(spec["size"], 3, "size")
        return trimesh.creation.box(extents=size)
    if kind == "cylinder":
        radius, height = _positive([spec["radius"], spec["height"]], 2, "radius, height")
        return trimesh.creation.cylinder(radius=radius, height=height, sections=int(spec.get("sections", 64)))
    sx, sy = _positive(spec["size"], 2, "size") / 2
    vertices = [[-sx, -sy, 0.0], [sx, -sy, 0.0], [sx, sy, 0.0], [-sx, sy, 0.0]]
    return trimesh.Trimesh(vertices=vertices, faces=[[0, 1, 2], [0, 2, 3]], process=False)


def _mesh_file(spec: dict, base_dir: Path) -> trimesh.Trimesh:
    path = base_dir / str(spec["file"])
    if not path.is_file():
        raise InputError("mesh file not found", path)
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as e:  # trimesh raises many types for unreadable files
        raise InputError(f"cannot load mesh: {type(e).__name__}: {e}", path) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError("cannot load mesh: no triangles in the file", path)
    return mesh.apply_scale(float(spec.get("scale", 1.0)))


def _placement(kind: str, spec: dict) -> np.ndarray:
    transform = spec.get("transform") or {}
    if not isinstance(transform, dict) or set(transform) - {"translation", "rpy"}:
        raise ValueError("transform must be a mapping with keys translation, rpy")
    if "center" in spec and ("translation" in transform or kind == "mesh"):
        raise ValueError("give either center (primitives only) or transform.translation")
    translation = spec.get("center", transform.get("translation", (0.0, 0.0, 0.0)))
    return pose_from_xyzrpy(
        [*_vector(translation, 3, "translation"), *_vector(transform.get("rpy", (0, 0, 0)), 3, "rpy")]
    )


def _vector(values, n: int, what: str) -> np.ndarray:
    out = np.asarray(values, dtype=float).ravel()
    if out.size != n or not np.all(np.isfinite(out)):
        raise ValueError(f"{what} needs {n} finite numbers, got {values!r}")
    return out


def _positive(values, n: int, what: str) -> np.ndarray:
    out = _vector(values, n, what)
    if np.any(out <= 0):
        raise ValueError(f"{what} must be positive, got {values!r}")
    return out
