#!/usr/bin/env bash
# Make the virtual environment DIR with $PYTHON (default python3), or check that the existing
# one was made with the same Python version: one environment per interpreter.
set -euo pipefail
venv=$1
python=${PYTHON:-python3}

version() { "$1" -c 'import sys; print("%d.%d" % sys.version_info[:2])'; }
wanted=$(version "$python") || { echo "lidarfield set-up: cannot run PYTHON=$python" >&2; exit 1; }
case $wanted in
  3.11 | 3.12 | 3.13) ;;
  *) echo "lidarfield set-up: $python is Python $wanted; lidarfield needs Python 3.11 to 3.13" >&2; exit 1 ;;
esac

if [[ -x $venv/bin/python ]]; then
  have=$(version "$venv/bin/python")
  if [[ $have != "$wanted" ]]; then
    echo "lidarfield set-up: $venv has Python $have, not $wanted ($python):" \
      "remove it, or give this Python its own, e.g. VENV=.venv-$wanted" >&2
    exit 1
  fi
  exit 0
fi
echo "lidarfield set-up: making the virtual environment $venv with $python (Python $wanted)"
"$python" -m venv "$venv"
