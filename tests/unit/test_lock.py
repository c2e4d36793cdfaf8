"""requirements.lock against pyproject.toml: every declared dependency is locked, at a version
in its declared range, for each supported Python and platform (the lock is installed with
--no-deps, so a dependency added to pyproject.toml but not locked would be silently missing)."""

from __future__ import annotations

import importlib.util
import re
import tomllib

import pytest
from packaging.markers import default_environment
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from conftest import ROOT

PLATFORMS = {
    "linux-x86_64": {
        "sys_platform": "linux",
        "platform_system": "Linux",
        "platform_machine": "x86_64",
        "os_name": "posix",
    },
    "linux-aarch64": {
        "sys_platform": "linux",
        "platform_system": "Linux",
        "platform_machine": "aarch64",
        "os_name": "posix",
    },
    "macos-arm64": {
        "sys_platform": "darwin",
        "platform_system": "Darwin",
        "platform_machine": "arm64",
        "os_name": "posix",
    },
    "windows-amd64": {
        "sys_platform": "win32",
        "platform_system": "Windows",
        "platform_machine": "AMD64",
        "os_name": "nt",
    },
}
PYTHONS = ("3.11.0", "3.12.0", "3.13.0")


def environment(platform: str, python: str) -> dict:
    return {
        **default_environment(),
        **PLATFORMS[platform],
        "python_full_version": python,
        "python_version": python.rsplit(".", 1)[0],
        "implementation_name": "cpython",
        "platform_python_implementation": "CPython",
    }


def locked_versions(env: dict) -> dict[str, str]:
    """Name -> version of the lock's lines whose marker holds in ``env``."""
    versions = {}
    for line in (ROOT / "requirements.lock").read_text().splitlines():
        if not line or line[0] in " #":
            continue
        requirement = Requirement(line)
        if requirement.marker is None or requirement.marker.evaluate(env):
            name = canonicalize_name(requirement.name)
            assert name not in versions, f"requirements.lock: two versions of {name} for one environment"
            (specifier,) = requirement.specifier
            versions[name] = specifier.version
    return versions


def declared(extras: list[str]) -> list[tuple[Requirement, str]]:
    """pyproject.toml's dependencies and those of the locked extras, with the extra of each."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    found = [(Requirement(r), "") for r in project["dependencies"]]
    for extra in extras:
        found += [(Requirement(r), extra) for r in project["optional-dependencies"][extra]]
    return found


def lock_extras() -> list[str]:
    header = (ROOT / "requirements.lock").read_text().split("\n", 3)[1]
    return re.findall(r"--extra (\S+)", header)


def test_the_lock_holds_the_test_extra():
    assert "test" in lock_extras()


@pytest.mark.parametrize("python", PYTHONS)
@pytest.mark.parametrize("platform", sorted(PLATFORMS))
def test_every_declared_dependency_is_locked_within_its_range(platform, python):
    env = environment(platform, python)
    versions = locked_versions(env)
    checked = 0
    for requirement, extra in declared(lock_extras()):
        if requirement.marker is not None and not requirement.marker.evaluate({**env, "extra": extra}):
            continue
        name = canonicalize_name(requirement.name)
        assert name in versions, f"{name} ({extra or 'dependencies'}) is not in requirements.lock: run `make lock`"
        assert requirement.specifier.contains(versions[name], prereleases=True), (
            f"requirements.lock has {name}=={versions[name]}, outside pyproject.toml's {requirement}: run `make lock`"
        )
        checked += 1
    assert checked >= 15


def test_open3d_cpu_on_linux_x86_64_open3d_elsewhere():
    for platform in PLATFORMS:
        versions = locked_versions(environment(platform, "3.13.0"))
        cpu = platform == "linux-x86_64"
        assert ("open3d-cpu" in versions) == cpu and ("open3d" in versions) == (not cpu), platform


# --- the environments the set-up installs: subsets of the lock (scripts/lock_subset.py) ------
def lock_subset():
    spec = importlib.util.spec_from_file_location("lock_subset", ROOT / "scripts" / "lock_subset.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def subset_names(extras: list[str]) -> set[str]:
    module = lock_subset()
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    lines = module.subset((ROOT / "requirements.lock").read_text(), module.roots(pyproject, extras) - {"lidarfield"})
    return {canonicalize_name(Requirement(line).name) for line in lines}


def excluded() -> set[str]:
    lines = (ROOT / "lock-excludes.txt").read_text().splitlines()
    return {canonicalize_name(line) for line in lines if line.strip() and not line.startswith("#")}


def test_the_run_environment_leaves_out_the_tests_docs_and_slurm_tools():
    core, everything = subset_names([]), subset_names(lock_extras())
    assert {"numpy", "open3d-cpu", "snakemake", "pandas", "matplotlib"} <= core
    for tool in ("pytest", "ruff", "snakefmt", "mkdocs", "mkdocs-material", "snakemake-executor-plugin-slurm"):
        assert tool in everything and tool not in core, tool
    assert subset_names(["test"]) - core >= {"pytest", "ruff", "snakefmt", "pluggy", "iniconfig"}
    assert "mkdocs" not in subset_names(["test"]) and "pytest" not in subset_names(["docs"])
    # every extra together is the whole lock
    locked = {canonicalize_name(Requirement(line).name) for line in _lock_lines()}
    assert everything == locked


@pytest.mark.parametrize("extras", [[], ["test", "slurm"], ["docs"]])
def test_each_environment_holds_what_its_packages_require(extras):
    """Checked against the installed packages' own metadata (this environment has the whole
    lock), not the lock's annotations the subset is made from."""
    from importlib.metadata import PackageNotFoundError, requires

    names = subset_names(extras)
    env = default_environment()
    checked = 0
    for name in sorted(names):
        try:
            required = requires(name) or []
        except PackageNotFoundError:  # another platform's (open3d, colorama, ...)
            continue
        for text in required:
            requirement = Requirement(text)
            if requirement.marker is None or requirement.marker.evaluate({**env, "extra": ""}):
                needed = canonicalize_name(requirement.name)
                assert needed in names or needed in excluded(), f"{name} requires {needed}, not in {extras or 'core'}"
        checked += 1
    assert checked > 0.8 * len(names)


def _lock_lines() -> list[str]:
    return [line for line in (ROOT / "requirements.lock").read_text().splitlines() if line and line[0] not in " #"]
