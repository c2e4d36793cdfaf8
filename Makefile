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
# The extras the lock holds and the set-up installs (ouster is left out: it pins an old click).
LOCK_EXTRAS ?= test slurm docs
UV_VERSION ?= 0.13.9

# The lock is the whole environment (--no-deps: lock-excludes.txt leaves out packages that a
# dependency declares but lidarfield never uses).
PIP_INSTALL := --quiet --disable-pip-version-check --no-deps

BIN := $(abspath $(VENV))/bin
# Recipes run inside the environment, as if it were activated: the workflow's rules call
# `lidarfield` from PATH.
export PATH := $(BIN):$(PATH)
export VIRTUAL_ENV := $(abspath $(VENV))

.PHONY: run test setup setup-test bench diagnosis lint lock docs

run: setup
	snakemake --cores $(CORES)

test: setup-test
	python -m pytest

# pip is re-run only when the lock or pyproject.toml changes.
setup: $(VENV)/.setup.stamp
$(VENV)/.setup.stamp: requirements.lock pyproject.toml
	PYTHON="$(PYTHON)" scripts/system-deps.sh
	PYTHON="$(PYTHON)" scripts/venv.sh "$(VENV)"
	python -m pip install $(PIP_INSTALL) -r requirements.lock
	python -m pip install $(PIP_INSTALL) -e .
	@# Bytecode up front, on all cores: where PYTHONDONTWRITEBYTECODE is set (as on CI machines)
	@# Python never caches it, and every job would compile matplotlib & co. again (1.4 s a job).
	python -m compileall -q -j 0 "$$(python -c 'import sysconfig; print(sysconfig.get_path("purelib"))')" src > /dev/null
	@touch $@

setup-test: setup
	scripts/system-deps.sh --test

bench: setup
	python bench/field_kernel.py
	python bench/hypotheses.py
	python bench/raycast.py

# The diagnosis benchmark (docs/diagnosis.md): the whole fault zoo, tables and figure in
# diagnosis-results/ (under 15 minutes on 2 cores).
diagnosis: setup
	python bench/diagnosis.py --slice full --out diagnosis-results

# The documentation site (docs/, mkdocs.yml) into site/; --strict fails on any warning.
docs: setup
	mkdocs build --strict --site-dir site

# ruff (pyproject.toml) on the Python; Snakemake's linter and snakefmt on the workflow.
lint: setup
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
