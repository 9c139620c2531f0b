# Shared by tools/association_sets.sh and tools/association_modes.sh (sourced, not run):
# the release binary, `--config FILE` parsing, the cached synthetic sets, and one row of
# voxel PQ read from `voxpan eval --3d`.
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
voxpan="$root/target/release/voxpan"
sets="${VOXPAN_SETS:-$root/target/association-sets}"
mkdir -p "$sets"
config=()
# Reads a leading `--config FILE` from "$@"; the caller shifts by $config_args afterwards.
config_args=0
if [[ "${1:-}" == "--config" ]]; then
    config=(--config "$2")
    config_args=2
fi
# Generates synthetic set NAME once: make_set NAME SYNTH_ARGS...
make_set() {
    local dir="$sets/$1"
    shift
    [[ -f "$dir/done" ]] && return
    rm -rf "$dir"
    "$voxpan" synth --out "$dir" "$@" >/dev/null 2>&1
    touch "$dir/done"
}
# Prints one row: association_row WIDTH NAME DATASET EVAL_ARGS... (ground-truth masks with
# random ids, default masks with the tracker and with correct association, their ratio, and
# the default map's instances).
association_row() {
    local width="$1" name="$2" dataset="$3"
    shift 3
    local table
    table=$("$voxpan" eval "$dataset" --3d --rules default "${config[@]}" "$@" 2>/dev/null |
        sed -n '/^maps against/,$p')
    awk -v name="$name" -v width="$width" '
        /^gt random ids/ {gt = $4}
        /^default  / {def = $2; inst = $7 " " $8}
        /^default, correct/ {cor = $4}
        END {printf "%-*s %8.2f %8.2f %8.2f %7.2f %10s\n", width, name, gt, def, cor, def / cor, inst}' <<<"$table"
}
