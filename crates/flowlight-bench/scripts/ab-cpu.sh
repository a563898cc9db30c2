#!/usr/bin/env bash
# Render CPU of two builds of Flowlight, alternated: the before/after of a change to the
# renderer (docs/performance.md, "Profiling"). On each of the peers' scenes (the Cornell box
# and the Lambertian dragon, 256², path depth 32) it renders PAIRS pairs, A then B, at SPP
# samples per pixel on one thread, after one untimed render of each, and prints each
# render's CPU time (the summary's, render only), each build's range per scene, and whether
# the two builds' images are the same bytes (else their RMSE).
#
#   crates/flowlight-bench/scripts/ab-cpu.sh BIN_A BIN_B [PAIRS] [SPP]   # defaults 3, 16
#
# BIN_A and BIN_B are `flowlight` binaries, each beside the plugins it was built with (a
# release build's target/release/, or a copy of its `flowlight` and `*.so`). Needs the
# peers' configs: run crates/flowlight-bench/peers/peers.py once (PEERS_OUT, default
# target/peers/out). On the two-core Zen 4 VM, three pairs at 16 spp take
# about a minute.
set -euo pipefail
cd "$(dirname "$0")/../../.."
[ $# -ge 2 ] || { echo "usage: $0 BIN_A BIN_B [PAIRS] [SPP]" >&2; exit 2; }
a=$1 b=$2 pairs=${3:-3} spp=${4:-16}
for bin in "$a" "$b"; do
    [ -x "$bin" ] || { echo "$bin: not an executable" >&2; exit 1; }
done
peers=${PEERS_OUT:-target/peers/out}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

# cpu BIN SCENE TAG: one render's CPU seconds; its image is $out/TAG.exr.
cpu() {
    local log=$out/$3.log
    "$1" render "$peers/$2.toml" --spp "$spp" --threads 1 --quiet --out "$out/$3.exr" \
        >"$log" 2>&1 || { echo "render failed: $(tail -1 "$log")" >&2; exit 1; }
    grep -m1 "cpu time" "$log" | awk '{print $3}'
}

# range T...: the smallest and largest of the times T.
range() { printf '%s\n' "$@" | sort -n | sed -n '1p;$p' | paste -sd '-'; }

# same_image: whether the last pair's images are the same file byte for byte, else their
# RMSE (0 where only the files' metadata differ).
same_image() {
    if cmp -s "$out/a.exr" "$out/b.exr"; then
        echo "the same bytes"
    else
        "$a" compare "$out/b.exr" "$out/a.exr" | awk '/RMSE/ { print "RMSE", $2; exit }'
    fi
}

echo "| scene | pair | A: CPU (s) | B: CPU (s) |"
echo "|---|---:|---:|---:|"
summary=()
for scene in cornell-box stanford-dragon; do
    [ -f "$peers/$scene.toml" ] || { echo "$peers/$scene.toml missing: run peers.py first" >&2; exit 1; }
    ta=() tb=()
    # One untimed render each first: the first render after a build or a pause pays for
    # cold caches (22% more CPU in one check here), which would fall on A.
    cpu "$a" "$scene" a >/dev/null
    cpu "$b" "$scene" b >/dev/null
    for i in $(seq "$pairs"); do
        ta+=("$(cpu "$a" "$scene" a)")
        tb+=("$(cpu "$b" "$scene" b)")
        echo "| $scene | $i | ${ta[-1]} | ${tb[-1]} |"
    done
    summary+=("$scene: A $(range "${ta[@]}") s, B $(range "${tb[@]}") s; images: $(same_image)")
done
echo
printf '%s\n' "${summary[@]}"
