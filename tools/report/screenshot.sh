#!/usr/bin/env bash
# Renders a report (report.html of `voxpan run` or `voxpan eval --report`) to a PNG with
# headless Chromium, to look at a report as a person would without a desktop.
#
#   tools/report/screenshot.sh RUN/report.html shot.png [WIDTHxHEIGHT]
#
# The screenshot is the window, from the top of the page: the default 1280x8000 holds a
# synthetic run's whole report. Chromium: tools/report/setup.sh. --no-sandbox because CI and
# the development machines run as root, where Chromium's sandbox refuses to start.
set -euo pipefail

if (($# < 2)); then
    echo "usage: $0 REPORT.html OUT.png [WIDTHxHEIGHT]" >&2
    exit 2
fi
html="$1"
png="$2"
size="${3:-1280x8000}"
if [[ ! -f "$html" ]]; then
    echo "$0: no such file: $html" >&2
    exit 1
fi
if ! command -v chromium >/dev/null 2>&1; then
    echo "$0: chromium is not installed: run tools/report/setup.sh" >&2
    exit 1
fi
if [[ ! "$size" =~ ^[0-9]+x[0-9]+$ ]]; then
    echo "$0: size must be WIDTHxHEIGHT, e.g. 1280x8000 (found $size)" >&2
    exit 2
fi
url="file://$(cd "$(dirname "$html")" && pwd)/$(basename "$html")"
out="$(cd "$(dirname "$png")" && pwd)/$(basename "$png")"
rm -f "$out"
# A profile of its own: a second Chromium (or a stale lock) cannot get in the way. Chromium
# logs harmless D-Bus and GPU complaints on a machine without a desktop: kept for failures only.
profile="$(mktemp -d)"
log="$profile.log"
trap 'rm -rf "$profile" "$log"' EXIT
if ! chromium --headless --no-sandbox --disable-gpu --hide-scrollbars \
    --user-data-dir="$profile" --window-size="${size/x/,}" \
    --screenshot="$out" "$url" >"$log" 2>&1 || [[ ! -s "$out" ]]; then
    echo "$0: chromium made no screenshot of $html:" >&2
    cat "$log" >&2
    exit 1
fi
echo "$out"
