# The two commands of the README: `make run` (the default study, report in results/report.html)
# and `make test`. Both set up what they need first; nothing else is needed on a fresh machine.
#
# Everything is installed into a virtual environment, $(VENV), made with $(PYTHON): never into
# the interpreter's own site-packages. Another interpreter gets its own environment, e.g.
#   make test PYTHON=python3.13 VENV=.venv-3.13
# The exact versions come from requirements.lock (`make lock` regenerates it from pyproject.toml).
PYTHON ?= python3
VENV ?= .venv
CORES ?= 2
# The extras the lock holds (ouster is left out: it pins an old click). `make run` installs
# none of them: `make test` adds test and slurm (the tests cover the SLURM executor), `make
# docs` docs, `make setup-slurm` slurm, each from the same lock (scripts/lock_subset.py).
LOCK_EXTRAS ?= test slurm docs
UV_VERSION ?= 0.13.9

# The lock pins every package (--no-deps: lock-excludes.txt leaves out packages that a
# dependency declares but lidarfield never uses); each environment installs its subset.
PIP_INSTALL := --quiet --disable-pip-version-check --no-deps

BIN := $(abspath $(VENV))/bin
# Recipes run inside the environment, as if it were activated: the workflow's rules call
# `lidarfield` from PATH.
export PATH := $(BIN):$(PATH)
export VIRTUAL_ENV := $(abspath $(VENV))

.PHONY: run test setup setup-test setup-docs setup-slurm bench diagnosis lint lock docs

run: setup
	snakemake --cores $(CORES)

# On $(CORES) processes (pytest-xdist), a test file's tests in one of them: its module-scoped
# fixtures (a workflow run, a decoded scan) are built once. A file run by hand runs in one.
test: setup-test
	python -m pytest -n $(CORES) --dist loadfile

# The core: pyproject.toml's dependencies and what they need, at the lock's versions. pip is
# re-run only when the lock or pyproject.toml changes.
setup: $(VENV)/.setup.stamp
$(VENV)/.setup.stamp: requirements.lock pyproject.toml scripts/lock_subset.py
	PYTHON="$(PYTHON)" scripts/system-deps.sh
	PYTHON="$(PYTHON)" scripts/venv.sh "$(VENV)"
	python scripts/lock_subset.py > $(VENV)/requirements-core.txt
	python -m pip install $(PIP_INSTALL) -r $(VENV)/requirements-core.txt
	python -m pip install $(PIP_INSTALL) -e .
	@# Bytecode up front, on all cores: where PYTHONDONTWRITEBYTECODE is set (as on CI machines)
	@# Python never caches it, and every job would compile matplotlib & co. again (1.4 s a job).
	python -m compileall -q -j 0 "$$(python -c 'import sysconfig; print(sysconfig.get_path("purelib"))')" src > /dev/null
	@touch $@

# An extra on top of the core (the subset of the lock of the core and the extra).
$(VENV)/.setup-%.stamp: $(VENV)/.setup.stamp
	python scripts/lock_subset.py $(foreach extra,$(subst +, ,$*),--extra $(extra)) > $(VENV)/requirements-$*.txt
	python -m pip install $(PIP_INSTALL) -r $(VENV)/requirements-$*.txt
	@touch $@

setup-test: $(VENV)/.setup-test+slurm.stamp
	scripts/system-deps.sh --test

setup-docs: $(VENV)/.setup-docs.stamp

setup-slurm: $(VENV)/.setup-slurm.stamp

bench: setup
	python bench/field_kernel.py
	python bench/hypotheses.py
	python bench/raycast.py

# The diagnosis benchmark (docs/diagnosis.md): the whole fault zoo, tables and figure in
# diagnosis-results/ (under 15 minutes on 2 cores).
diagnosis: setup
	python bench/diagnosis.py --slice full --out diagnosis-results

# The documentation site (docs/, mkdocs.yml) into site/; --strict fails on any warning.
docs: setup-docs
	mkdocs build --strict --site-dir site

# ruff (pyproject.toml) on the Python; Snakemake's linter and snakefmt on the workflow.
lint: setup-test
	ruff format --check src tests bench hypotheses docs
	ruff check src tests bench hypotheses docs
	snakemake --lint
	snakefmt --check Snakefile workflow/rules

# One lock for every supported Python and platform (environment markers), preferring the
# versions already in it: add a dependency to pyproject.toml, run `make lock`, commit both.
# uv, not pip-compile: pip-compile resolves for the running interpreter and platform only.
lock:
	PYTHON="$(PYTHON)" scripts/venv.sh "$(VENV)"
	python -m pip install --quiet --disable-pip-version-check uv==$(UV_VERSION)
	uv pip compile pyproject.toml --universal --python-version 3.11 \
	  $(foreach extra,$(LOCK_EXTRAS),--extra $(extra)) --excludes lock-excludes.txt -o requirements.lock
