#!/usr/bin/env bash
# Same seed, same bytes, across builds: runs `robocal generate` with two builds of robocal on every
# shipped scenario (or those given) at the given seeds and compares the three output files byte for
# byte. Used to check that a change of the generator (streaming, issue 15) leaves the data as it was.
#
#   scripts/same_bytes.sh OLD_ROBOCAL NEW_ROBOCAL [--seeds "0 7"] [--poses N] [scenario.toml ...]
#
# Prints one line per scenario and seed (`same` or `DIFFERENT: files`), exits 1 if any differ.
set -euo pipefail

usage() {
    echo "usage: $0 OLD_ROBOCAL NEW_ROBOCAL [--seeds \"0 7\"] [--poses N] [scenario.toml ...]" >&2
    exit 2
}
[[ $# -ge 2 ]] || usage
old=$1
new=$2
shift 2
seeds="0 7"
poses=()
scenarios=()
while [[ $# -gt 0 ]]; do
    case $1 in
        --seeds) seeds=$2; shift 2 ;;
        --poses) poses=(--poses "$2"); shift 2 ;;
        -*) usage ;;
        *) scenarios+=("$1"); shift ;;
    esac
done
root=$(cd "$(dirname "$0")/.." && pwd)
if [[ ${#scenarios[@]} -eq 0 ]]; then
    scenarios=("$root"/scenarios/*.toml)
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

status=0
for s in "${scenarios[@]}"; do
    for seed in $seeds; do
        name=$(basename "$s" .toml)
        for which in old new; do
            bin=$old
            [[ $which == new ]] && bin=$new
            rm -rf "$work/$which"
            "$bin" generate --scenario "$s" --out "$work/$which" --seed "$seed" "${poses[@]}" \
                >/dev/null 2>"$work/$which.err" || {
                echo "$name seed $seed: $which build failed: $(tail -1 "$work/$which.err")"
                status=1
                continue 2
            }
        done
        diff=()
        for f in measurements.parquet truth.parquet truth.json; do
            cmp -s "$work/old/$f" "$work/new/$f" || diff+=("$f")
        done
        if [[ ${#diff[@]} -eq 0 ]]; then
            echo "$name seed $seed: same"
        else
            echo "$name seed $seed: DIFFERENT: ${diff[*]}"
            status=1
        fi
    done
done
exit $status
