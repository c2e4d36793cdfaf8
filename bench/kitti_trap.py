"""The KITTI trap, measured and drawn: KITTI odometry's poses are the left camera's, and used as
the lidar's own they register every pair wrongly without a word.

A simulated drive through the paper's intersection (10 m/s, 10 Hz, 6 HDL-64E scans with 2 cm
of range noise, a slight left turn) is written as a KITTI odometry folder with KITTI's own
``Tr`` (sequence 00's), camera-0 poses ``P = Tr @ L @ inv(Tr)``. The same study is planned and
run twice through the workflow's jobs (ingest, register: truth, stage 0, field):

- converted: ``dataset: {format: kitti, ...}``, the reader's lidar poses ``inv(Tr) @ P @ Tr``;
- the trap: ``scans: .../velodyne/*.bin`` with ``poses: poses/07.txt`` taken as lidar poses.

It prints each pair's stage-0 rms field magnitude and the median of both, and draws
docs/images/kitti_trap.png: one pair's stage-0 field from above for both, and the rms per pair.

Run: python bench/kitti_trap.py [figure.png]
"""

from __future__ import annotations

import io
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from lidarfield import load_scene, pose_from_xyzrpy, sensor_model, simulate_scan, write_scan  # noqa: E402
from lidarfield.commands.jobs import field_stage, mitigate_stage, register_job, scan_job  # noqa: E402
from lidarfield.field.file import read_field  # noqa: E402
from lidarfield.io.pose_files import write_kitti_poses  # noqa: E402
from lidarfield.plots.png import compact_png  # noqa: E402
from lidarfield.study.config import validate_config  # noqa: E402
from timing import machine  # noqa: E402 (bench/timing.py)

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # KITTI's own Tr
from helpers.datasets import KITTI_TR  # noqa: E402

SENSOR = "hdl64"
SPEED_MPS, RATE_HZ, SCANS = 10.0, 10.0, 6
YAW_RATE_RPS = 0.2  # a slight left turn
HEIGHT_M = 1.73  # KITTI's Velodyne above the road
GRID = {"azimuth_bins": 36, "elevation_deg": [-25, 3], "elevation_bins": 7, "min_points": 30}
DRAWN_PAIR = 2


def drive_poses() -> np.ndarray:
    """World-from-lidar poses of the drive, centred on the intersection."""
    step = 1.0 / RATE_HZ
    return np.stack(
        [
            pose_from_xyzrpy([SPEED_MPS * step * (k - (SCANS - 1) / 2), 0.0, HEIGHT_M, 0, 0, YAW_RATE_RPS * step * k])
            for k in range(SCANS)
        ]
    )


def write_kitti_folder(root: Path, sequence: str = "07") -> None:
    scene, model = load_scene("paper-intersection"), sensor_model(SENSOR)
    poses = drive_poses()
    folder = root / "sequences" / sequence
    (folder / "velodyne").mkdir(parents=True)
    for k, pose in enumerate(poses):
        scan = simulate_scan(scene, model, pose, seed=k, range_noise_m=0.02)
        scan.pose = None  # KITTI's .bin files hold the points only
        write_scan(scan, folder / "velodyne" / f"{k:06d}.bin")
    (folder / "calib.txt").write_text("Tr: " + " ".join(f"{v:.12e}" for v in KITTI_TR[:3].ravel()) + "\n")
    (folder / "times.txt").write_text("".join(f"{k / RATE_HZ:e}\n" for k in range(SCANS)))
    lidar = np.linalg.inv(poses[0]) @ poses  # KITTI's world: the first scan's frame
    (root / "poses").mkdir()
    write_kitti_poses(root / "poses" / f"{sequence}.txt", KITTI_TR @ lidar @ np.linalg.inv(KITTI_TR))


