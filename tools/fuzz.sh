#!/usr/bin/env bash
# Runs every fuzz target for SECONDS each (default 600) with cargo-fuzz on the nightly
# toolchain, growing fuzz/corpus/<target> from fuzz/seeds/<target>. Crashes are copied into
# fuzz/regressions/<target>/ (replayed by the normal test suite) and make the script fail.
#   tools/fuzz.sh [SECONDS] [TARGET...]
# Needs: rustup toolchain install nightly; cargo install cargo-fuzz.
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
seconds=${1:-600}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    mapfile -t targets < <(cargo +nightly fuzz list)
fi
cargo +nightly fuzz build
failed=0
for t in "${targets[@]}"; do
    mkdir -p "corpus/$t" "artifacts/$t"
    echo "== $t: ${seconds}s"
    # -rss_limit_mb: a reader must not need gigabytes for a small file.
    if ! cargo +nightly fuzz run "$t" "corpus/$t" "seeds/$t" -- \
        -max_total_time="$seconds" -rss_limit_mb=2048 -max_len=65536 -print_final_stats=1 \
        2> "artifacts/$t/log.txt"; then
        failed=1
        mkdir -p "regressions/$t"
        cp artifacts/"$t"/crash-* artifacts/"$t"/oom-* artifacts/"$t"/timeout-* "regressions/$t/" 2>/dev/null || true
        echo "   FAILED: see fuzz/artifacts/$t/log.txt"
    fi
    grep -E "stat::number_of_executed_units|Done [0-9]+ runs" "artifacts/$t/log.txt" | tail -2 | sed 's/^/   /'
    # Keep the committed corpus small: only inputs that add coverage.
    mkdir -p "corpus/$t.min"
    cargo +nightly fuzz cmin "$t" "corpus/$t" >/dev/null 2>&1 || true
    rmdir "corpus/$t.min" 2>/dev/null || true
done
exit $failed
