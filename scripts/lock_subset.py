"""The lines of requirements.lock that one environment needs: pyproject.toml's dependencies,
those of the extras named, and what they need in turn, by the lock's own ``# via``
annotations (uv writes under each package the locked packages that require it).

    python scripts/lock_subset.py [--extra NAME ...] [--lock FILE] [--pyproject FILE] > subset.txt

Every line keeps its exact pin and its environment marker, so the subset installs with
``pip install --no-deps -r`` as the whole lock does. The lock stays the one file that
``make lock`` writes; the subsets are derived from it at set-up (standard library only: it
runs before anything is installed).
"""

from __future__ import annotations

import argparse
import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
_ME = "lidarfield"


def canonical(name: str) -> str:
    """A distribution name as PEP 503 compares them."""
    return re.sub(r"[-_.]+", "-", name).lower()


def requirement_name(text: str) -> str:
    return canonical(_NAME.match(text.strip()).group())


def parse_lock(text: str) -> dict[str, tuple[list[str], set[str]]]:
    """Name -> (its requirement lines, the names of the packages that require it). A name can
    have several lines, one per environment marker."""
    packages: dict[str, tuple[list[str], set[str]]] = {}
    current = None
    for line in text.splitlines():
        if not line.strip():
            continue
        if not line.startswith((" ", "#")):
            current = requirement_name(line)
            packages.setdefault(current, ([], set()))[0].append(line)
        elif current is not None and line.startswith("    #"):
            via = line.strip().lstrip("#").strip().removeprefix("via").strip()
            if via:
                packages[current][1].add(requirement_name(via))
    return packages


def roots(pyproject: dict, extras: list[str]) -> set[str]:
    """The names lidarfield itself requires: its dependencies and those of ``extras``."""
    project = pyproject["project"]
    unknown = [extra for extra in extras if extra not in project.get("optional-dependencies", {})]
    if unknown:
        raise SystemExit(f"lock_subset: no extra {', '.join(unknown)} in pyproject.toml")
    declared = list(project["dependencies"])
    for extra in extras:
        declared += project["optional-dependencies"][extra]
    return {requirement_name(r) for r in declared}


def subset(lock_text: str, wanted: set[str]) -> list[str]:
    """The lock's lines of ``wanted`` and of every locked package that one of them requires,
    in the lock's order."""
    packages = parse_lock(lock_text)
    missing = sorted(wanted - set(packages))
    if missing:
        raise SystemExit(f"lock_subset: {', '.join(missing)} not in the lock: run `make lock`")
    needed = set(wanted)
    grew = True
    while grew:  # a package is needed when one that requires it is
        grew = False
        for name, (_, parents) in packages.items():
            if name not in needed and parents & needed:
                needed.add(name)
                grew = True
    return [line for name, (lines, _) in packages.items() if name in needed for line in lines]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--extra", action="append", default=[], help="an extra of pyproject.toml to add")
    parser.add_argument("--lock", type=Path, default=ROOT / "requirements.lock")
    parser.add_argument("--pyproject", type=Path, default=ROOT / "pyproject.toml")
    args = parser.parse_args(argv)
    wanted = roots(tomllib.loads(args.pyproject.read_text()), args.extra)
    sys.stdout.write("\n".join(subset(args.lock.read_text(), wanted - {_ME})) + "\n")


if __name__ == "__main__":
    main()
