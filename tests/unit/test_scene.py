"""Scenes (built-in and YAML) and trajectories."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
import yaml

from lidarfield.errors import ConfigError, InputError
from lidarfield.poses import pose_from_xyzrpy as pose_from_values
from lidarfield.simulation.scene import builtin_scenes, load_scene, scene_from_dict
from lidarfield.simulation.trajectory import arc_trajectory, moved_pose, paper_turn_trajectory


def _write_yaml(path, spec):
    path.write_text(yaml.safe_dump(spec))
    return path


def test_paper_intersection_matches_the_papers_description():
    scene = load_scene("paper-intersection")
    ground, *buildings = scene.objects
    assert np.allclose(ground.mesh.bounds, [[-13, -13, 0], [13, 13, 0]])
    extents = sorted(tuple(np.round(b.mesh.extents, 6)) for b in buildings)
    assert extents == [(5, 5, 10), (5, 5, 10), (7, 5, 10), (8, 5, 10)]  # the cylinder's box is 5x5
    cylinder = next(b for b in buildings if "cylinder" in b.name)
    centre = cylinder.mesh.bounds.mean(axis=0)
    radii = np.hypot(*(cylinder.mesh.vertices[:, :2] - centre[:2]).T)
    assert np.allclose(radii[radii > 1e-9], 2.5)  # rim vertices; the caps' centres are at 0
    quadrants = {tuple(np.sign(b.mesh.bounds.mean(axis=0)[:2])) for b in buildings}
    assert quadrants == {(1, 1), (-1, 1), (-1, -1), (1, -1)}
    for b in buildings:
        lo, hi = b.mesh.bounds
        assert np.all(lo[:2] >= -13) and np.all(hi[:2] <= 13)  # inside the ground plane
        assert np.min(np.abs(np.r_[lo[:2], hi[:2]])) >= 4  # the streets |x|, |y| < 4 stay open
    assert not any(o.moving for o in scene.objects)


def test_street_canyon_matches_its_description():
    """14 m between the facades, the street's centre clear for a drive, cars and posts at the kerbs."""
    scene = load_scene("street-canyon")
    ground, *others = scene.objects
    assert np.allclose(ground.mesh.bounds, [[-50, -20, 0], [50, 20, 0]])
    buildings = [o for o in others if o.name.startswith(("north", "south"))]
    assert len(buildings) == 8 and not any(o.moving for o in scene.objects)
    inner = [b.mesh.bounds[0, 1] if b.mesh.bounds[0, 1] > 0 else b.mesh.bounds[1, 1] for b in buildings]
    assert sorted(np.round(np.abs(inner), 6)) == [7] * 7 + [7.5]  # one building set back 0.5 m
    heights = sorted(b.mesh.bounds[1, 2] for b in buildings)
    assert heights[0] == pytest.approx(8) and heights[-1] == pytest.approx(22)
    for o in others:
        lo, hi = o.mesh.bounds
        assert min(abs(lo[1]), abs(hi[1])) >= 4.5 and lo[1] * hi[1] > 0  # nothing in |y| < 4.5


def test_unknown_scene_lists_the_builtins():
    with pytest.raises(ConfigError) as e:
        load_scene("no-such-scene")
    for name in builtin_scenes():
        assert name in str(e.value)
    assert "paper-intersection" in builtin_scenes()


@pytest.mark.parametrize("ext", ["obj", "stl", "ply", "glb"])
def test_yaml_scene_with_primitives_meshes_and_transforms(tmp_path, ext):
    trimesh.creation.box(extents=(2, 4, 6)).export(tmp_path / f"part.{ext}")
    spec = {
        "name": "lab",
        "objects": [
            {"kind": "plane", "size": [30, 20]},
            {"kind": "box", "size": [1, 2, 3], "center": [5, 0, 1.5]},
            {"kind": "box", "size": [1, 2, 3], "transform": {"translation": [0, 5, 1.5], "rpy": [0, 0, np.pi / 2]}},
            {"kind": "cylinder", "radius": 0.5, "height": 4, "center": [-5, 0, 2], "sections": 16},
            {
                "kind": "mesh",
                "file": f"part.{ext}",
                "scale": 0.5,
                "transform": {"translation": [0, -5, 1.5]},
                "velocity_mps": [1, 0, 0],
            },
        ],
    }
    scene = load_scene(_write_yaml(tmp_path / "lab.yaml", spec))
    plane, box, turned, cylinder, part = scene.objects
    assert scene.name == "lab"
    assert np.allclose(plane.mesh.bounds, [[-15, -10, 0], [15, 10, 0]])
    assert np.allclose(box.mesh.bounds, [[4.5, -1, 0], [5.5, 1, 3]])
    assert np.allclose(turned.mesh.bounds, [[-1, 4.5, 0], [1, 5.5, 3]])  # yaw 90 deg swaps x and y
    assert np.allclose(cylinder.mesh.bounds, [[-5.5, -0.5, 0], [-4.5, 0.5, 4]])
    assert np.allclose(part.mesh.bounds, [[-0.5, -6, 0], [0.5, -4, 3]])  # scaled by 0.5, then moved
    assert part.moving and not box.moving
    assert np.allclose(part.mesh_at(2.0).bounds, part.mesh.bounds + [2, 0, 0])
    assert len(scene.mesh_at(0.0).faces) == sum(len(o.mesh.faces) for o in scene.objects)


