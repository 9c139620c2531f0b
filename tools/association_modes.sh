#!/usr/bin/env bash
# Voxel PQ of association under each mask error mode alone, on the synthetic flat of three
# rooms (seed 1 unless given), at strengths 0.5, 1 and 2 on top of the classic mix at 1: a
# method that only works at one strength is tuned (docs/design/association.md).
#
#   tools/association_modes.sh [--config FILE.toml] [SEED]
#
# Sequences are generated once into $VOXPAN_SETS (default target/association-sets).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
voxpan="$root/target/release/voxpan"
config=()
if [[ "${1:-}" == "--config" ]]; then
    config=(--config "$2")
    shift 2
fi
seed="${1:-1}"
sets="${VOXPAN_SETS:-$root/target/association-sets}"
mkdir -p "$sets"
printf "%-26s %8s %8s %8s %7s %10s\n" "mode" "gt" "default" "correct" "ratio" "instances"
for spec in "classic 1" "flicker 0.5" "flicker 1" "flicker 2" "splits 0.5" "splits 1" "splits 2" \
    "one-by-one 0.5" "one-by-one 1" "one-by-one 2" "repeated-fragments 0.5" \
    "repeated-fragments 1" "repeated-fragments 2"; do
    read -r mode strength <<<"$spec"
    dir="$sets/modes-$seed-$mode-$strength"
    if [[ ! -f "$dir/done" ]]; then
        rm -rf "$dir"
        extra=()
        [[ "$mode" != classic ]] && extra=(--error "$mode=$strength")
        "$voxpan" synth --out "$dir" --world flat --frames 240 --width 320 --height 240 \
            --seed "$seed" --mask-error 1 "${extra[@]}" >/dev/null 2>&1
        touch "$dir/done"
    fi
    table=$("$voxpan" eval "$dir" --3d --rules default "${config[@]}" 2>/dev/null |
        sed -n '/^maps against/,$p')
    awk -v name="$mode $strength" '
        /^gt random ids/ {gt = $4}
        /^default  / {def = $2; inst = $7 " " $8}
        /^default, correct/ {cor = $4}
        END {printf "%-26s %8.2f %8.2f %8.2f %7.2f %10s\n", name, gt, def, cor, def / cor, inst}' <<<"$table"
done
