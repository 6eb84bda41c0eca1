#!/usr/bin/env bash
# The benchmarks that belong on a GPU, in one run, most wanted first: the whole suite's compile
# and time, the edit-to-table loop on both rollout paths, throughput against batch size, a
# 16k-execution chunk of suite-like executions, one stress cell, the split path's layout (workers
# x slots), the edit-to-table loop on the path "auto" takes, and the fused path's slots per
# device (the whole suite and 16k executions at 96 to 16,384 slots).  Each step has its own time
# limit, so one slow step cannot take the others with it; each writes its output to
# OUTDIR/<step>.txt as it goes.
#
#   bash benchmarks/gpu_benchmarks.sh OUTDIR [STEP ...]     # default: every step, in order
#
# $PYTHON (default python3) must import lantern_jax with a CUDA build of jaxlib.
set -u
out=${1:?usage: gpu_benchmarks.sh OUTDIR [STEP ...]}
shift
py=${PYTHON:-python3}
all="machine evaluate_coop iterate rollout_coop stream_16k stress_pe split_layout iterate_auto
rollout_expert compact_slots"
steps=${*:-$all}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
t_all=$(date +%s)

step() {  # step NAME LIMIT_S COMMAND...
  local name=$1 limit=$2
  shift 2
  local t0
  t0=$(date +%s)
  echo "== $name (limit ${limit} s): $*"
  timeout "$limit" "$@" > "$out/$name.txt" 2>&1
  local rc=$?
  echo "   rc=$rc in $(( $(date +%s) - t0 )) s; last lines:"
  tail -n 25 "$out/$name.txt" | sed 's/^/   | /'
}

for s in $steps; do
  case $s in
    machine) step machine 60 bash -c "nvidia-smi -L; nproc; $py -c 'import sys, jax, jaxlib, flax, optax;
print(sys.version); print(jax.__version__, jaxlib.__version__, flax.__version__, optax.__version__);
print(jax.devices()); import lantern_jax; print(\"lantern_jax\", lantern_jax.__version__)'" ;;
    evaluate_coop) step "$s" 120 "$py" benchmarks/bench_evaluate.py --policy coop --repeats 3 ;;
    iterate) step "$s" 300 "$py" benchmarks/bench_iterate.py --edits mlp --batches subset,suite \
      --stores stored,cold --paths split,fused ;;
    rollout_coop) step "$s" 180 "$py" benchmarks/bench_rollout.py --policy coop --ticks 200 \
      --repeats 2 --batches 360 4096 16384 65536 ;;
    stream_16k) step "$s" 150 "$py" benchmarks/bench_stream.py --counts 16384 --chunk 16384 ;;
    stress_pe) step "$s" 200 "$py" benchmarks/bench_stress.py --budget-rollouts 32 \
      --policies coop --families PE --restarts 4 --methods gradient,random --quality-points 0 \
      --out /tmp/gpu_stress ;;
    split_layout) step "$s" 150 "$py" benchmarks/bench_split_workers.py --ticks 200 --rounds 2 \
      --cases 8x48,1x48,2x180,1x360 ;;
    iterate_auto) step "$s" 200 "$py" benchmarks/bench_iterate.py --edits mlp,template \
      --batches subset,suite --stores stored --paths auto,fused ;;
    rollout_expert) step "$s" 150 "$py" benchmarks/bench_rollout.py --policy expert --ticks 200 \
      --repeats 2 --batches 360 4096 16384 65536 ;;
    compact_slots) for n in 96 1024 4096 16384; do
        LANTERN_JAX_COMPACT_SLOTS=$n step "${s}_$n" 150 bash -c "$py benchmarks/bench_evaluate.py \
          --policy coop --repeats 3 && $py benchmarks/bench_stream.py --counts 16384 --chunk 16384"
      done ;;
    *) echo "unknown step $s (one of: $all)"; exit 2 ;;
  esac
done
echo "== all steps in $(( $(date +%s) - t_all )) s"
