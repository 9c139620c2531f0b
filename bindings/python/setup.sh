#!/usr/bin/env bash
# Builds voxpan's Python package into a virtual environment and runs its tests.
#
#   bindings/python/setup.sh [--release]
#
# Venv: $VOXPAN_VENV, default target/py-venv in the checkout (maturin, numpy, pytest, pillow,
# and scipy, the distance field's reference; open3d-cpu for the interop and distance tests and bench_open3d.py only, never needed by voxpan itself:
# VOXPAN_SKIP_OPEN3D=1 leaves it out, and its test then fails unless
# VOXPAN_ALLOW_MISSING_DATA=1). Open3D's library links libusb-1.0: where it is missing, root
# installs Debian's libusb-1.0-0 with apt-get; anyone else is told the command.
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
    "maturin>=1.16,<1.17" numpy pytest pillow scipy
if [[ "${VOXPAN_SKIP_OPEN3D:-0}" != 1 ]]; then
    # Captured first: `ldconfig -p | grep -q` can fail under pipefail when grep stops early.
    libs="$(PATH="$PATH:/sbin:/usr/sbin" ldconfig -p 2>/dev/null || true)"
    if [[ "$libs" != *libusb-1.0* ]]; then
        if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null; then
            echo "setup.sh: installing libusb-1.0-0 (Open3D links it)"
            # A fresh machine may have no package lists yet.
            apt-get install -y -q libusb-1.0-0 >/dev/null \
                || { apt-get update -q >/dev/null && apt-get install -y -q libusb-1.0-0 >/dev/null; }
        else
            echo "setup.sh: libusb-1.0 is missing, so open3d will not import:" \
                "sudo apt-get install libusb-1.0-0" >&2
        fi
    fi
    "$venv/bin/pip" install --quiet --disable-pip-version-check "open3d-cpu>=0.20,<0.21"
fi
# maturin develop installs into the venv it runs in.
VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" \
    "$venv/bin/maturin" develop --quiet --manifest-path "$here/Cargo.toml" "${profile[@]}"
# no:dash: Open3D brings Dash, whose pytest plugin has nothing to do here.
"$venv/bin/python" -m pytest -q -p no:dash "$here/tests"
