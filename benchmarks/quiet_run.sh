#!/bin/bash
# The quiet-machine script of BENCHMARKS.md: every speed target of issues 15, 16 and 20 once.
# Run from the repository root: O=DIR [SRC=tree/src] [FULL=1] [DATA=DIR] bash benchmarks/quiet_run.sh
# (FULL=1 adds the whole transport set, peers included, and `python -m benchmarks batch --repeat 2`). Logs with load and steal
# ticks go to DIR/log; the bags and the demo log are written once into DATA.
set -u
O=${O:?set O}; mkdir -p "$O"
PY=${PY:-.venv/bin/python}
export PYTHONPATH=${SRC:-src}:.  # the tree measured, then benchmarks/ (python -m benchmarks)
steal() { awk '/^cpu /{print "steal ticks", $9}' /proc/stat; }
log() { echo "== $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg) $(steal) :: $*" | tee -a "$O/log"; }
D=${DATA:-/tmp/redrive-quiet}; mkdir -p $D
[ -f $D/urban.mcap ] || $PY -m redrive synth urban --duration 20 -o $D/urban.mcap > /dev/null
# the bags: written once by `python -m benchmarks read-synth` (one pass each, output discarded)
for n in 200 2000; do
  [ -f $D/p$n.bag ] || $PY -m benchmarks read-synth 0.1 --points $n --repeat 1 $D/p$n.bag > /dev/null 2>&1
  log "read $n"; $PY -m redrive bench read $D/p$n.bag --repeat 5 --tune-malloc --json > $O/read$n.json 2> $O/read$n.err
done
[ -f $D/xyzi.bag ] || $PY -m benchmarks read-synth 0.32 --layout xyzi --repeat 1 $D/xyzi.bag > /dev/null 2>&1
log "read xyzi"; $PY -m redrive bench read $D/xyzi.bag --repeat 5 --tune-malloc --json > $O/readxyzi.json 2> $O/readxyzi.err
log transport; $PY -m benchmarks transport --sizes 64K,1M,4M --sides redrive-inplace,iceoryx2 --repeat 3 --no-paced --no-memcpy > $O/transport.txt 2>&1
log engine; $PY -m redrive bench engine --repeat 5 > $O/engine.txt 2>&1
for m in sequential sequential pipelined pipelined; do
  log "run $m"; rm -rf $O/run; $PY -m redrive run $D/urban.mcap --out $O/run --mode $m > $O/run-$m.txt 2>&1; grep -i "real time\|×" $O/run-$m.txt | tail -2 >> $O/log
done
# issue 36: pipelined against sequential in fresh processes (wall ratio, cores in use, the two-core
# bound by CPU time, tables compared), and the first run on a fresh machine: an empty numba cache,
# the install step (`python -m redrive.closedloop.kernels`, what `make venv` runs), then the run
log overlap; $PY -m benchmarks.pipelined_overlap $D/urban.mcap --rounds 3 > $O/overlap.txt 2>&1; tail -2 $O/overlap.txt >> $O/log
log "overlap, switch interval 0.5 ms"; $PY -m benchmarks.pipelined_overlap $D/urban.mcap --rounds 3 --switch-interval-ms 0.5 > $O/overlap-si.txt 2>&1; tail -2 $O/overlap-si.txt >> $O/log
rm -rf $D/numba-fresh; log "install step (fresh numba cache)"
NUMBA_CACHE_DIR=$D/numba-fresh $PY -m redrive.closedloop.kernels > $O/kernels.txt 2>&1; cat $O/kernels.txt >> $O/log
log "first run"; rm -rf $O/run; NUMBA_CACHE_DIR=$D/numba-fresh $PY -m redrive run $D/urban.mcap --out $O/run > $O/run-first.txt 2>&1; grep -i "real time" $O/run-first.txt | tail -1 >> $O/log
log closed-loop; $PY -m redrive bench closed-loop --repeat 3 > $O/closed.txt 2>&1
log sensor; $PY -m redrive bench closed-loop --level sensor --repeat 1 > $O/sensor.txt 2>&1
log "done main set"
if [ "${FULL:-0}" = 1 ]; then
  log "transport full"; $PY -m benchmarks transport > $O/transport-full.txt 2>&1
  log batch; $PY -m benchmarks batch --repeat 2 > $O/batch.txt 2>&1
  log "done full"
fi
