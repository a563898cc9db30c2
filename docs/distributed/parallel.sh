#!/usr/bin/env bash
# Distributed render with GNU parallel (over ssh, or local cores), falling back to xargs -P
# on this machine when GNU parallel is not installed. See docs/distributed.md.
#
#   parallel.sh CONFIG N OUT.exr [SSHLOGINS]
#
# Renders CONFIG as N parts (`flowlight render --part K/N`, K = 0..N-1) into $PARTS_DIR
# (default: OUT's folder/parts), then `flowlight merge`s them into OUT.exr. SSHLOGINS
# (GNU parallel's --sshlogin list, e.g. "8/node1,8/node2") runs the parts on other machines,
# which must see CONFIG, its scene and PARTS_DIR at the same paths (a shared file system).
# Environment: FLOWLIGHT (the binary, default `flowlight`), FLOWLIGHT_ARGS (extra render
# arguments, e.g. "--threads 4"), JOBS (parts at once, default: the cores), NO_GNU_PARALLEL=1
# (force the xargs path).
set -euo pipefail
if [ $# -lt 3 ]; then
    echo "usage: $0 CONFIG N OUT.exr [SSHLOGINS]" >&2
    exit 2
fi
config=$1 n=$2 out=$3 logins=${4:-}
flowlight=${FLOWLIGHT:-flowlight}
jobs=${JOBS:-$(nproc)}
parts_dir=${PARTS_DIR:-$(dirname "$out")/parts}
read -r -a extra <<<"${FLOWLIGHT_ARGS:-}"
mkdir -p "$parts_dir"

if command -v parallel >/dev/null 2>&1 && [ -z "${NO_GNU_PARALLEL:-}" ]; then
    echo "parallel.sh: $n parts with GNU parallel" >&2
    seq 0 $((n - 1)) | parallel --halt now,fail=1 -j "$jobs" ${logins:+--sshlogin "$logins"} \
        "$flowlight" render "$config" --part "{}/$n" --out "$parts_dir/part-{}.exr" -q "${extra[@]}"
else
    if [ -n "$logins" ]; then
        echo "parallel.sh: SSHLOGINS needs GNU parallel (apt-get install parallel)" >&2
        exit 2
    fi
    echo "parallel.sh: $n parts with xargs -P $jobs (GNU parallel not found)" >&2
    seq 0 $((n - 1)) | xargs -P "$jobs" -I{} \
        "$flowlight" render "$config" --part "{}/$n" --out "$parts_dir/part-{}.exr" -q "${extra[@]}"
fi

parts=()
for k in $(seq 0 $((n - 1))); do parts+=("$parts_dir/part-$k.exr"); done
"$flowlight" merge "$out" "${parts[@]}"
