#!/usr/bin/env bash
# The bigram reader's three training chains, seeds 0, 1 and 2, all three at once:
#
#   bash examples/train_bigram_ensemble.sh [OUT]      # OUT: runs/train/bigram_ensemble
#
# CLOSED_CONFIG names another closed-loop stage's config (the first two stages are the same),
# e.g. the counterfactual positions drawn where true warnings state theirs:
#
#   CLOSED_CONFIG=configs/train_closed_loop_rig_bigram_stated.toml \
#       bash examples/train_bigram_ensemble.sh runs/train/bigram_stated
#
# BASE_CONFIG and DISTANCE_CONFIG name the first two stages' configs (default the bigram rig's),
# e.g. the model whose actors are pooled by their mean and largest values, all three stages:
#
#   BASE_CONFIG=configs/train_base_rig_bigram_max.toml \
#   DISTANCE_CONFIG=configs/train_distance_onset_only_rig_bigram_max.toml \
#   CLOSED_CONFIG=configs/train_closed_loop_rig_bigram_stated_half_short_max.toml \
#       bash examples/train_bigram_ensemble.sh runs/train/bigram_stated_half_short_max
#
# SEEDS names the seeds (default "0 1 2"), e.g. a second, independent set of three chains:
#
#   SEEDS="3 4 5" bash examples/train_bigram_ensemble.sh runs/train/bigram_ensemble_s345
#
# Each seed's chain is the configs' own (docs/learned.md, "Reading which word follows which"):
# base -> distance (onset only) -> the closed-loop rounds CLOSED_CONFIG sets (nine by default),
# each stage from the same seed's previous checkpoint, written to
# OUT/bigram_s<seed>/{base,distance,closed}, its output appended to OUT/bigram_s<seed>.log.
# Then evaluate the three as one ensemble (the mean of their plans):
#
#   .venv/bin/lantern-jax evaluate --policy examples/bigram_ensemble.py:bigram_ensemble
#
# On a 2-core CPU the three chains take about 41 min and 14 GB together (docs/learned.md,
# "The bigram reader's vocabulary"); one chain alone about 15 min, three in a row about 46.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-runs/train/bigram_ensemble}
BASE_CONFIG=${BASE_CONFIG:-configs/train_base_rig_bigram.toml}
DISTANCE_CONFIG=${DISTANCE_CONFIG:-configs/train_distance_onset_only_rig_bigram.toml}
CLOSED_CONFIG=${CLOSED_CONFIG:-configs/train_closed_loop_rig_bigram.toml}
read -r -a SEED_LIST <<< "${SEEDS:-0 1 2}"

config_name() {  # each stage exports its model under the name its config gives
  local name
  name=$(sed -n 's/^name *= *"\(.*\)"/\1/p' "$1")
  [ -n "$name" ] || { echo "train_bigram_ensemble: no name in $1" >&2; return 2; }
  echo "$name"
}
BASE_NAME=$(config_name "$BASE_CONFIG")
DISTANCE_NAME=$(config_name "$DISTANCE_CONFIG")
CLOSED_NAME=$(config_name "$CLOSED_CONFIG")
mkdir -p "$OUT"

chain() {  # one seed's three stages, each from the previous one's exported model
  local seed=$1 d="$OUT/bigram_s$1"
  .venv/bin/lantern-jax train --config "$BASE_CONFIG" --seed "$seed" \
      --out "$d/base" --quiet &&
  .venv/bin/lantern-jax train --config "$DISTANCE_CONFIG" \
      --seed "$seed" --out "$d/distance" \
      --init-from "$d/base/$BASE_NAME.msgpack" --quiet &&
  .venv/bin/lantern-jax train --config "$CLOSED_CONFIG" \
      --seed "$seed" --out "$d/closed" \
      --init-from "$d/distance/$DISTANCE_NAME.msgpack" --quiet
}

pids=()
for seed in "${SEED_LIST[@]}"; do
  chain "$seed" >> "$OUT/bigram_s$seed.log" 2>&1 &  # appended: a rerun keeps the earlier log
  pids+=("$!")
done
failed=0
for i in "${!SEED_LIST[@]}"; do
  seed=${SEED_LIST[$i]}
  if ! wait "${pids[$i]}"; then
    echo "train_bigram_ensemble: seed $seed failed; see $OUT/bigram_s$seed.log" >&2
    failed=1
  fi
done
[ "$failed" = 0 ] || exit 1
for seed in "${SEED_LIST[@]}"; do
  echo "$OUT/bigram_s$seed/closed/$CLOSED_NAME.msgpack"
done
