#!/usr/bin/env bash
# The accumulation benchmarks of docs/performance.md ("Accumulation, threads and seams"), from the
# release build (cargo build --release --workspace):
#
#   crates/flowlight-bench/accumulation/run.sh memory  [THREADS...]   # default 1 2 8 16
#   crates/flowlight-bench/accumulation/run.sh scaling [THREADS...]   # default 1 2 4 8 16, up to the cores
#   crates/flowlight-bench/accumulation/run.sh seams
#
# memory:  peak resident memory of ERPT on the Cornell box at 1920×1080 with 8 lighting
#          layers (path_depth 7: layers 0..7, 9 framebuffers with the main image), 1 spp,
#          for each style and precision and thread count; the ratio is to one f32 framebuffer
#          set (9 × 1920 × 1080 × 12 B = 224 MB), by the end of the render and after the EXR
#          and PNG are written (the process's peak). Threads beyond 4 per core are allowed here
#          (FLOWLIGHT_OVERSUBSCRIBE=1): memory does not need the cores.
# scaling: wall and CPU time of MCPT (Blasting) and ERPT (Caching) on the Cornell box at
#          512², parallel efficiency T(1) / (n · T(n)), and the framebuffer locks found held
#          per flush (the contention a 16-thread run would grow).
# seams:   ERPT on the Cornell box at 256², 24-pixel tiles, 16 spp, with Blasting at flange 0,
#          the integrator's (2K = 16) and the whole screen, Caching, and the image-wide
#          quantum; `flowlight seams --tile 24` of each against the same of a 256 spp MCPT
#          render (no seams possible: the baseline for scene edges on the tile grid).
#
# Results go to stdout as markdown rows, and the renders to $OUT_DIR (default a temp dir).
set -euo pipefail
cd "$(dirname "$0")/../../.."
bin=target/release/flowlight
[ -x "$bin" ] || { echo "build first: cargo build --release --workspace" >&2; exit 1; }
out=${OUT_DIR:-$(mktemp -d)}
mkdir -p "$out"
mode=${1:-memory}
shift || true

. crates/flowlight-bench/scripts/render-config.sh

# A copy of scenes/cornell-box/BASE.toml (default erpt) with the scene path made absolute,
# `[render]` size and spp (and tile size, with TILE set) replaced and no outputs:
# config NAME WIDTH HEIGHT SPP [BASE]. Integrator parameters are given to `render` as
# --set KEY=VALUE.
config() {
    local name=$1 w=$2 h=$3 spp=$4 base=${5:-erpt}
    render_config "scenes/cornell-box/$base.toml" "$out/$name.toml" \
        "width=$w" "height=$h" "spp=$spp" ${TILE:+"tile_size=$TILE"}
    echo "$out/$name.toml"
}

field() { # field LOG PATTERN AWK-PROGRAM
    grep -m1 "$2" "$1" | awk "$3"
}

case $mode in
memory)
    threads=${*:-1 2 8 16}
    cfg=$(config mem 1920 1080 1)
    params=(--set path_depth=7 --set layers=true --set mutations_per_sample=1 --set chain_length=4)
    set_bytes=$((9 * 1920 * 1080 * 12))
    # What the process holds whatever the image: binaries, Embree, plugins, scene, BVH. The
    # same render at 16×16 measures it; "net" columns subtract it.
    tiny=$(config mem-tiny 16 16 1)
    "$bin" render "$tiny" --threads 1 --quiet "${params[@]}" --out "$out/mem-tiny.exr" >"$out/mem-tiny.log" 2>&1
    base=$(field "$out/mem-tiny.log" "peak memory" '{print $3}')
    echo "base: $base MiB resident for a 16×16 render of the same scene and settings"
    echo
    echo "| style | precision | threads | peak RSS by the end of the render (MiB) | net / f32 set | peak RSS after writing (MiB) | net / f32 set | frame (MiB) | private (MiB) | allocated / f32 set | flushes | locks (held) | wall (s) |"
    echo "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    for precision in exact f32; do
        for style in blasting buffering caching; do
            for n in $threads; do
                log=$out/mem-$style-$precision-$n.log
                FLOWLIGHT_OVERSUBSCRIBE=1 "$bin" render "$cfg" --threads "$n" --quiet "${params[@]}" \
                    --set render.accumulation=$style --set render.precision=$precision \
                    --out "$out/mem.exr" >"$log" 2>&1 || { echo "| $style | $precision | $n | failed: $(tail -1 "$log") |"; continue; }
                peak=$(field "$log" "peak memory" '{print $3}')
                after=$(grep -m1 "peak memory" "$log" | sed -E 's/.*, ([0-9.]+) MiB after writing.*/\1/')
                wall=$(field "$log" "wall time" '{print $3}')
                acc=$(grep -m1 "accumulation " "$log")
                frame=$(echo "$acc" | sed -E 's/.*frame ([0-9.]+) MiB.*/\1/')
                private=$(echo "$acc" | sed -E 's/.*private buffers ([0-9.]+) MiB.*/\1/')
                flushes=$(echo "$acc" | sed -E 's/.*; ([0-9]+) flushes.*/\1/')
                locks=$(echo "$acc" | sed -E 's/.* ([0-9]+) framebuffer locks \(([0-9]+) found held\).*/\1 (\2)/')
                ratio=$(awk -v p="$peak" -v b="$base" -v s="$set_bytes" 'BEGIN { printf "%.2f", (p - b) * 1048576 / s }')
                alloc=$(awk -v f="$frame" -v p="$private" -v s="$set_bytes" 'BEGIN { printf "%.2f", (f + p) * 1048576 / s }')
                aratio=$(awk -v p="$after" -v b="$base" -v s="$set_bytes" 'BEGIN { printf "%.2f", (p - b) * 1048576 / s }')
                echo "| $style | $precision | $n | $peak | $ratio | $after | $aratio | $frame | $private | $alloc | $flushes | $locks | $wall |"
            done
        done
    done
    ;;
