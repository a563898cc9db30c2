#!/usr/bin/env bash
# Renders the committed references scenes/<scene>/reference/<scene>.exr of the benchmark
# suites (scenes/suite.toml, scenes/experiments/*.toml): once, long, with the most efficient
# configuration per scene (docs/results.md): MCPT for the suite scenes, the bidirectional
# config a research scene ships (its bdpt.toml or vcm.toml: no MCPT converges there), at the
# suites' 128x128 and each scene's MCPT path_depth, with lighting layers, as two independent halves (seeds 1000000 and 1000001)
# whose difference gives the variance layer and the floor (docs/bench.md). The EXR metadata
# records the spp, seeds, parameters, path depths, floor and this command line.
#
#   scenes/make-references.sh [SCENE...]        # default: all twelve; build the dev profile first:
#   cargo build --workspace
#
# FLOWLIGHT (default target/debug/flowlight) and THREADS (default 2) can be set. The
# committed files were made with BUDGET=spp (the table's spp: a floor of about 1/30 of the
# best MCPT relMSE at 8 s; release build, 2 threads; docs/results.md lists spp and
# floor per scene). The default BUDGET=time renders each scene's wall-time budget instead
# (split over the two halves), for a quick look; such references are too short for the floor
# rule against ERPT. Then commit the new files.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="${FLOWLIGHT:-$root/target/debug/flowlight}"
threads="${THREADS:-2}"

# scene | wall seconds (both halves) | spp (both halves) | parameters | config (default
# <scene>.toml)
table=(
  "glass-caustic|600|49152|variant=entangled termination=expo"
  "mirror-chain|720|11264|variant=entangled termination=bxdf"
  "indirect-room|1200|16384|variant=entangled termination=expo"
  "ring-caustic|900|61440|variant=untangled termination=equi"
  "cornell-box|420|20480|variant=entangled termination=bxdf"
  "narrow-gap|480|23552|variant=entangled termination=equi"
  "veach-door|420|0|path_depth=12|bdpt.toml"
  "water-pool|480|0|path_depth=12|vcm.toml"
  "veach-mis|240|0|path_depth=10|bdpt.toml"
  "lamp-shade|240|0|path_depth=10|bdpt.toml"
  "lens-spot|300|0|path_depth=10|bdpt.toml"
  "glass-rod|300|14336|path_depth=10|bdpt.toml"
)
budget_kind="${BUDGET:-time}"

want=("$@")
for row in "${table[@]}"; do
  IFS='|' read -r scene seconds spp params config <<<"$row"
  if [ ${#want[@]} -gt 0 ] && [[ ! " ${want[*]} " == *" $scene "* ]]; then continue; fi
  sets=(--set layers=true)
  for p in $params; do sets+=(--set "$p"); done
  mkdir -p "$root/scenes/$scene/reference"
  config="${config:-$scene.toml}"
  # The research scenes' references are made by time (spp 0 in the table), but for glass-rod,
  # whose 300 s reference was too noisy for the floor rule against ERPT seeded by BDPT.
  if [ "$budget_kind" = spp ] && [ "$spp" != 0 ]; then budget=(--spp "$spp"); else budget=(--time "$seconds"); fi
  echo "== $scene: ${budget[*]}, $params"
  (cd "$root/scenes" && "$bin" reference "$scene/$config" --width 128 --height 128 \
    "${budget[@]}" --seed 1000000 --threads "$threads" "${sets[@]}" \
    --out "$scene/reference/$scene.exr")
done
