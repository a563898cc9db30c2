#!/usr/bin/env bash
# Thread scaling of MCPT on the Stanford dragon (871k triangles), through Embree and through
# the pure-Rust BVH: render wall time (the log's "wall time", which excludes loading and the
# acceleration-structure build), the build time, and parallel efficiency T(1) / (n · T(n)).
# For a many-core machine; on 2 cores only the 1- and 2-thread rows mean anything.
#
#   crates/flowlight-bench/scripts/scaling.sh [SPP [THREADS...]]   # default 128 spp; 1 2 4 8 16
#
# Needs `cargo build --release --workspace` and the dragon scene (`bash .ci/setup`). The
# Cornell box's scaling per accumulation style is `crates/flowlight-bench/accumulation/run.sh
# scaling`; ray-query scaling alone is the rays bench with `FLOWLIGHT_BENCH_THREADS`.
# Results go to stdout as markdown rows, the renders to $OUT_DIR (default a temp dir).
set -euo pipefail
cd "$(dirname "$0")/../../.."
bin=${FLOWLIGHT_BIN:-target/release/flowlight}
[ -x "$bin" ] || { echo "build first: cargo build --release --workspace" >&2; exit 1; }
scene=$PWD/scenes/stanford-dragon
[ -f "$scene/dragon.gltf" ] || { echo "fetch the dragon first: bash .ci/setup" >&2; exit 1; }
. crates/flowlight-bench/scripts/render-config.sh
out=${OUT_DIR:-$(mktemp -d)}
mkdir -p "$out"
spp=${1:-128}
shift || true
threads=${*:-1 2 4 8 16}
cores=$(nproc)

echo "| intersector | threads | render wall (s) | build (s) | M samples/s | parallel efficiency |"
echo "|---|---:|---:|---:|---:|---:|"
for intersector in embree bvh; do
    cfg=$out/dragon-$intersector.toml
    # The scene's config with an absolute scene path, this intersector and no outputs.
    render_config "$scene/dragon.toml" "$cfg" "intersector=\"$intersector\""
    t1=
    for n in $threads; do
        [ "$n" -le "$cores" ] || continue
        log=$out/dragon-$intersector-$n.log
        "$bin" render "$cfg" --spp "$spp" --threads "$n" --quiet --out "$out/dragon.exr" >"$log" 2>&1
        wall=$(grep -m1 "wall time" "$log" | awk '{print $3}')
        build=$(grep -m1 "^  intersector " "$log" | sed -E 's/.*build ([0-9.]+) s.*/\1/')
        rate=$(grep -m1 "samples " "$log" | grep -o '[0-9.]* M samples/s' | awk '{print $1}')
        t1=${t1:-$wall}
        eff=$(awk -v a="$t1" -v b="$wall" -v n="$n" -v m="${threads%% *}" \
            'BEGIN { printf "%.2f", a * m / (n * b) }')
        echo "| $intersector | $n | $wall | ${build:-?} | $rate | $eff |"
    done
done
