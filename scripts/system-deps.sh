#!/usr/bin/env bash
# Install the system libraries lidarfield needs that pip cannot: libusb-1.0-0 (Open3D loads it),
# Debian's venv module for $PYTHON when it lacks one (python3.X-venv), and, with --test,
# Chromium for the browser tests. Installs with apt-get when run as root on
# Debian/Ubuntu; otherwise stops with the exact command to run.
set -euo pipefail

packages=()
ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0' || packages+=(libusb-1.0-0)
python=${PYTHON:-python3}
if ! "$python" -c 'import ensurepip, venv' 2>/dev/null; then
  packages+=("$("$python" -c 'import sys; print("python%d.%d-venv" % sys.version_info[:2])')")
fi
if [[ "${1:-}" == "--test" ]]; then
  command -v chromium >/dev/null 2>&1 || packages+=(chromium chromium-driver)
fi
[[ ${#packages[@]} -eq 0 ]] && exit 0

if [[ $(id -u) -ne 0 ]] || ! command -v apt-get >/dev/null 2>&1; then
  echo "lidarfield set-up: missing system packages: ${packages[*]}" >&2
  echo "  install them, e.g.: sudo apt-get install -y ${packages[*]}" >&2
  exit 1
fi
echo "lidarfield set-up: installing ${packages[*]} with apt-get"
export DEBIAN_FRONTEND=noninteractive
apt-get install -y --no-install-recommends "${packages[@]}" >/dev/null 2>&1 \
  || { apt-get update >/dev/null && apt-get install -y --no-install-recommends "${packages[@]}" >/dev/null; }
