# Table "relMSE × spp per termination distribution" of docs/results.md from a bench results.csv:
#   python3 docs/results/termination_table.py docs/results/termination.csv
# relMSE × spp uses (relMSE − reference floor) per render; efficiency = 1 / (that × wall),
# paired with mcpt-entangled-bxdf at the same budget and seed; medians over budgets × seeds.
import csv, sys, statistics as st, math, collections
rows = list(csv.DictReader(open(sys.argv[1])))
base = "mcpt-entangled-bxdf"
by = collections.defaultdict(list)
for r in rows:
    by[(r["scene"], r["method"])].append(r)
def corr(r):
    return max(float(r["relmse"]) - float(r["reference_floor"] or 0), 1e-30)
scenes = []
for r in rows:
    if r["scene"] not in scenes: scenes.append(r["scene"])
methods = []
for r in rows:
    if r["method"] not in methods: methods.append(r["method"])
out = []
eff_all = collections.defaultdict(list)
vps_tab = {}
for sc in scenes:
    basemap = {(r["budget_s"], r["seed"]): r for r in by[(sc, base)]}
    for m in methods:
        rs = by[(sc, m)]
        if not rs: continue
        vps = [corr(r) * float(r["spp"]) for r in rs]
        raw = [float(r["relmse"]) * float(r["spp"]) for r in rs]
        effs = []
        for r in rs:
            b = basemap[(r["budget_s"], r["seed"])]
            e = (corr(b) * float(b["wall_s"])) / (corr(r) * float(r["wall_s"]))
            effs.append(e)
        eff_all[m].append(st.median(effs))
        spp = [float(r["spp"]) / float(r["wall_s"]) for r in rs]
        lum = [float(r["luminance_ratio"]) for r in rs]
        vps_tab[(sc, m)] = st.median(vps)
        out.append((sc, m, st.median(vps), min(vps), max(vps), st.median(raw), st.median(spp), st.median(effs), min(effs), max(effs), st.median(lum), len(rs)))
print("| scene | method | relMSE × spp (median) | range | samples/s per pixel | efficiency vs entangled-bxdf (median) | range | lum. ratio |")
print("|---|---|---:|---:|---:|---:|---:|---:|")
for o in out:
    print(f"| {o[0]} | {o[1]} | {o[2]:.3g} | {o[3]:.3g}–{o[4]:.3g} | {o[6]:.1f} | {o[7]:.2f} | {o[8]:.2f}–{o[9]:.2f} | {o[10]:.3f} |")
print()
print("| method | geometric mean of efficiency vs entangled-bxdf over scenes |")
print("|---|---:|")
for m in methods:
    v = eff_all[m]
    print(f"| {m} | {math.exp(sum(map(math.log, v))/len(v)):.2f} |")
