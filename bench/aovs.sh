#!/usr/bin/env bash
# The cost of render passes: one scene rendered without passes, with the denoising features (albedo, normal, depth),
# and with every pass, at the same samples; each RUNS times, printing the median wall and CPU seconds and the peak
# resident memory of the whole `tessera render` (loading, rendering, resolving and writing the EXR), and each
# configuration's ratio to the one without passes. Run it twice with different SPP to tell the per-sample cost from
# the fixed cost of resolving and encoding the passes.
#
#   bench/aovs.sh [JOB.json]            (default: the Cornell box)
#   env: BUILD=build WIDTH=1920 HEIGHT=1080 SPP=16 RUNS=3 THREADS=<all>
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
WIDTH=${WIDTH:-1920}
HEIGHT=${HEIGHT:-1080}
SPP=${SPP:-16}
RUNS=${RUNS:-3}
TESSERA=$BUILD/clients/cli/tessera
job=${1:-proto/examples/cornell.json}
threads=()
[[ -n ${THREADS:-} ]] && threads=(--threads "$THREADS")
[[ -x $TESSERA ]] || { echo "build $TESSERA first (cmake --build $BUILD --target tessera)" >&2; exit 1; }
[[ -x /usr/bin/time ]] || { echo "/usr/bin/time not found (apt-get install time)" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# Every pass the contract lists (the render schema's enum), as --aov options.
all=$(python3 -c 'import json, sys; print(" ".join("--aov " + n for n in json.load(open(sys.argv[1]))["properties"]["aovs"]["items"]["enum"]))' \
  proto/schemas/render.schema.json)
declare -A configs=([none]="" [features]="--aov albedo --aov normal --aov depth" [all]="$all")

# median of the numbers on stdin
median() { sort -g | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }

printf '%s at %dx%d, %d spp, %d runs each (medians)\n' "$job" "$WIDTH" "$HEIGHT" "$SPP" "$RUNS"
printf '%-9s %8s %8s %9s %8s %8s\n' passes wall_s cpu_s peak_MiB wall/none cpu/none
declare -A wall cpu
for name in none features all; do
  : >"$tmp/$name"
  for _ in $(seq "$RUNS"); do
    # shellcheck disable=SC2086  # the options are words
    /usr/bin/time -f '%e %U %S %M' -o "$tmp/t" "$TESSERA" render "$job" --width "$WIDTH" --height "$HEIGHT" \
      --spp "$SPP" -q "${threads[@]}" ${configs[$name]} -o "$tmp/$name.exr"
    cat "$tmp/t" >>"$tmp/$name"
  done
  wall[$name]=$(awk '{ print $1 }' "$tmp/$name" | median)
  cpu[$name]=$(awk '{ print $2 + $3 }' "$tmp/$name" | median)
  peak=$(awk '{ print $4 / 1024 }' "$tmp/$name" | median)
  printf '%-9s %8.2f %8.2f %9.0f %8.3f %8.3f\n' "$name" "${wall[$name]}" "${cpu[$name]}" "$peak" \
    "$(awk -v a="${wall[$name]}" -v b="${wall[none]}" 'BEGIN { print a / b }')" \
    "$(awk -v a="${cpu[$name]}" -v b="${cpu[none]}" 'BEGIN { print a / b }')"
done