scaling)
    cores=$(nproc)
    threads=${*:-1 2 4 8 16}
    mcpt=$(config scale-mcpt 512 512 32 cornell-box)
    erpt=$(config scale-erpt 512 512 2)
    echo "| integrator (style) | threads | wall (s) | CPU (s) | parallel efficiency | flushes | locks (held) | held per flush |"
    echo "|---|---:|---:|---:|---:|---:|---:|---:|"
    for which in mcpt erpt; do
        cfg=$mcpt
        [ $which = erpt ] && cfg=$erpt
        t1=
        for n in $threads; do
            [ "$n" -le "$cores" ] || continue
            log=$out/scale-$which-$n.log
            "$bin" render "$cfg" --threads "$n" --quiet --out "$out/scale.exr" >"$log" 2>&1
            wall=$(field "$log" "wall time" '{print $3}')
            cpu=$(field "$log" "cpu time" '{print $3}')
            acc=$(grep -m1 "accumulation " "$log")
            style=$(echo "$acc" | awk '{print $2}' | tr -d ,)
            flushes=$(echo "$acc" | sed -E 's/.*; ([0-9]+) flushes.*/\1/')
            locks=$(echo "$acc" | sed -E 's/.* ([0-9]+) framebuffer locks.*/\1/')
            held=$(echo "$acc" | sed -E 's/.*\(([0-9]+) found held\).*/\1/')
            t1=${t1:-$wall}
            eff=$(awk -v a="$t1" -v b="$wall" -v n="$n" 'BEGIN { printf "%.2f", a / (n * b) }')
            per=$(awk -v h="$held" -v f="$flushes" 'BEGIN { printf "%.3f", (f > 0) ? h / f : 0 }')
            echo "| $which ($style) | $n | $wall | $cpu | $eff | $flushes | $locks ($held) | $per |"
        done
    done
    ;;
seams)
    # 24-pixel tiles: the Cornell box's wall edges fall on a 32-pixel grid.
    export TILE=24
    # Scene edges that fall on the tile grid raise the ratio too: path tracing (tile-local,
    # no seams possible) of the same image and tiles is the baseline a render is judged by.
    cfg=$(config seams-mcpt 256 256 256 cornell-box)
    "$bin" render "$cfg" --threads 2 --quiet --out "$out/seams-mcpt.exr" >"$out/seams-mcpt.log" 2>&1
    ref=$("$bin" seams "$out/seams-mcpt.exr" --tile $TILE | awk '{print $3}')
    echo "| run | seam ratio | border mean dY | inside mean dY | ratio / MCPT's ($ref) |"
    echo "|---|---:|---:|---:|---:|"
    for run in "blasting-flange0|render.accumulation=blasting|render.flange=0|quantum=tile" \
        "blasting-flange16|render.accumulation=blasting|render.flange=16|quantum=tile" \
        "blasting-screen|render.accumulation=blasting|render.flange=screen|quantum=tile" \
        "caching|render.accumulation=caching|render.accumulation=caching|quantum=tile" \
        "caching-image-quantum|render.accumulation=caching|render.accumulation=caching|quantum=image"; do
        IFS='|' read -r name a b q <<<"$run"
        cfg=$(config "seams-$name" 256 256 16)
        sed -i "s|^\[output\]|[output]\npng = \"seams-$name.png\"|" "$cfg"
        "$bin" render "$cfg" --threads 2 --quiet --set "$a" --set "$b" --set "$q" \
            --out "$out/seams-$name.exr" >"$out/seams-$name.log" 2>&1
        line=$("$bin" seams "$out/seams-$name.exr" --tile $TILE)
        ratio=$(echo "$line" | awk '{print $3}')
        border=$(echo "$line" | sed -E 's/.*border mean \|dY\| ([0-9.eE+-]+).*/\1/')
        inside=$(echo "$line" | sed -E 's/.*inside ([0-9.eE+-]+).*/\1/')
        rel=$(awk -v a="$ratio" -v b="$ref" 'BEGIN { printf "%.3f", a / b }')
        echo "| $name | $ratio | $border | $inside | $rel |"
    done
    ;;
*)
    echo "usage: $0 memory|scaling|seams [THREADS...]" >&2
    exit 2
    ;;
esac
echo "(renders and logs in $out)" >&2
