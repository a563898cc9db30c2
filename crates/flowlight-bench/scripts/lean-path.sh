#!/usr/bin/env bash
# What MCPT's walker spends beyond the least a path tracer must do, and what eight lanes per
# instruction take off that least (docs/performance.md, "What a lean path costs"): on the
# peers' scenes, one thread, alternated rounds of
#
#   - `flowlight render` with MCPT at one branch (`--set branches=1`), its summary's CPU time;
#   - the `lean_path` example (crates/flowlight-bench/examples/lean_path/) in each of its
#     modes: `scalar` (one path at a time), `phased` (each phase of the vertex over the whole
#     wave), `lanes` (eight paths per step, SSE) and `avx2` (the same compiled for AVX2), its
#     wall time on one thread.
#
# Each is divided by the camera samples (256² × SPP). Every lean mode's image is checked to
# be the scalar mode's bits, and each image's relMSE against the peers' reference is printed,
# so a faster mode that computed something else would show.
#
#   crates/flowlight-bench/scripts/lean-path.sh [ROUNDS [SPP]]     # default 3 rounds, 64 spp
#
# Needs `cargo build --release --workspace` and `cargo build --release -p flowlight-bench
# --example lean_path`, and the peers' configs and references (run
# crates/flowlight-bench/peers/peers.py once; PEERS_OUT, default target/peers/out).
set -euo pipefail
cd "$(dirname "$0")/../../.."
bin=${FLOWLIGHT_BIN:-target/release/flowlight}
lean=${LEAN_BIN:-target/release/examples/lean_path}
for b in "$bin" "$lean"; do
    [ -x "$b" ] || { echo "$b missing: build it first (see the header)" >&2; exit 1; }
done
peers=${PEERS_OUT:-target/peers/out}
for f in cornell-box.toml cornell-box.ref.exr stanford-dragon.toml stanford-dragon.ref.exr; do
    [ -f "$peers/$f" ] || { echo "$peers/$f missing: run crates/flowlight-bench/peers/peers.py first" >&2; exit 1; }
done
rounds=${1:-3}
spp=${2:-64}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
samples=$((256 * 256 * spp))

relmse() { "$bin" compare "$1" "$2" | awk '/relMSE/ {print $2; exit}'; }

echo "| scene | round | MCPT, 1 branch (µs) | lean scalar (µs) | lean phased (µs) | lean lanes (µs) | lean avx2 (µs) |"
echo "|---|---:|---:|---:|---:|---:|---:|"
for scene in cornell-box stanford-dragon; do
    for r in $(seq "$rounds"); do
        cpu=$("$bin" render "$peers/$scene.toml" --spp "$spp" --threads 1 --set branches=1 \
            --out "$out/mcpt.exr" 2>/dev/null | awk '/cpu time/ {print $3; exit}')
        row="| $scene | $r | $(awk -v c="$cpu" -v n="$samples" 'BEGIN { printf "%.3f", c / n * 1e6 }')"
        for mode in scalar phased lanes avx2; do
            t=$(LEAN_MODE=$mode "$lean" "$peers/$scene.toml" "$spp" "$out/$mode.exr" 2>/dev/null \
                | awk '/lean_path:/ {print $2; exit}')
            row="$row | $(awk -v c="$t" -v n="$samples" 'BEGIN { printf "%.3f", c / n * 1e6 }')"
        done
        echo "$row |"
        for mode in phased lanes avx2; do
            rmse=$("$bin" compare "$out/$mode.exr" "$out/scalar.exr" | awk '$1 == "RMSE" {print $2; exit}')
            awk -v e="$rmse" 'BEGIN { exit !(e == 0) }' \
                || { echo "$scene: the $mode image differs from the scalar one (RMSE $rmse)" >&2; exit 1; }
        done
    done
    echo "relMSE against the reference, $scene, last round: MCPT $(relmse "$out/mcpt.exr" "$peers/$scene.ref.exr"), lean $(relmse "$out/scalar.exr" "$peers/$scene.ref.exr")" >&2
done
