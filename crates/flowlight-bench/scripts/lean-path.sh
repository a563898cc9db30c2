#!/usr/bin/env bash
# What MCPT's walker spends beyond the least a path tracer must do, and what eight lanes per
# instruction take off that least (docs/performance.md, "What a lean path costs"): on the
# peers' scenes, one thread, alternated rounds of
#
#   - `flowlight render` with MCPT at one branch (`--set branches=1`; `BRANCHES=k` for k),
#     its summary's CPU time;
#   - the `lean_path` example (crates/flowlight-bench/examples/lean_path/) in each of its
#     modes: `scalar` (one path at a time), `phased` (each phase of the vertex over the whole
#     wave), `lanes` (eight paths per step, SSE), `avx2` (the same compiled for AVX2) and
#     `surface8` (only the surface in AVX2 lanes), its wall time on one thread.
#
# Each is divided by the camera samples (256² × SPP). Every lean mode's image is checked to
# be the scalar mode's bits, and each image's relMSE against the peers' reference is printed,
# so a faster mode that computed something else would show.
#
#   crates/flowlight-bench/scripts/lean-path.sh [ROUNDS [SPP]]     # default 3 rounds, 64 spp
#   crates/flowlight-bench/scripts/lean-path.sh --instructions
#
# `--instructions` counts instead, exactly, by callgrind: MCPT at one branch and the lean
# path's `scalar` and `avx2` modes, each as the difference of a 1-spp and a 2-spp render
# (loading and the BVH build cancel), split into Embree's and everything else's
# instructions per camera sample (needs Debian `valgrind`; about five minutes).
#
# `FAST=1` renders everything with Embree's fast mode (`[render] robust = false` in copies of
# the peers' configs), to see what a vectorised path and fast mode would reach together.
# `BRANCHES=k` (default 1) splits every camera path into k branches at its first vertex in
# MCPT and the lean path alike (`--set branches=k`, `LEAN_BRANCHES=k`): MCPT's default is 4.
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
branches=${BRANCHES:-1}
case $branches in
    [1-9] | [1-5][0-9] | 6[0-4]) ;;
    *) echo "BRANCHES=$branches: a whole number in 1..64" >&2; exit 1 ;;
esac
export LEAN_BRANCHES=$branches
for f in cornell-box.toml cornell-box.ref.exr stanford-dragon.toml stanford-dragon.ref.exr; do
    [ -f "$peers/$f" ] || { echo "$peers/$f missing: run crates/flowlight-bench/peers/peers.py first" >&2; exit 1; }
done
if [ "${1:-}" = --instructions ]; then
    command -v valgrind >/dev/null || { echo "valgrind missing (Debian: valgrind)" >&2; exit 1; }
    out=$(mktemp -d)
    trap 'rm -rf "$out"' EXIT
    count() { # LABEL SCENE ENV-MODE COMMAND-WITH-@SPP@...
        local label=$1 scene=$2 mode=$3
        shift 3
        for spp in 1 2; do
            LEAN_MODE=$mode valgrind --tool=callgrind --dump-instr=yes --compress-strings=no --compress-pos=no \
                --callgrind-out-file="$out/$spp.cg" "${@//@SPP@/$spp}" >/dev/null 2>&1
        done
        python3 - "$out/1.cg" "$out/2.cg" "$label" "$scene" <<'PY'
import importlib.util, os, sys
here = "crates/flowlight-bench/scripts/inline-profile.py"
spec = importlib.util.spec_from_file_location("inline_profile", here)
ip = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ip)
split = []
for f in sys.argv[1:3]:
    embree = rest = 0
    for obj, costs in ip.instruction_counts(f).items():
        n = sum(costs.values())
        if obj and "embree" in os.path.basename(obj):
            embree += n
        else:
            rest += n
    split.append((embree, rest))
samples = 256 * 256
e, r = ((b - a) / samples for a, b in zip(*split))
print(f"| {sys.argv[4]} | {sys.argv[3]} | {r:,.0f} | {e:,.0f} |")
PY
    }
    echo "| scene | renderer | instructions besides Embree | Embree's |"
    echo "|---|---|---:|---:|"
    for scene in cornell-box stanford-dragon; do
        count "MCPT, $branches branch(es)" "$scene" scalar "$bin" render "$peers/$scene.toml" --spp @SPP@ \
            --threads 1 --quiet --set branches="$branches" --out "$out/mcpt.exr"
        for mode in scalar avx2; do
            count "lean $mode" "$scene" "$mode" "$lean" "$peers/$scene.toml" @SPP@ "$out/lean.exr"
        done
    done
    exit 0
fi
rounds=${1:-3}
spp=${2:-64}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cfg() { echo "$peers/$1.toml"; }
if [ "${FAST:-0}" = 1 ]; then
    for scene in cornell-box stanford-dragon; do
        grep -q '^robust' "$peers/$scene.toml" && { echo "$peers/$scene.toml sets robust already" >&2; exit 1; }
        sed 's/^\[render\]$/[render]\nrobust = false/' "$peers/$scene.toml" >"$out/$scene.toml"
    done
    cfg() { echo "$out/$1.toml"; }
    echo "Embree's fast mode (robust = false) for every render."
    echo
fi
samples=$((256 * 256 * spp))

relmse() { "$bin" compare "$1" "$2" | awk '/relMSE/ {print $2; exit}'; }

echo "Branches per camera sample: $branches (MCPT and the lean path)."
echo
echo "| scene | round | MCPT (µs) | lean scalar (µs) | lean phased (µs) | lean lanes (µs) | lean avx2 (µs) | lean surface8 (µs) |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|"
for scene in cornell-box stanford-dragon; do
    for r in $(seq "$rounds"); do
        cpu=$("$bin" render "$(cfg "$scene")" --spp "$spp" --threads 1 --set branches="$branches" \
            --out "$out/mcpt.exr" 2>/dev/null | awk '/cpu time/ {print $3; exit}')
        row="| $scene | $r | $(awk -v c="$cpu" -v n="$samples" 'BEGIN { printf "%.3f", c / n * 1e6 }')"
        for mode in scalar phased lanes avx2 surface8; do
            t=$(LEAN_MODE=$mode "$lean" "$(cfg "$scene")" "$spp" "$out/$mode.exr" 2>/dev/null \
                | awk '/lean_path:/ {print $2; exit}')
            row="$row | $(awk -v c="$t" -v n="$samples" 'BEGIN { printf "%.3f", c / n * 1e6 }')"
        done
        echo "$row |"
        for mode in phased lanes avx2 surface8; do
            rmse=$("$bin" compare "$out/$mode.exr" "$out/scalar.exr" | awk '$1 == "RMSE" {print $2; exit}')
            awk -v e="$rmse" 'BEGIN { exit !(e == 0) }' \
                || { echo "$scene: the $mode image differs from the scalar one (RMSE $rmse)" >&2; exit 1; }
        done
    done
    echo "relMSE against the reference, $scene, last round: MCPT $(relmse "$out/mcpt.exr" "$peers/$scene.ref.exr"), lean $(relmse "$out/scalar.exr" "$peers/$scene.ref.exr")" >&2
done
