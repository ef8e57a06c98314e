#!/bin/bash
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
S=atrium,clocks,cornell_box,cornell_dielectric,light_behind_glass,thesis_irradiance_cache,thesis_veach_mis,veach_mis
python3 bench/regression.py base=.wt/src/6b42ac5 lp=. --sizes 1k,100k,1M --methods nee --rounds 3 --seconds 1.5 \
  --device gpu --debs .gl --json $OUT/soup.json > $OUT/soup.txt 2>&1
python3 bench/regression.py base=.wt/src/6b42ac5 lp=. --benches frame_cost --npz .wt/npz --scenes $S --methods mis \
  --rounds 2 --seconds 1 --device gpu --debs .gl --json $OUT/frames.json > $OUT/frames.txt 2>&1
site=/tmp/pxsite-lp
declare -A V=([pinned]="" [cycles]="pixel_filter_type=BLACKMAN_HARRIS filter_width=1.5 diffuse_bounces=4 glossy_bounces=4 transmission_bounces=12 sample_clamp_indirect=10"
  [kinds]="diffuse_bounces=4 glossy_bounces=4 transmission_bounces=12" [clamp]="sample_clamp_indirect=10" [filter]="pixel_filter_type=BLACKMAN_HARRIS filter_width=1.5")
for r in 1 2; do for v in pinned cycles kinds clamp filter; do
  PYTHONPATH=$site python3 -m bench.frame_cost --npz .wt/npz --scenes $S --methods mis --seconds 1 --device gpu \
    --set ${V[$v]} --out $OUT/defaults_${v}_$r.json > /dev/null 2>>$OUT/defaults_err.txt
done; done
python3 - <<'PY'
import json, os, statistics as st
out = os.environ["OUT"]
rows = {}
for v in ("pinned", "cycles", "kinds", "clamp", "filter"):
    runs = [json.load(open(f"{out}/defaults_{v}_{r}.json")) for r in (1, 2)]
    rows[v] = {k: st.median(run[k]["ms"] for run in runs) for k in runs[0]}
print("| scene | pinned ms | cycles | kinds | clamp | filter |")
for k in rows["pinned"]:
    p = rows["pinned"][k]
    print(f"| {k} | {p:.1f} | " + " | ".join(f"{rows[v][k] / p:.3f}" for v in ("cycles", "kinds", "clamp", "filter")) + " |")
PY
tail -14 $OUT/soup.txt; tail -12 $OUT/frames.txt