def test_scene_extends_a_builtin(tmp_path):
    base = load_scene("paper-intersection")
    scene = load_scene("paper-intersection-moving-car")
    assert [o.name for o in scene.objects[: len(base.objects)]] == [o.name for o in base.objects]
    car = scene.objects[-1]
    assert np.allclose(car.velocity_mps, [-5, 0, 0])
    assert np.allclose(car.mesh_at(0.2).bounds.mean(axis=0), [8, 2, 0.75])


def test_mesh_file_that_does_not_load_names_the_file(tmp_path):
    (tmp_path / "broken.stl").write_bytes(b"solid nothing\nthis is not an stl\n")
    path = _write_yaml(tmp_path / "s.yaml", {"objects": [{"kind": "mesh", "file": "broken.stl"}]})
    with pytest.raises(InputError, match="broken.stl"):
        load_scene(path)
    missing = _write_yaml(tmp_path / "m.yaml", {"objects": [{"kind": "mesh", "file": "absent.obj"}]})
    with pytest.raises(InputError, match="absent.obj: mesh file not found"):
        load_scene(missing)


@pytest.mark.parametrize(
    "obj, message",
    [
        ({"kind": "sphere", "radius": 1}, "kind must be one of"),
        ({"kind": "box"}, "missing \\['size'\\]"),
        ({"kind": "box", "size": [1, 1, 1], "colour": "red"}, "unknown key"),
        ({"kind": "box", "size": [1, -1, 1]}, "must be positive"),
        ({"kind": "box", "size": [1, 1]}, "size needs 3"),
        (
            {"kind": "box", "size": [1, 1, 1], "center": [0, 0, 0], "transform": {"translation": [1, 0, 0]}},
            "either center",
        ),
        ({"kind": "box", "size": [1, 1, 1], "frame": "vehicle"}, "frame must be one of"),
        ({"kind": "box", "size": [1, 1, 1], "frame": "sensor", "velocity_mps": [1, 0, 0]}, "carries has no velocity"),
    ],
)
def test_bad_scene_objects_say_what_is_wrong(obj, message):
    with pytest.raises(ConfigError, match=message):
        scene_from_dict({"objects": [obj]}, name="bad")


def test_moved_pose_is_constant_velocity_motion():
    pose = pose_from_values([1, 0, 3, 0, 0, 0.3])
    assert np.array_equal(moved_pose(pose, 0.7, (0, 0, 0), (0, 0, 0)), pose)
    moved = moved_pose(pose, np.array([0.0, 0.5]), (2, 0, 0), (0, 0, 1))
    assert moved.shape == (2, 4, 4)
    assert np.allclose(moved[1][:3, 3], [2, 0, 3])
    assert np.allclose(moved[1][:3, :3], pose_from_values([0, 0, 0, 0, 0, 0.8])[:3, :3])


def test_arc_trajectory_heads_along_the_arc():
    frames = arc_trajectory((1, 2), 10.0, 0.0, speed_mps=5.0, rate_hz=2.0, frames=5, height_m=1.5)
    for k, (pose, velocity, angular) in enumerate(frames):
        angle = 0.25 * k  # 5 m/s / 10 m for 0.5 s per frame
        assert np.allclose(pose[:3, 3], [1 + 10 * np.cos(angle), 2 + 10 * np.sin(angle), 1.5])
        heading = pose[:3, :3] @ [1, 0, 0]
        assert np.allclose(heading, [-np.sin(angle), np.cos(angle), 0])
        assert np.allclose(velocity, 5 * heading)
        assert np.allclose(angular, [0, 0, 0.5])
    clockwise = arc_trajectory((0, 0), 10.0, 0.0, -5.0, 2.0, 2, 0.0)  # negative speed: clockwise
    pose, velocity, angular = clockwise[1]
    assert pose[1, 3] < 0 and angular[2] == -0.5
    assert np.allclose(velocity, 5 * (pose[:3, :3] @ [1, 0, 0]))  # still driving forwards
    assert np.allclose(clockwise[0].pose[:3, :3] @ [1, 0, 0], [0, -1, 0])


def test_paper_turn_stays_in_the_streets():
    import open3d as o3d

    scene = load_scene("paper-intersection")
    buildings = trimesh.util.concatenate([o.mesh for o in scene.objects if o.name != "ground"])
    caster = o3d.t.geometry.RaycastingScene()
    caster.add_triangles(
        o3d.core.Tensor(buildings.vertices.astype(np.float32)), o3d.core.Tensor(buildings.faces.astype(np.uint32))
    )
    frames = paper_turn_trajectory()
    assert len(frames) >= 9
    positions = np.array([f.pose[:3, 3] for f in frames])
    clearance = caster.compute_distance(o3d.core.Tensor(positions.astype(np.float32))).numpy()
    assert clearance.min() >= 2.5 - 1e-5
    assert np.all((np.abs(positions[:, 0]) < 4) | (np.abs(positions[:, 1]) < 4))
    headings = np.degrees([np.arctan2(f.pose[1, 0], f.pose[0, 0]) for f in frames])
    assert headings[0] == pytest.approx(0) and headings[-1] > 80  # a left turn from +x towards +y
