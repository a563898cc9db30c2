#!/usr/bin/env bash
# What sampling each pixel by its own error could take off MCPT's relMSE on the peers' scenes
# at an equal total of samples (docs/performance.md, "What sampling by pixel error could
# reach"): per scene, PILOT one-sample renders (seeds 101, 102, …) estimate each pixel's
# relative variance, 16 independent renders of 8 samples (seeds 1–16) score the allocation
# the pilot gives, and the `pixel_allocation` example prints the gains
# (crates/flowlight-bench/examples/pixel_allocation.rs says how they are computed).
#
#   crates/flowlight-bench/scripts/pixel-allocation.sh [PILOT ...]     # default: 4 8
#
# Needs `cargo build --release --workspace`, `cargo build --release -p flowlight-bench
# --example pixel_allocation`, and the peers' configs and references (run
# crates/flowlight-bench/peers/peers.py once; PEERS_OUT, default target/peers/out). On the
# two-core Zen 4 VM it takes about two minutes.
set -euo pipefail
cd "$(dirname "$0")/../../.."
bin=${FLOWLIGHT_BIN:-target/release/flowlight}
tool=target/release/examples/pixel_allocation
for b in "$bin" "$tool"; do
    [ -x "$b" ] || { echo "$b missing: build it first (see the header)" >&2; exit 1; }
done
peers=${PEERS_OUT:-target/peers/out}
for f in cornell-box.toml cornell-box.ref.exr stanford-dragon.toml stanford-dragon.ref.exr; do
    [ -f "$peers/$f" ] || { echo "$peers/$f missing: run crates/flowlight-bench/peers/peers.py first" >&2; exit 1; }
done
pilots=("$@")
[ ${#pilots[@]} -gt 0 ] || pilots=(4 8)
for p in "${pilots[@]}"; do
    case $p in
        [2-9] | [1-5][0-9] | 6[0-4]) ;;
        *) echo "PILOT=$p: a whole number in 2..64" >&2; exit 1 ;;
    esac
done
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

render() { # SCENE SPP SEED FILE
    "$bin" render "$peers/$1.toml" --spp "$2" --seed "$3" --threads 2 --quiet --out "$4" \
        >"$out/log" 2>&1 || { echo "render failed: $(tail -1 "$out/log")" >&2; exit 1; }
}

max_pilot=$(printf '%s\n' "${pilots[@]}" | sort -n | tail -1)
for scene in cornell-box stanford-dragon; do
    for seed in $(seq 1 16); do render "$scene" 8 "$seed" "$out/$scene-eval-$seed.exr"; done
    for seed in $(seq 101 $((100 + max_pilot))); do render "$scene" 1 "$seed" "$out/$scene-pilot-$seed.exr"; done
    for p in "${pilots[@]}"; do
        echo "## $scene, pilot of $p samples per pixel"
        echo
        "$tool" "$peers/$scene.ref.exr" \
            --pilot $(seq -f "$out/$scene-pilot-%g.exr" 101 $((100 + p))) \
            --eval $(seq -f "$out/$scene-eval-%g.exr" 1 16) | sed 's/^/    /'
        echo
    done
done
