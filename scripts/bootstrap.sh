#!/usr/bin/env bash
# Install what pbmdem needs on a Debian 12 machine (run as root), idempotently:
#   - LIGGGHTS 3.8 and Open MPI from Debian (without recommends: no ParaView/desktop),
#   - python3-venv if the system Python cannot create virtual environments,
#   - Chromium (headless, for the test that renders the report as a browser shows it),
#   - a virtual environment in .venv with the pinned dependencies and pbmdem itself.
# A second run only checks and returns quickly.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v liggghts >/dev/null 2>&1 || need_apt+=(liggghts)
command -v mpirun >/dev/null 2>&1 || need_apt+=(openmpi-bin)
command -v python3 >/dev/null 2>&1 || need_apt+=(python3)
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
if command -v python3 >/dev/null 2>&1 && ! python3 -c 'import ensurepip, venv' >/dev/null 2>&1; then
    need_apt+=(python3-venv)
fi
if [ ${#need_apt[@]} -gt 0 ]; then
    echo "bootstrap: installing Debian packages: ${need_apt[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${need_apt[@]}" ca-certificates
fi

# The virtual environment is rebuilt only when the pinned requirements or the
# package metadata change (a stamp stores their hash).
stamp=.venv/.pbmdem-installed
want=$(cat requirements.txt pyproject.toml | sha256sum | cut -d' ' -f1)
if [ ! -x .venv/bin/python ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    echo "bootstrap: creating .venv with the pinned Python dependencies"
    python3 -m venv .venv
    .venv/bin/python -m pip install -q --upgrade pip
    .venv/bin/python -m pip install -q -r requirements.txt
    .venv/bin/python -m pip install -q --no-deps -e .
    echo "$want" > "$stamp"
fi
echo "bootstrap: ready (liggghts: $(command -v liggghts), python: .venv/bin/python)"
