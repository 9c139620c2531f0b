#!/usr/bin/env bash
# Builds voxpan's Python package into a virtual environment and runs its tests.
#
#   bindings/python/setup.sh [--release]
#
# Venv: $VOXPAN_VENV, default target/py-venv in the checkout (maturin, numpy, pytest, pillow).
# Build: `maturin develop` into $CARGO_TARGET_DIR, default the checkout's target/, with the
# main workspace's dev profile, so it reuses what `cargo build` / `cargo test` compiled there
# (--release: optimised, as `pip install ./bindings/python` builds it). The data tests compare
# with the command line ($VOXPAN_BIN, default target/debug/voxpan: `cargo build -p voxpan`).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
venv="${VOXPAN_VENV:-$repo/target/py-venv}"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$repo/target}"
profile=()
[[ "${1:-}" == "--release" ]] && profile=(--release)

if [[ ! -x "$venv/bin/python" ]]; then
    python3 -m venv "$venv"
fi
"$venv/bin/pip" install --quiet --disable-pip-version-check \
    "maturin>=1.16,<1.17" numpy pytest pillow
# maturin develop installs into the venv it runs in.
VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" \
    "$venv/bin/maturin" develop --quiet --manifest-path "$here/Cargo.toml" "${profile[@]}"
"$venv/bin/python" -m pytest -q "$here/tests"
