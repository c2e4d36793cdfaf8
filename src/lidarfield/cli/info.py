"""``lidarfield info PATH``: what a scan file, bag, capture or dataset folder holds, in one screen."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "info",
        help="what a scan file, ROS bag, capture or dataset folder holds",
        description="Print a file's format, its scans and, for ROS bags and captures, the topics with their "
        "message counts (or the packets), the time span and the point fields; for a dataset folder (KITTI "
        "odometry, an Argoverse 2 log, nuScenes), its sequences, scans, time spans and whether poses are there.",
    )
    parser.add_argument(
        "file", help="a scan file, a ROS bag (file or ROS 2 folder), a .pcap capture or a dataset folder"
    )
    parser.set_defaults(func=_info)


def _info(args: argparse.Namespace) -> int:
    print(describe_path(args.file))
    return 0


def describe_path(path: str) -> str:
    """What ``lidarfield info`` prints of ``path``: a dataset folder's sequences
    (:func:`lidarfield.datasets.describe_dataset`), else the file's scans
    (:func:`lidarfield.io.describe.describe_file`). A folder that is no dataset's and no ROS 2
    bag is an InputError saying what folders are read. Decided here, above both: lidarfield.io
    must not import lidarfield.datasets, which builds on it."""
    from ..datasets import describe_dataset
    from ..errors import InputError
    from ..io.describe import describe_file
    from ..io.rosbag.bag import is_bag_folder

    folder = Path(path)
    if folder.is_dir() and not is_bag_folder(folder):
        text = describe_dataset(folder)
        if text is None:
            raise InputError(
                "a folder that is no dataset lidarfield reads (KITTI odometry: sequences/; an Argoverse 2 log: "
                "sensors/lidar/; nuScenes: v1.0-*/ tables) and no ROS 2 bag (metadata.yaml)",
                folder,
            )
        return text
    return describe_file(path)
