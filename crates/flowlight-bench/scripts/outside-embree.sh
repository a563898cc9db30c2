#!/usr/bin/env bash
# Performance target 3 (docs/performance.md): the share of an MCPT render of the Stanford
# dragon that is spent outside Embree's ray queries (target ≤ 40%). One render thread (`dragon.toml`, 480×320,
# 8 spp), sampled by `perf record -F 999`; a render thread's samples are split by library:
# libembree4 (the ray queries) against everything else (the plugin's sampling and shading
# and surface data, the host's batch callbacks and accumulation, libc). The loader, the
# acceleration-structure build and the EXR writer run on other threads and are left out.
#
#   crates/flowlight-bench/scripts/outside-embree.sh [RUNS [SPP]]     # default 4 runs, 8 spp
#   FLOWLIGHT_BIN_B=/path/to/other/flowlight ... outside-embree.sh    # alternate two builds
#
# With FLOWLIGHT_BIN_B the runs alternate between the two binaries (a before/after on a
# shared machine, where the share moves by a few points from run to run). A copied binary
# finds its plugins beside it and Embree through FLOWLIGHT_EMBREE_LIB.
#
# The split is `perf report --sort comm,dso`: with perf 6.1, `--comm flowlight-worke --sort
# dso` drops every library that other threads also ran (Embree among them) from the report.
set -euo pipefail
cd "$(dirname "$0")/../../.."
command -v perf >/dev/null || { echo "perf is missing (Debian: linux-perf)" >&2; exit 1; }
bin=${FLOWLIGHT_BIN:-target/release/flowlight}
[ -x "$bin" ] || { echo "build first: cargo build --release --workspace" >&2; exit 1; }
[ -f scenes/stanford-dragon/dragon.gltf ] || { echo "fetch the dragon first: bash .ci/setup" >&2; exit 1; }
runs=${1:-4}
spp=${2:-8}
out=${OUT_DIR:-$(mktemp -d)}
mkdir -p "$out"
bins=("$bin")
[ -n "${FLOWLIGHT_BIN_B:-}" ] && bins+=("$FLOWLIGHT_BIN_B")

echo "| run | binary | Embree (% of samples) | elsewhere | outside Embree |"
echo "|---:|---|---:|---:|---:|"
for run in $(seq "$runs"); do
    for b in "${bins[@]}"; do
        perf record -q -F 999 -o "$out/perf.data" -- "$b" render \
            scenes/stanford-dragon/dragon.toml --spp "$spp" --threads 1 --quiet \
            --out "$out/dragon.exr" >/dev/null 2>&1
        perf report -i "$out/perf.data" --no-children --sort comm,dso --stdio 2>/dev/null |
            awk -v run="$run" -v b="$b" '
                $2 == "flowlight-worke" {
                    sub(/%/, "", $1)
                    if ($3 ~ /^libembree4/) e += $1; else o += $1
                }
                END {
                    if (e + o == 0) { print "no render-thread samples" > "/dev/stderr"; exit 1 }
                    printf "| %d | %s | %.1f | %.1f | %.1f%% |\n", run, b, e, o, 100 * o / (e + o)
                }'
    done
done
