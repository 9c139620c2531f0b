#!/usr/bin/env bash
# Sweeps each association constant around its default, one at a time, and prints voxel PQ
# (against the tracker-free reference) of the ground-truth masks with random ids and of the
# dataset's masks with the default refinement, for each dataset given.
#
#   tools/sweep_tracking.sh ../shared/data/flat /tmp/synthetic-seed5
#
# (the synthetic sequence: voxpan synth --out DIR --frames 120 --width 320 --height 240
#  --seed 5 --mask-error 1). Uses the release binary; build it first.
set -euo pipefail
voxpan="$(dirname "$0")/../target/release/voxpan"
sweeps=(
  "min_overlap 0.3 0.5 0.7"
  "min_pixels 4 8 16 25 50 100"
  "min_observations 1 2 3"
  "merge_votes 1 2 3"
  "downscale 2 4 8"
  "class_aware_things true false"
  "min_voxels 0 2 8 10 12 14 16 24 32"
)
config=$(mktemp --suffix .toml)
trap 'rm -f "$config"' EXIT
printf "%-28s %-34s %8s %8s %8s\n" "setting" "dataset" "gt PQ" "def PQ" "def inst"
for sweep in "${sweeps[@]}"; do
  read -r key values <<<"$sweep"
  for value in $values; do
    printf "[tracking]\n%s = %s\n" "$key" "$value" >"$config"
    for dataset in "$@"; do
      table=$("$voxpan" eval "$dataset" --3d --config "$config" 2>/dev/null | sed -n '/^maps against/,$p')
      gt=$(awk '/^gt random ids/ {print $4}' <<<"$table")
      def=$(awk '/^default  / {print $2}' <<<"$table")
      inst=$(awk '/^default  / {print $7}' <<<"$table")
      printf "%-28s %-34s %8s %8s %8s\n" "$key = $value" "$(basename "$dataset")" "$gt" "$def" "$inst"
    done
  done
done
