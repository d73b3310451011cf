#!/usr/bin/env bash
# Train CCHP, RANP, Dummy LSTM and the fixed p_TF = 0.9 ablation for several
# seeds, then evaluate them on the six settings with the noise sweep, the
# spectrum and the attention figure.
#
#   DATA=out/population15.h5 OUT=out/eval STEPS=1000 SEEDS="0 1 2" JOBS=2 EXTRA="--tf-hold-steps 300" \
#     benchmarks/run_evaluation.sh
#
# The paper's protocol is STEPS=8300 (738 epochs of 360 clips at batch 32)
# and SEEDS="0 1 2 3 4". Each training process uses one thread; JOBS of them
# run at once. Extra ablations: ABLATIONS="fixed0.5 fixed0.1 pd0.1 pd0.75 pd1".
set -euo pipefail
PY=${PY:-/work/venv/bin/python}
DATA=${DATA:?set DATA to a dataset file}
OUT=${OUT:-out/eval}
STEPS=${STEPS:-1500}
SEEDS=${SEEDS:-"0 1 2"}
JOBS=${JOBS:-2}
ABLATIONS=${ABLATIONS:-"fixed0.9"}
EXTRA=${EXTRA:-}  # further train arguments for every run, e.g. "--tf-hold-steps 300"
mkdir -p "$OUT"

jobs_file="$OUT/jobs.txt"
: > "$jobs_file"
for seed in $SEEDS; do
  for model in cchp ranp lstm; do
    echo "$model-s$seed --model $model --seed $seed" >> "$jobs_file"
  done
  for ab in $ABLATIONS; do
    case $ab in
      fixed*) echo "cchp_$ab-s$seed --model cchp --seed $seed --tf-schedule fixed:${ab#fixed}" >> "$jobs_file" ;;
      pd*) p=${ab#pd}; echo "cchp_$ab-s$seed --model cchp --seed $seed --p-d $p --p-u $p" >> "$jobs_file" ;;
    esac
  done
done

run_one() {
  name=$1; shift
  if [ -f "$OUT/$name/checkpoint.pt" ] && [ -f "$OUT/$name/history.json" ]; then return 0; fi
  OMP_NUM_THREADS=1 "$PY" -m rtcohand_drake.train --data "$DATA" --out "$OUT/$name" --steps "$STEPS" \
    --threads 1 --quiet $EXTRA "$@" > "$OUT/$name.log" 2>&1
  echo "done $name"
}
export -f run_one
export PY DATA OUT STEPS EXTRA
xargs -P "$JOBS" -L 1 bash -c 'run_one "$@"' _ < "$jobs_file"

"$PY" -m rtcohand_drake.evaluate --data "$DATA" --checkpoint "$OUT"/*/checkpoint.pt --out "$OUT/results" \
  --noise-sweep --spectrum --attention --threads "$JOBS"
