# Sourced by the benchmark scripts beside the benchmark crate (not run on its own).
#
# render_config SRC DEST [KEY=VALUE...]: writes to DEST a copy of the render config SRC with
# its scene path made absolute, each `[render]` key given replaced by its value (only keys
# SRC already has; quote strings: intersector='"bvh"'), and no outputs (`exr`, `png`), so a
# benchmark renders the committed scene at its own settings without touching the scene's
# files.
render_config() {
    local src=$1 dest=$2
    shift 2
    DIR=$(cd "$(dirname "$src")" && pwd) SETS=$(printf '%s\n' "$@") awk '
        BEGIN {
            n = split(ENVIRON["SETS"], kv, "\n")
            for (i = 1; i <= n; i++) {
                eq = index(kv[i], "=")
                if (eq > 0) set[substr(kv[i], 1, eq - 1)] = substr(kv[i], eq + 1)
            }
        }
        /^\[/ { render = ($0 ~ /^\[render\]/) }
        /^scene = "/ { sub(/^scene = "/, "scene = \"" ENVIRON["DIR"] "/") }
        render && match($0, /^[a-z_]+ = /) {
            key = substr($0, 1, RLENGTH - 3)
            if (key in set) $0 = key " = " set[key]
        }
        /^(exr|png) = / { next }
        { print }' "$src" >"$dest"
}
