#!/usr/bin/env bash
# Voxel PQ of association on the synthetic flat of three rooms with the masks drawn again: the
# same worlds (seeds 1-5), trajectories and depth, other draws of the network's errors
# (`voxpan synth --mask-seed`). Tells how far one draw moves the figures of
# tools/association_sets.sh from what the tracker does on such a world
# (docs/design/association.md).
#
#   tools/association_draws.sh [--config FILE.toml] [--live] [DRAW...]     (default draws: 101 102 103 104)
#
# Prints one row per draw, then per seed and over all draws the mean ratio and its range.
# Uses the release binary; build it first (cargo build --release). About 8 min for 20 draws.
set -euo pipefail
source "$(dirname "$0")/association_common.sh"
shift "$config_args"
draws=("$@")
[[ ${#draws[@]} -gt 0 ]] || draws=(101 102 103 104)
rows=$(mktemp)
trap 'rm -f "$rows"' EXIT
association_header 22 set
for seed in 1 2 3 4 5; do
    for draw in "${draws[@]}"; do
        make_set "flat-$seed-m$draw" --world flat --frames 240 --width 320 --height 240 \
            --seed "$seed" --harder --mask-seed "$draw"
        association_row 22 "3 rooms $seed, draw $draw" "$sets/flat-$seed-m$draw" | tee -a "$rows"
    done
done
# Columns from the end: ratio is the third-last field (instances prints as "N (M)"), or the
# fourth-last with the live column.
awk -v off="${#live[@]}" '{ seed = $3; sub(",", "", seed)
       r = $(NF - 2 - off); t = $(NF - 4 - off); c = $(NF - 3 - off)
       n[seed]++; sum[seed] += r; tr[seed] += t; co[seed] += c; lv[seed] += $NF; live += $NF
       if (!(seed in lo) || r < lo[seed]) lo[seed] = r
       if (!(seed in hi) || r > hi[seed]) hi[seed] = r
       all += r; count++ }
     END { for (s in n) {
               printf "seed %s: tracker %.2f, correct %.2f, ratio %.3f (%.2f-%.2f)",
                   s, tr[s] / n[s], co[s] / n[s], sum[s] / n[s], lo[s], hi[s]
               if (off) printf ", live %.2f", lv[s] / n[s]
               printf "\n" }
           printf "all %d draws: ratio %.3f", count, all / count
           if (off) printf ", live %.2f", live / count
           printf "\n" }' "$rows" | sort
