#!/usr/bin/env bash
# Installs headless Chromium (Debian's `chromium`), which renders report.html to a PNG for
# tools/report/screenshot.sh and the report's browser test (cargo test -p voxpan, report).
# Idempotent: nothing is done when `chromium` is already on PATH (< 1 s). Installing needs root
# (CI is root on Debian bookworm); it downloads about 155 MB, about a minute.
set -euo pipefail

if command -v chromium >/dev/null 2>&1; then
    exit 0
fi
if [[ $(id -u) != 0 ]]; then
    echo "setup.sh: chromium is not installed, and installing it needs root: apt-get install chromium" >&2
    exit 1
fi
echo "apt-get install chromium"
apt-get update -qq
DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
command -v chromium >/dev/null