def run_study(entry: dict, base: Path, out: Path) -> list[dict]:
    """Plan the sequence (validate_config) and run each pair's jobs to stage 0's field."""
    study = validate_config({"sequences": {"drive": entry}, "grid": dict(GRID)}, base_dir=base)
    rows = []
    for name, pair in sorted(study.pairs.items()):
        folder = out / name
        folder.mkdir(parents=True)
        for k, scan in (("1", pair.scan1), ("2", pair.scan2)):
            spec = {**scan.spec, "path": str(base / scan.spec["path"])}
            scan_job(scan.kind, spec, folder / f"scan{k}.parquet")
        register_job(folder / "scan1.parquet", folder / "scan2.parquet", pair.register, folder / "pair.parquet")
        changes = [folder / "changes.parquet"]
        mitigate_stage(folder / "pair.parquet", [], None, "00-none", 0, changes[0], folder / "removed.parquet")
        rows.append(
            field_stage(
                folder / "pair.parquet",
                changes,
                folder / "removed.parquet",
                study.config["grid"],
                name,
                folder / "field.parquet",
                folder / "stats.json",
            )
        )
    return rows


def draw(fields: dict[str, dict], rms: dict[str, list[float]], path: Path) -> None:
    colours = {"converted": "tab:blue", "trap": "tab:red"}
    labels = {
        "converted": "dataset: {format: kitti} (inv(Tr) @ P @ Tr)",
        "trap": "scans + poses/07.txt as lidar poses",
    }
    fig, (top, bars) = plt.subplots(1, 2, figsize=(10, 4.4), gridspec_kw={"width_ratios": [1.25, 1]})
    for key in ("trap", "converted"):
        f = fields[key]
        ok = f["valid"]
        arrows = {"angles": "xy", "scale_units": "xy", "scale": 1, "width": 0.004}
        top.quiver(f["x1"][ok], f["y1"][ok], f["u"][ok], f["v"][ok], color=colours[key], label=labels[key], **arrows)
    top.plot([0], [0], "k^", markersize=8, label="sensor 1")
    top.set_aspect("equal")
    top.set_xlim(-16, 16)
    top.set_ylim(-16, 16)
    top.set_xlabel("x in sensor 1's frame (m)")
    top.set_ylabel("y (m)")
    top.set_title(
        f"stage-0 field of pair drive-{DRAWN_PAIR:03d} from above, arrows to scale\n"
        "(converted: a few cm, hidden under the trap's metres)",
        fontsize=10,
    )
    top.legend(loc="lower left", fontsize=7)
    pairs = np.arange(len(rms["trap"]))
    for offset, key in ((-0.2, "trap"), (0.2, "converted")):
        bars.bar(
            pairs + offset,
            rms[key],
            0.4,
            color=colours[key],
            label=f"{labels[key]}: median {np.median(rms[key]):.3f} m",
        )
    bars.set_xticks(pairs, [f"drive-{k:03d}" for k in pairs], fontsize=8)
    bars.set_ylabel("stage-0 rms field magnitude (m)")
    bars.set_title(f"every pair of the drive ({SPEED_MPS:.0f} m/s, {SCANS} HDL-64E scans)", fontsize=10)
    bars.set_ylim(0, 1.3 * max(rms["trap"]))
    bars.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    plt.close(fig)
    path.write_bytes(compact_png(buffer.getvalue()))


def main() -> None:
    figure = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "images" / "kitti_trap.png"
    print(machine())
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        write_kitti_folder(base / "dataset")
        velodyne = "dataset/sequences/07/velodyne/*.bin"
        entries = {
            "converted": {"dataset": {"format": "kitti", "path": "dataset", "sequence": "07"}, "register": "truth"},
            "trap": {"scans": velodyne, "poses": "dataset/poses/07.txt", "sensor": SENSOR, "register": "truth"},
        }
        rows = {key: run_study(entry, base, base / "results" / key) for key, entry in entries.items()}
        rms = {key: [row["rms_magnitude"] for row in rows[key]] for key in rows}
        fields = {
            key: read_field(base / "results" / key / f"drive-{DRAWN_PAIR:03d}" / "field.parquet")[0] for key in rows
        }
        for key in ("converted", "trap"):
            per_pair = ", ".join(f"{value:.3f}" for value in rms[key])
            print(f"{key}: stage-0 rms field magnitude per pair (m): {per_pair}; median {np.median(rms[key]):.3f} m")
        print(f"median ratio trap / converted: {np.median(rms['trap']) / np.median(rms['converted']):.0f}")
        draw(fields, rms, figure)
        print(f"figure: {figure} ({figure.stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
