"""Content-addressed stage ids: ``{k:02d}-{name}-{hash8}``.

``hash_0`` covers the pair's inputs and registration settings (and the package version, since
Snakemake does not track code inside ``src/``); ``hash_k = sha256(hash_{k-1} +
canonical_json(step_k) + source_digest_k)`` where ``source_digest_k`` is the digest of a plugin
hypothesis's source file ('' for built-ins). Editing hypothesis j therefore changes the ids of
stages j..N and leaves the earlier ones, and their files, untouched.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from .. import __version__
from ..hypotheses.steps import step_name


def canonical_json(obj) -> str:
    """Key-sorted, whitespace-free JSON: equal settings give equal strings."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def source_digest(step: dict, base_dir: str | Path = ".") -> str:
    """Digest of a plugin hypothesis's source file; '' for built-ins."""
    name = step_name(step)
    if name != "plugin":
        return ""
    path = Path(base_dir) / step[name]["file"]
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "missing"


def stage_ids(pair_inputs: dict, stack: list[dict], base_dir: str | Path = ".") -> list[str]:
    """The ids of stage 0 (no mitigation) and of every stage of ``stack``, in order."""
    digest = _sha256(canonical_json({"pair": pair_inputs, "lidarfield": __version__}))
    ids = [f"00-none-{digest[:8]}"]
    for k, step in enumerate(stack, start=1):
        digest = _sha256(digest + canonical_json(step) + source_digest(step, base_dir))
        ids.append(f"{k:02d}-{step_name(step)}-{digest[:8]}")
    return ids
