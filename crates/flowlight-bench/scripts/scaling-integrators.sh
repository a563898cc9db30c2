#!/usr/bin/env bash
# Thread scaling of every integrator family: the four the performance targets name
# (docs/performance.md, "Target 4": MCPT, ERPT, BDPT, VCM) and the primary-sample-space
# Metropolis plugins (PSSMLT, MMLT) on the Cornell box at 512², each at 1, 2, 4, 8 and 16
# threads (those the machine has), one process per row. Prints the render's wall and CPU time
# (the summary's, which leave out loading and the acceleration-structure build) and the
# parallel efficiency T(1) / (n · T(n)) of wall time, as markdown rows.
#
#   crates/flowlight-bench/scripts/scaling-integrators.sh [THREADS...]   # default 1 2 4 8 16
#
# The sample counts give each integrator 5–15 s at one thread on a Zen 4 core; the rows at 1
# and 2 threads took 85 s there, and 4, 8 and 16 threads add less than the one-thread
# rows again (not yet timed on a 16-core machine). Needs
# `cargo build --release --workspace`. SPP_MCPT, SPP_ERPT, SPP_BDPT, SPP_VCM, SPP_PSSMLT and
# SPP_MMLT override the sample counts; OUT_DIR keeps the configs and logs (default a temp dir).
set -euo pipefail
cd "$(dirname "$0")/../../.."
bin=${FLOWLIGHT_BIN:-target/release/flowlight}
[ -x "$bin" ] || { echo "build first: cargo build --release --workspace" >&2; exit 1; }
. crates/flowlight-bench/scripts/render-config.sh
out=${OUT_DIR:-$(mktemp -d)}
mkdir -p "$out"
threads=${*:-1 2 4 8 16}
cores=$(nproc)
box=scenes/cornell-box

# config NAME BASE SPP [PLUGIN]: the Cornell box's BASE config at 512², SPP samples, with the
# integrator swapped for PLUGIN (its defaults; BASE's other integrator keys dropped).
config() {
    local name=$1 base=$2 spp=$3 plugin=${4:-}
    local cfg=$out/$name.toml
    render_config "$box/$base.toml" "$cfg" "width=512" "height=512" "spp=$spp"
    if [ -n "$plugin" ]; then
        awk -v p="$plugin" '
            /^\[/ { section = $0 }
            section == "[integrator]" && /^[a-z_]+ = / {
                if ($0 ~ /^plugin = /) print "plugin = \"" p "\"" 
                next
            }
            { print }' "$cfg" >"$cfg.tmp" && mv "$cfg.tmp" "$cfg"
    fi
    echo "$cfg"
}

field() { grep -m1 "$2" "$1" | awk "$3"; }

rows=(
    "mcpt|$(config scale-mcpt cornell-box "${SPP_MCPT:-16}")"
    "erpt|$(config scale-erpt erpt "${SPP_ERPT:-2}")"
    "bdpt|$(config scale-bdpt cornell-box "${SPP_BDPT:-8}" bdpt)"
    "vcm|$(config scale-vcm cornell-box "${SPP_VCM:-4}" vcm)"
    "pssmlt|$(config scale-pssmlt cornell-box "${SPP_PSSMLT:-16}" pssmlt)"
    "mmlt|$(config scale-mmlt cornell-box "${SPP_MMLT:-64}" mmlt)"
)

echo "| integrator | threads | wall (s) | CPU (s) | parallel efficiency |"
echo "|---|---:|---:|---:|---:|"
for row in "${rows[@]}"; do
    name=${row%%|*}
    cfg=${row#*|}
    t1= n1=
    for n in $threads; do
        [ "$n" -le "$cores" ] || continue
        log=$out/$name-$n.log
        "$bin" render "$cfg" --threads "$n" --quiet --out "$out/$name.exr" >"$log" 2>&1 ||
            { echo "$name at $n threads failed: see $log" >&2; exit 1; }
        wall=$(field "$log" "wall time" '{print $3}')
        cpu=$(field "$log" "cpu time" '{print $3}')
        t1=${t1:-$wall}
        n1=${n1:-$n}
        eff=$(awk -v a="$t1" -v b="$wall" -v n="$n" -v m="$n1" 'BEGIN { printf "%.2f", a * m / (n * b) }')
        echo "| $name | $n | $wall | $cpu | $eff |"
    done
done
