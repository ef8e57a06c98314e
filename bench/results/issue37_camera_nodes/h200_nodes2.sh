#!/bin/bash
# H200: the node programs' cost per frame with the interpreter's heavier operations grouped behind
# scene feature bits (new), against the same payload as h200_issue37.sh's (all in this build).
for f in .gl/*.deb; do dpkg -x $f / ; done; ldconfig
PX_TAG=new bash scripts/device_build.sh > $OUT/build.txt 2>&1 || { tail -30 $OUT/build.txt; exit 1; }
N=atrium,cornell_box,light_behind_glass,veach_mis
for r in 1 2 3; do
  for k in npz npz_nodes npz_noise; do
    PYTHONPATH=/tmp/pxsite-new python3 -m bench.frame_cost --npz .wt/$k --scenes $N --methods pt,mis --seconds 0.6 \
      --device gpu --out $OUT/n_${k}_$r.json >> $OUT/nodes2.txt 2>&1
  done
done
S=atrium,clocks,cornell_box,cornell_dielectric,light_behind_glass,thesis_irradiance_cache,thesis_veach_mis,veach_mis
python3 bench/regression.py 3b07e7e=.wt/src/3b07e7e new=. --benches frame_cost --npz .wt/npz --scenes $S \
  --methods pt,nee,mis --rounds 3 --seconds 0.6 --device gpu --debs .gl --json $OUT/frames2.json > $OUT/frames2.txt 2>&1
python3 - <<'PY'
import json, os, statistics
out = os.environ["OUT"]
for k in ("npz", "npz_nodes", "npz_noise"):
    rows = {}
    for r in (1, 2, 3):
        for key, v in json.load(open(f"{out}/n_{k}_{r}.json")).items():
            rows.setdefault(key, []).append(v["ms"])
    print(k, {key: round(statistics.median(v), 2) for key, v in rows.items()})
PY
grep "^|" $OUT/frames2.txt
