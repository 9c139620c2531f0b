#!/usr/bin/env bash
# Voxel PQ of association on every set it is measured on (docs/design/association.md): the
# flat sample's halves and whole, the one-room synthetic world (seeds 1, 2, 3, 5; classic mask
# errors) and the synthetic flat of three rooms (seeds 1, 2, 3; every error mode at strength 1).
# Prints, per set: ground-truth masks with random ids, the default rule's masks with the
# tracker and with correct association, the ratio of the last two, and with --live the default
# map where the stream stops (`voxpan eval --live`).
#
#   tools/association_sets.sh [--config FILE.toml] [--live] [FLAT_DIR]
#
# Synthetic sequences are generated once into $VOXPAN_SETS (default target/association-sets).
# Uses the release binary; build it first (cargo build --release).
set -euo pipefail
source "$(dirname "$0")/association_common.sh"
shift "$config_args"
flat="${1:-$root/../shared/data/flat}"
for seed in 1 2 3 5; do
    make_set "room-$seed" --frames 120 --width 320 --height 240 --seed "$seed" --mask-error 1
done
for seed in 1 2 3; do
    make_set "flat-$seed" --world flat --frames 240 --width 320 --height 240 --seed "$seed" --harder
done
association_header 22 set
row() { association_row 22 "$@"; }
row "flat 0-98" "$flat" --frames 0:98
row "flat 100-198" "$flat" --frames 100:198
row "flat 0-198" "$flat"
for seed in 1 2 3 5; do row "room seed $seed" "$sets/room-$seed"; done
for seed in 1 2 3; do row "3 rooms seed $seed" "$sets/flat-$seed"; done
