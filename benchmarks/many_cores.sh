#!/bin/bash
# The DEM on a many-core machine, in one prepared run (docs/validation.md section 6, "Strong
# scaling on 16 cores"):
#   1. tub47's strong scaling on 1, 2, 4, ... up to every core of the process's affinity, the
#      balls' state the same bits on each (benchmarks/dem_scaling.py);
#   2. `vibroflow dem tub47-quick` on the default thread count (every core), whose
#      bulk_velocity.csv must be the stored seed 1's (sha256 5354927ff6be389c...);
#   3. the long tub (140 000 balls) on every core;
#   4. the blocks' share of tub47's work, block by block on one thread
#      (benchmarks/dem_block_balance.py), to set beside 1.
#
#     bash benchmarks/many_cores.sh OUT_DIR
#
# Both settled beds come from the fill cache (VIBROFLOW_CACHE or ~/.cache/vibroflow): copy
# fills/ there from a machine that has settled them (`vibroflow dem tub47-quick`, `vibroflow
# dem tub47`), or let the first run settle them (tub47's takes minutes on 16 cores).  Python
# needs vibroflow importable (an install, or PYTHONPATH at the checkout).
set -u -o pipefail
OUT=${1:?usage: bash benchmarks/many_cores.sh OUT_DIR}
HERE=$(cd "$(dirname "$0")" && pwd)
PY=${PYTHON:-python3}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
CORES=$($PY -c "import os; print(len(os.sched_getaffinity(0)))")
THREADS=1
t=2
while [ "$t" -le "$CORES" ]; do THREADS="$THREADS,$t"; t=$((t * 2)); done
case ",$THREADS," in *",$CORES,"*) ;; *) THREADS="$THREADS,$CORES" ;; esac
echo "== $CORES cores; tub47 on $THREADS threads"
$PY "$HERE/dem_scaling.py" --sizes tub47 --threads "$THREADS" --repeats 1 --warmup 300 \
    --pass-steps 20 --json "$OUT/tub47.json" 2>&1 | tee "$OUT/tub47.log"
echo "== vibroflow dem tub47-quick on $CORES threads"
rm -rf "$OUT/quick"
( time $PY -m vibroflow.cli dem tub47-quick --out "$OUT/quick" ) > "$OUT/quick.log" 2>&1
tail -4 "$OUT/quick.log"
sha256sum "$OUT/quick/bulk_velocity.csv" | tee -a "$OUT/quick.log"
echo "   (the stored seed 1's: 5354927ff6be389c...)"
echo "== the long tub on $CORES threads"
$PY "$HERE/dem_scaling.py" --sizes long --threads "$CORES" --repeats 1 --warmup 200 \
    --pass-steps 20 --json "$OUT/long.json" 2>&1 | tee "$OUT/long.log"
echo "== the blocks' share of tub47's work, block by block on one thread"
$PY "$HERE/dem_block_balance.py" --size tub47 --json "$OUT/balance.json" 2>&1 \
    | tee "$OUT/balance.log"
