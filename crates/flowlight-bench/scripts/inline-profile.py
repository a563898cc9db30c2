#!/usr/bin/env python3
"""Instructions per inlined function of one shared object, from callgrind.

`perf` samples land on the instruction that waits, not on the one that costs, and in an
inlined walker that can put a function's cost on its neighbour (docs/performance.md,
"Profiling"). Callgrind counts instructions exactly; this script runs a render under it,
maps every executed instruction of the object to its chain of inlined functions
(`addr2line -i`), and prints each function's inclusive and self share of the object's
instructions, and its instructions per closest-hit ray of the render (the summary's count).

    crates/flowlight-bench/scripts/inline-profile.py [--object libflowlight_mcpt.so] [--top 60] \\
        -- target/release/flowlight render scenes/cornell-box/cornell-box.toml --spp 1 --threads 1

Needs `valgrind` and `addr2line` (Debian: valgrind, binutils) and a release build (its line
tables: `[profile.release] debug = 1`). The Cornell box at 1 spp takes about 25 s at 256x256 and
85 s at its config's 512x512 on a Zen 4 core.
"""

import argparse
import collections
import os
import re
import subprocess
import sys
import tempfile


def run_callgrind(command, out):
    """Runs `command` under callgrind, per-instruction counts into `out`; returns its stdout."""
    cg = ["valgrind", "--tool=callgrind", "--dump-instr=yes", "--compress-pos=no",
          "--compress-strings=no", f"--callgrind-out-file={out}"]
    done = subprocess.run(cg + command, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"inline-profile: the command failed under valgrind:\n{done.stderr[-2000:]}")
    return done.stdout + done.stderr


def instruction_counts(path):
    """{object path: {address: instructions}} from a callgrind file written uncompressed.
    A cost line after `calls=` is the call's inclusive cost and is skipped."""
    counts = collections.defaultdict(collections.Counter)
    obj, after_call = None, False
    with open(path) as f:
        for line in f:
            if line.startswith("ob="):
                obj = line[3:].strip()
            elif line.startswith("calls="):
                after_call = True
            elif line.startswith("0x"):
                if after_call:
                    after_call = False
                    continue
                fields = line.split()
                counts[obj][int(fields[0], 16)] += int(fields[-1])
            else:
                after_call = False
    return counts


def inline_chains(library, addresses):
    """{address: [function, ...]} innermost first, from `addr2line -i -f -C`."""
    chains = {}
    batch = 4000
    for i in range(0, len(addresses), batch):
        part = [hex(a) for a in addresses[i:i + batch]]
        out = subprocess.run(["addr2line", "-a", "-i", "-f", "-C", "-e", library] + part,
                             capture_output=True, text=True, check=True).stdout.splitlines()
        current, lines = None, []
        for line in out + ["0x0"]:
            if line.startswith("0x"):
                if current is not None:
                    chains[current] = lines[0::2]
                current, lines = int(line, 16), []
            elif line.strip():
                lines.append(line)
    return chains


def short(name):
    """A function's path without generic arguments, to keep the table readable."""
    for _ in range(6):
        name = re.sub(r"<[^<>]*>", "", name)
    return name


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--object", default="libflowlight_mcpt.so",
                    help="the shared object whose instructions to attribute (file name)")
    ap.add_argument("--top", type=int, default=60, help="rows to print")
    ap.add_argument("command", nargs=argparse.REMAINDER, help="-- then the render command")
    a = ap.parse_args()
    command = a.command[1:] if a.command[:1] == ["--"] else a.command
    if not command:
        ap.error("give the render command after --")
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "callgrind.out")
        text = run_callgrind(command, out)
        counts = instruction_counts(out)
    objects = {o: c for o, c in counts.items() if o and os.path.basename(o) == a.object}
    if not objects:
        sys.exit(f"inline-profile: no instructions ran in {a.object}")
    library, costs = next(iter(objects.items()))
    rays = re.search(r"rays\s+\d+ \((\d+) closest", text)
    closest = int(rays.group(1)) if rays else None
    total_all = sum(sum(c.values()) for c in counts.values())
    total = sum(costs.values())
    chains = inline_chains(library, sorted(costs))
    inclusive, own = collections.Counter(), collections.Counter()
    for address, n in costs.items():
        names = [short(f) for f in chains.get(address, ["??"])]
        for name in set(names):
            inclusive[name] += n
        own[names[0]] += n
    print(f"{a.object}: {total:,} instructions, {100 * total / total_all:.1f}% of the process's"
          + (f"; {total / closest:,.0f} per closest-hit ray ({closest:,} rays)" if closest else ""))
    per = "per ray" if closest else ""
    print(f"\n| inclusive % | self % | {per} | function |\n|---:|---:|---:|---|")
    for name, n in inclusive.most_common(a.top):
        ray = f"{n / closest:,.0f}" if closest else ""
        print(f"| {100 * n / total:.2f} | {100 * own[name] / total:.2f} | {ray} | `{name}` |")


if __name__ == "__main__":
    main()
