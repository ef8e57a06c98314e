#!/bin/bash
# H200, issue 37: frames of materials without graphs, new against 3b07e7e (the commit before
# issue 37); then what node programs cost per frame in new (npz_nodes, npz_noise against npz).
for f in .gl/*.deb; do dpkg -x $f / ; done; ldconfig
S=atrium,clocks,cornell_box,cornell_dielectric,light_behind_glass,thesis_irradiance_cache,thesis_veach_mis,veach_mis
date > $OUT/log.txt
python3 bench/regression.py 3b07e7e=.wt/src/3b07e7e new=. --benches frame_cost --npz .wt/npz --scenes $S \
  --methods pt,nee,mis --rounds 2 --seconds 0.6 --device gpu --debs .gl --json $OUT/frames.json > $OUT/frames.txt 2>&1
date >> $OUT/log.txt
N=atrium,cornell_box,light_behind_glass,veach_mis
for r in 1 2 3; do
  for k in npz npz_nodes npz_noise; do
    PYTHONPATH=/tmp/pxsite-new python3 -m bench.frame_cost --npz .wt/$k --scenes $N --methods pt,mis --seconds 0.6 \
      --device gpu --out $OUT/nodes_${k}_$r.json >> $OUT/nodes.txt 2>&1
  done
done
date >> $OUT/log.txt
python3 bench/regression.py 3b07e7e=.wt/src/3b07e7e new=. --sizes 1k,100k,1M --methods nee --rounds 2 --seconds 1.0 \
  --device gpu --debs .gl --json $OUT/soup.json > $OUT/soup.txt 2>&1
date >> $OUT/log.txt
grep "^|" $OUT/frames.txt $OUT/soup.txt | head -80
