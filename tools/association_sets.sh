#!/usr/bin/env bash
# Voxel PQ of association on every set it is measured on (docs/design/association.md): the
# flat sample's halves and whole, the one-room synthetic world (seeds 1, 2, 3, 5; classic mask
# errors) and the synthetic flat of three rooms (seeds 1, 2, 3; every error mode at strength 1).
# Prints, per set: ground-truth masks with random ids, the default rule's masks with the
# tracker and with correct association, and the ratio of the last two.
#
#   tools/association_sets.sh [--config FILE.toml] [FLAT_DIR]
#
# Synthetic sequences are generated once into $VOXPAN_SETS (default target/association-sets).
# Uses the release binary; build it first (cargo build --release).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
voxpan="$root/target/release/voxpan"
config=()
if [[ "${1:-}" == "--config" ]]; then
    config=(--config "$2")
    shift 2
fi
flat="${1:-$root/../shared/data/flat}"
sets="${VOXPAN_SETS:-$root/target/association-sets}"
mkdir -p "$sets"
make_set() { # name, synth args...
    local dir="$sets/$1"
    shift
    [[ -f "$dir/done" ]] && return
    rm -rf "$dir"
    "$voxpan" synth --out "$dir" "$@" >/dev/null 2>&1
    touch "$dir/done"
}
for seed in 1 2 3 5; do
    make_set "room-$seed" --frames 120 --width 320 --height 240 --seed "$seed" --mask-error 1
done
for seed in 1 2 3; do
    make_set "flat-$seed" --world flat --frames 240 --width 320 --height 240 --seed "$seed" --harder
done
printf "%-22s %8s %8s %8s %7s %10s\n" set "gt" "default" "correct" "ratio" "instances"
row() { # name, dataset, eval args...
    local name="$1" dataset="$2"
    shift 2
    local table
    table=$("$voxpan" eval "$dataset" --3d --rules default "${config[@]}" "$@" 2>/dev/null |
        sed -n '/^maps against/,$p')
    awk -v name="$name" '
        /^gt random ids/ {gt = $4}
        /^default  / {def = $2; inst = $7 " " $8}
        /^default, correct/ {cor = $4}
        END {printf "%-22s %8.2f %8.2f %8.2f %7.2f %10s\n", name, gt, def, cor, def / cor, inst}' <<<"$table"
}
row "flat 0-98" "$flat" --frames 0:98
row "flat 100-198" "$flat" --frames 100:198
row "flat 0-198" "$flat"
for seed in 1 2 3 5; do row "room seed $seed" "$sets/room-$seed"; done
for seed in 1 2 3; do row "3 rooms seed $seed" "$sets/flat-$seed"; done
