#!/usr/bin/env bash
# Cross-validation of the association constants (docs/design/association.md): for each
# `[tracking]` constant, each value is measured on every set tools/association_sets.sh
# measures (flat frames 0-98 and 100-198, the one-room synthetic seeds, the synthetic flat of
# three rooms). A value is chosen on one half of the flat sample and kept only if the choice
# holds on the other half and on the synthetic seeds.
#
#   tools/association_crossval.sh [FLAT_DIR]     (release binary: cargo build --release)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
sweeps=(
    "min_overlap 0.4 0.5 0.6"
    "min_voxels 8 12 16"
    "merge_votes 1 2 3"
    "min_observations 2 3"
)
config=$(mktemp --suffix .toml)
trap 'rm -f "$config"' EXIT
for sweep in "${sweeps[@]}"; do
    read -r key values <<<"$sweep"
    for value in $values; do
        printf "[tracking]\n%s = %s\n" "$key" "$value" >"$config"
        echo "== $key = $value"
        "$root/tools/association_sets.sh" --config "$config" "$@" | grep -v "^flat 0-198"
    done
done
