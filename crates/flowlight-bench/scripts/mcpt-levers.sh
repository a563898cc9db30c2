#!/usr/bin/env bash
# The sampling levers of MCPT's efficiency against Mitsuba 3 (docs/performance.md, "Target 1"),
# on the peers' scenes at their settings (256², path depth 32, 2 threads). Each MCPT
# parameter setting below is rendered at SPP samples per pixel with seeds 1001 and 1002 (apart
# from the references': the peers' use 1000000 and 1000001, the direct-light one below the
# configs' 1) and compared with the peers' reference. Markdown rows of CPU time, relMSE and
# efficiency 1 / (relMSE × CPU time); the references' floors, below 1% of every relMSE here,
# are not subtracted.
#
#   crates/flowlight-bench/scripts/mcpt-levers.sh [SPP]        # default 32
#
# Rows: `branches` 1, 4 (the default), 8, 16; `rr_depth` 1, 2, 3, 5 (the default), 8, 12; the
# independent sampler against Sobol' at 1 and 4 branches (the Cornell box); `branches` 1, 2,
# 4, 8 on the dragon; and how much of each scene's error is direct light: direct light alone
# (`path_depth = 1`) at SPP against its own reference of 1024 spp, one branch and four.
# On the two-core Zen 4 VM the whole run takes about three minutes.
#
# Needs `cargo build --release --workspace` and the peers' configs and cached references:
# run `crates/flowlight-bench/peers/peers.py` once (PEERS_OUT, default target/peers/out).
# OUT_DIR keeps the images and logs (default a temp dir).
set -euo pipefail
cd "$(dirname "$0")/../../.."
bin=${FLOWLIGHT_BIN:-target/release/flowlight}
[ -x "$bin" ] || { echo "build first: cargo build --release --workspace" >&2; exit 1; }
peers=${PEERS_OUT:-target/peers/out}
for f in cornell-box.toml cornell-box.ref.exr stanford-dragon.toml stanford-dragon.ref.exr; do
    [ -f "$peers/$f" ] || { echo "$peers/$f missing: run crates/flowlight-bench/peers/peers.py first" >&2; exit 1; }
done
spp=${1:-32}
out=${OUT_DIR:-$(mktemp -d)}
mkdir -p "$out"

field() { grep -m1 "$2" "$1" | awk "$3"; }

# row SCENE REF LABEL [--set K=V ...]: one row per seed.
row() {
    local scene=$1 ref=$2 label=$3
    shift 3
    for seed in 1001 1002; do
        local img=$out/lever.exr log=$out/lever.log
        "$bin" render "$peers/$scene.toml" --spp "$spp" --seed "$seed" --threads 2 --quiet \
            --out "$img" "$@" >"$log" 2>&1 || { echo "render failed: see $log" >&2; exit 1; }
        local cpu rel
        cpu=$(field "$log" "cpu time" '{print $3}')
        rel=$("$bin" compare "$img" "$ref" | field /dev/stdin "relMSE" '{print $2}')
        awk -v s="$scene" -v l="$label" -v seed="$seed" -v c="$cpu" -v r="$rel" \
            'BEGIN { printf "| %s | %s | %d | %.3f | %.3e | %.1f |\n", s, l, seed, c, r, 1 / (r * c) }'
    done
}

echo "| scene | setting | seed | CPU (s) | relMSE | efficiency |"
echo "|---|---|---:|---:|---:|---:|"
cbox_ref=$peers/cornell-box.ref.exr
for b in 1 4 8 16; do row cornell-box "$cbox_ref" "branches = $b" --set "branches=$b"; done
for r in 1 2 3 5 8 12; do row cornell-box "$cbox_ref" "rr_depth = $r" --set "rr_depth=$r"; done
for b in 1 4; do
    row cornell-box "$cbox_ref" "independent sampler, branches = $b" --set "branches=$b" --set sampler=independent
done
for b in 1 2 4 8; do
    row stanford-dragon "$peers/stanford-dragon.ref.exr" "branches = $b" --set "branches=$b"
done

# Direct light alone, against a direct-light reference of its own.
for scene in cornell-box stanford-dragon; do
    direct_ref=$out/$scene-direct-ref.exr
    "$bin" render "$peers/$scene.toml" --spp 1024 --threads 2 --quiet --set path_depth=1 \
        --set branches=1 --out "$direct_ref" >"$out/$scene-direct-ref.log" 2>&1
    for b in 1 4; do
        row "$scene" "$direct_ref" "direct light only (path_depth = 1), branches = $b" \
            --set path_depth=1 --set "branches=$b"
    done
done
