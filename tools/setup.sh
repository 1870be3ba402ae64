#!/usr/bin/env bash
# Set up spacefit on a fresh machine: check the system libLLVM Dr.Jit needs, create .venv if missing.
# Dr.Jit's CPU backend loads the system libLLVM; Debian 12's libLLVM 15 (and 16) abort at the first
# render, libLLVM 19 works.
set -euo pipefail
cd "$(dirname "$0")/.."

have_llvm() {
    [ -n "${DRJIT_LIBLLVM_PATH:-}" ] && return 0
    local f major
    for f in /usr/lib/*-linux-gnu/libLLVM.so.* /usr/lib/*-linux-gnu/libLLVM-*.so*; do
        [ -e "$f" ] || continue
        major=$(basename "$f" | grep -oE '[0-9]+' | head -n 1)
        [ -n "$major" ] && [ "$major" -ge 19 ] && return 0
    done
    return 1
}
if ! have_llvm; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "setup: installing libllvm19 (Dr.Jit needs libLLVM >= 19)" >&2
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null
    else
        echo "setup: Dr.Jit needs libLLVM >= 19. Run: sudo apt-get update && sudo apt-get install -y libllvm19" >&2
        echo "       (or set DRJIT_LIBLLVM_PATH to a libLLVM >= 19)" >&2
        exit 1
    fi
fi

# The docs test opens the built pages in a headless browser: Debian's chromium.
if ! command -v chromium >/dev/null && ! command -v chromium-browser >/dev/null; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "setup: installing chromium (the docs test opens the built pages in it)" >&2
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
    else
        echo "setup: the docs test needs chromium: sudo apt-get update && sudo apt-get install -y chromium" >&2
    fi
fi

# The interpreter .venv is made from: PYTHON where set; else the system's /usr/bin/python3 where it is 3.11 or newer and
# can make a venv (Debian's links the interpreter into its binary: the fit process took 0.94 of the wall and 0.95 of the CPU
# it took on pyenv's build, which calls it from a shared library; docs/measurements/performance.md); else python3.
interpreter() {
    if [ -n "${PYTHON:-}" ]; then
        echo "$PYTHON"
    elif [ -x /usr/bin/python3 ] && /usr/bin/python3 -c 'import sys, ensurepip, venv; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
        echo /usr/bin/python3
    else
        echo python3
    fi
}

if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c "import spacefit, pytest, xdist, hypothesis, xarray, zarr, dask.distributed, tqdm, sphinx, myst_nb, sphinx_gallery, pydata_sphinx_theme, sphinxarg; import importlib; importlib.import_module('sphinx-mathjax-offline')" 2>/dev/null; then
    python=$(interpreter)
    echo "setup: creating .venv from $python and installing spacefit (a few minutes the first time)" >&2
    "$python" -m venv .venv
    .venv/bin/python -m pip install -q --upgrade pip
    .venv/bin/python -m pip install -q -e ".[dev,docs]"
fi
