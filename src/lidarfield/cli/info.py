"""``lidarfield info FILE``: what a scan file, bag or capture holds, in one screen."""

from __future__ import annotations

import argparse


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "info",
        help="what a scan file, ROS bag or capture holds",
        description="Print a file's format, its scans and, for ROS bags and captures, the topics with their "
        "message counts (or the packets), the time span and the point fields.",
    )
    parser.add_argument("file", help="a scan file, a ROS bag (file or ROS 2 folder) or a .pcap capture")
    parser.set_defaults(func=_info)


def _info(args: argparse.Namespace) -> int:
    from ..io.describe import describe_file

    print(describe_file(args.file))
    return 0
