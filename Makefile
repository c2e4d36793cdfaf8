# The two commands of the README: `make run` (the default study, report in results/report.html)
# and `make test`. Both install what they need first; nothing else is needed on a fresh machine.
PYTHON ?= python3
CORES ?= 2

.PHONY: run test setup setup-test bench lint

run: setup
	snakemake --cores $(CORES)

test: setup-test
	$(PYTHON) -m pytest

# pip is re-run only when pyproject.toml changes.
setup: .setup.stamp
.setup.stamp: pyproject.toml
	scripts/system-deps.sh
	$(PYTHON) -m pip install --quiet --disable-pip-version-check -e ".[test,slurm]"
	@touch $@

setup-test: setup
	scripts/system-deps.sh --test

bench: setup
	$(PYTHON) bench/field_kernel.py
	$(PYTHON) bench/hypotheses.py
	$(PYTHON) bench/raycast.py

lint: setup
	snakemake --lint
	snakefmt --check Snakefile workflow/rules
