# Shared by tools/association_sets.sh, association_modes.sh and association_draws.sh
# (sourced, not run): the release binary, leading `--config FILE` and `--live` parsing, the
# cached synthetic sets, and one row of voxel PQ read from `voxpan eval --3d`.
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
voxpan="$root/target/release/voxpan"
sets="${VOXPAN_SETS:-$root/target/association-sets}"
mkdir -p "$sets"
config=()
live=()
# Reads leading `--config FILE` and `--live` (a column for the default map as a live reader
# holds it when the stream stops: `voxpan eval --live`) from "$@", in either order; the
# caller shifts by $config_args afterwards. Sourced scripts share the caller's arguments,
# so they are read by position, not shifted here.
config_args=0
while :; do
    next="${*:config_args+1:1}"
    if [[ "$next" == "--config" ]]; then
        if (($# < config_args + 2)); then
            echo "--config needs a file" >&2
            exit 2
        fi
        config=(--config "${*:config_args+2:1}")
        config_args=$((config_args + 2))
    elif [[ "$next" == "--live" ]]; then
        live=(--live)
        config_args=$((config_args + 1))
    else
        break
    fi
done
# Prints the header of association_row's table: association_header WIDTH FIRST_COLUMN.
association_header() {
    printf "%-*s %8s %8s %8s %7s %10s" "$1" "$2" "gt" "default" "correct" "ratio" "instances"
    [[ ${#live[@]} -gt 0 ]] && printf " %8s" "live"
    printf "\n"
}
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
# random ids, default masks with the tracker and with correct association, their ratio, the
# default map's instances, and with --live the default map where the stream stops).
association_row() {
    local width="$1" name="$2" dataset="$3"
    shift 3
    local table
    table=$("$voxpan" eval "$dataset" --3d --rules default "${live[@]}" "${config[@]}" "$@" \
        2>/dev/null | sed -n '/^maps against/,$p')
    awk -v name="$name" -v width="$width" -v live="${#live[@]}" '
        /^gt random ids/ {gt = $4}
        /^default  / {def = $2; inst = $7 " " $8}
        /^default, live/ {liv = $3}
        /^default, correct/ {cor = $4}
        END {printf "%-*s %8.2f %8.2f %8.2f %7.2f %10s", width, name, gt, def, cor, def / cor, inst
             if (live) printf " %8.2f", liv
             printf "\n"}' <<<"$table"
}
