"""Registration: scan 2 expressed in scan 1's sensor frame (identity, reference poses, a fixed
transform from a file, or scan matching with Open3D), and the translation hidden in an aligned
copy of a scan."""

from .aligned import read_xyz_rows, translation_from_aligned_copy, translation_offsets, write_transform
from .settings import DEFAULTS, METHODS, parse_settings

__all__ = [
    "DEFAULTS",
    "METHODS",
    "parse_settings",
    "read_xyz_rows",
    "register_pair",
    "translation_from_aligned_copy",
    "translation_offsets",
    "write_transform",
]


def __getattr__(name: str):
    # register_pair needs Open3D (over a second to import): loaded on first use, so that
    # validating a config (every Snakemake start, twice per job on a cluster) does not pay it.
    if name == "register_pair":
        from .core import register_pair

        return register_pair
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
