#!/usr/bin/env bash
# Voxel PQ of association under each mask error mode alone, on the synthetic flat of three
# rooms (seed 1 unless given), at strengths 0.5, 1 and 2 on top of the classic mix at 1 (0.5
# and 1 for stuff-per-class, a share of frames): a method that only works at one strength is
# tuned (docs/design/association.md).
#
#   tools/association_modes.sh [--config FILE.toml] [--live] [SEED]
#
# Sequences are generated once into $VOXPAN_SETS (default target/association-sets).
set -euo pipefail
source "$(dirname "$0")/association_common.sh"
shift "$config_args"
seed="${1:-1}"
association_header 26 mode
for spec in "classic 1" "flicker 0.5" "flicker 1" "flicker 2" "splits 0.5" "splits 1" "splits 2" \
    "one-by-one 0.5" "one-by-one 1" "one-by-one 2" "repeated-fragments 0.5" \
    "repeated-fragments 1" "repeated-fragments 2" "stuff-per-class 0.5" "stuff-per-class 1"; do
    read -r mode strength <<<"$spec"
    extra=()
    [[ "$mode" != classic ]] && extra=(--error "$mode=$strength")
    make_set "modes-$seed-$mode-$strength" --world flat --frames 240 --width 320 --height 240 \
        --seed "$seed" --mask-error 1 "${extra[@]}"
    association_row 26 "$mode $strength" "$sets/modes-$seed-$mode-$strength"
done
