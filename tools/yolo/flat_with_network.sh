#!/usr/bin/env bash
# A copy of a flat dataset whose predicted masks come from a YOLO network instead of the
# dataset's Detectron2 masks: the paper's Table II rows (c)/(d) with a real network.
#
#   tools/yolo/flat_with_network.sh VOXPAN MODEL.onnx FLAT_DIR OUT_DIR [segment options...]
#
# VOXPAN is a voxpan binary built with a network backend (--features ort or tract). OUT_DIR
# gets symbolic links to FLAT_DIR's colour, depth, pose and ground-truth files, and the
# network's NNNNNN_predicted.png + NNNNNN_labels.json (`voxpan segment`); the model's class
# table becomes OUT_DIR/detectron_labels.csv (the flat format's name for the network's
# classes). Then, for example:
#
#   voxpan eval OUT_DIR            # raw masks and each refinement rule against the ground truth
#   voxpan eval OUT_DIR --3d       # and the maps built from them (voxel PQ)
#
# Nothing is copied from the network into the repository: OUT_DIR is derived from the
# weights (GPL-3.0 for YOLOv5s-seg); keep it under target/.
set -euo pipefail

if [[ $# -lt 4 ]]; then
    sed -n '2,17p' "$0" >&2
    exit 2
fi
voxpan="$1"; model="$2"; flat="$(cd "$3" && pwd)"; out="$4"; shift 4

[[ -f "$flat/run1/timestamps.csv" || -n "$(ls "$flat"/run1/*_color.png 2>/dev/null)" ]] \
    || { echo "$flat: not a flat dataset (no run1/)" >&2; exit 1; }
mkdir -p "$out/run1"
for f in "$flat"/*; do
    name="$(basename "$f")"
    [[ -f "$f" && "$name" != detectron_labels.csv ]] && ln -sfn "$f" "$out/$name"
done
for f in "$flat"/run1/*; do
    case "$f" in
        *_predicted.png|*_labels.json) ;;
        *) ln -sfn "$f" "$out/run1/$(basename "$f")" ;;
    esac
done
"$voxpan" segment --model "$model" --out "$out/run1" "$@" "$flat"/run1/*_color.png
mv "$out/run1/labels.csv" "$out/detectron_labels.csv"
echo "wrote $out (masks of $(basename "$model"))"
