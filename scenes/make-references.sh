#!/usr/bin/env bash
# Renders the committed references scenes/<scene>/reference/<scene>.exr of the benchmark
# suites (scenes/suite.toml, scenes/suite-erpt.toml): once, long, with the most efficient MCPT
# configuration per scene (docs/results.md), at the suites' 128x128 and each scene's
# path_depth, with lighting layers, as two independent halves (seeds 1000000 and 1000001)
# whose difference gives the variance layer and the floor (docs/bench.md). The EXR metadata
# records the spp, seeds, parameters, path depths, floor and this command line.
#
#   scenes/make-references.sh [SCENE...]        # default: all six; build the dev profile first:
#   cargo build -p flowlight -p flowlight-mcpt
#
# FLOWLIGHT (default target/debug/flowlight) and THREADS (default 2) can be set. The
# committed files were made with the default BUDGET=time (cornell-box since with BUDGET=spp, release build: 20480 spp, floor 1.93e-5) (each scene's wall-time budget of the
# table, split over the two halves, on a 2-core machine shared with six other helpers' builds:
# the spp they reached are in docs/results.md and in each file's flowlight.spp), and are too
# short for the floor rule against ERPT. BUDGET=spp renders the table's spp instead: what each
# scene needs for a floor of 1/30 of today's best MCPT relMSE at 8 s (docs/results.md, setup
# section; about 50 minutes in all on an idle 2-core machine). Then commit the new files.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="${FLOWLIGHT:-$root/target/debug/flowlight}"
threads="${THREADS:-2}"

# scene | wall seconds (both halves) | spp (both halves) | MCPT parameters
table=(
  "glass-caustic|480|46080|variant=untangled termination=equi"
  "mirror-chain|720|11264|variant=entangled termination=bxdf"
  "indirect-room|720|8192|variant=entangled termination=expo"
  "ring-caustic|600|22528|variant=untangled termination=equi"
  "cornell-box|420|20480|variant=entangled termination=bxdf"
  "narrow-gap|480|23552|variant=entangled termination=equi"
)
budget_kind="${BUDGET:-time}"

want=("$@")
for row in "${table[@]}"; do
  IFS='|' read -r scene seconds spp params <<<"$row"
  if [ ${#want[@]} -gt 0 ] && [[ ! " ${want[*]} " == *" $scene "* ]]; then continue; fi
  sets=(--set layers=true)
  for p in $params; do sets+=(--set "$p"); done
  mkdir -p "$root/scenes/$scene/reference"
  if [ "$budget_kind" = spp ]; then budget=(--spp "$spp"); else budget=(--time "$seconds"); fi
  echo "== $scene: ${budget[*]}, $params"
  (cd "$root/scenes" && "$bin" reference "$scene/$scene.toml" --width 128 --height 128 \
    "${budget[@]}" --seed 1000000 --threads "$threads" "${sets[@]}" \
    --out "$scene/reference/$scene.exr")
done
