#!/usr/bin/env bash
# The GPU check: MuJoCo Warp on a lent GPU machine, in one run of at most 8 minutes.
#
# That machine has Python 3.12 with a CUDA torch and reaches no registry; legoh's other
# dependencies travel as wheels made here by experiments/gpu_wheels.sh, cut into parts that
# each fit one call's 64 MiB carry. docs/scaling.md ("GPU check") gives the calls:
#
#   bash experiments/gpu_check.sh receive     # once per part but the last, carry [".whl/partK"]
#   bash experiments/gpu_check.sh             # the last part: join, install, check
#
# The check: the parity tests on CUDA (tests/test_warp_sim.py --warp-device cuda), then
# bench.py env --backend warp at N = 1024, 4096, 8192 with and without depth, the chunk-size
# table on the GPU, and a TRAIN_SECONDS oracle training (sim=warp device=cuda) where the env
# runs on the Warp backend. Figures and logs go to experiments/results/gpu_check/ and, on the
# lent machine, to $OUT.
#
#   DEVICE=cpu SIZES="8" TRAIN_SECONDS=20 bash experiments/gpu_check.sh --here   # dry run, CPU
#
# --here: use this machine's Python environment (no wheels, no install). The install alone,
# dry, with a local Python 3.12 (EXTRA_PATH: what the lent image has and this one lacks):
#   PY=python3.12 EXTRA_PATH=/tmp/np312 INSTALL_ONLY=1 bash experiments/gpu_check.sh
set -uo pipefail
cd "$(dirname "$0")/.."
STAGE=${1:-check}
START=$(date +%s)
BUDGET=${BUDGET:-470}                 # s for the whole check (the lent call's limit: 8 min)
TRAIN_SECONDS=${TRAIN_SECONDS:-300}
DEVICE=${DEVICE:-cuda}
SIZES=${SIZES:-"1024 4096 8192"}
CHUNK_ENVS=${CHUNK_ENVS:-4096}
PARTS=/tmp/legoh_wheels
RESULTS=${RESULTS:-experiments/results/gpu_check}
mkdir -p "$RESULTS" "$PARTS"
LOG="$RESULTS/gpu_check.log"

# the parts this call carried (the last one also brings their count and the joined hash)
if [ -d .whl ]; then cp .whl/part*/wheels.* "$PARTS"/ 2>/dev/null || true; fi
if [ "$STAGE" = receive ]; then
  ls -la "$PARTS"; du -sh "$PARTS"; exit 0
fi

left() { echo $(( BUDGET - ($(date +%s) - START) )); }
stage() {  # stage NAME SECONDS CMD...: run with a limit that also fits what is left
  local name=$1 limit=$2; shift 2
  local rest; rest=$(left)
  (( limit > rest - 5 )) && limit=$(( rest - 5 ))
  if (( limit < 10 )); then echo "== $name: skipped, no time left" | tee -a "$LOG"; return; fi
  echo "== $name (limit ${limit}s, $(date -u +%T))" | tee -a "$LOG"
  local t0; t0=$(date +%s)
  timeout -s INT -k 10 "$limit" "$@" 2>&1 | tee "$RESULTS/$name.log" | tail -n 25
  local rc=${PIPESTATUS[0]}
  echo "== $name: rc $rc in $(( $(date +%s) - t0 ))s" | tee -a "$LOG"
}

: > "$LOG"
PY=${PY:-python3}
if [ "$STAGE" != --here ]; then
  have=$(ls "$PARTS"/wheels.tar.* 2>/dev/null | wc -l)
  want=$(cat "$PARTS/wheels.parts" 2>/dev/null || echo '?')
  if [ "$have" != "$want" ] || [ "$(cat "$PARTS"/wheels.tar.* | sha256sum | cut -d' ' -f1)" \
       != "$(cat "$PARTS/wheels.sha256")" ]; then
    echo "wheel parts incomplete: $have of $want in $PARTS (the machine went cold between"
    echo "calls?): send them again from part 1 (docs/scaling.md)"; exit 1
  fi
  rm -rf /tmp/legoh_whl && mkdir -p /tmp/legoh_whl
  cat "$PARTS"/wheels.tar.* | tar -xf - -C /tmp/legoh_whl
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site /tmp/legoh_whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site${EXTRA_PATH:+:$EXTRA_PATH}:$PWD
  echo "installed in $(( $(date +%s) - START ))s" | tee -a "$LOG"
fi
export MUJOCO_GL=${MUJOCO_GL:-egl} WARP_CACHE_PATH=${WARP_CACHE_PATH:-/tmp/warp_cache}
export PYTHONPATH=${PYTHONPATH:-}:$PWD
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2>/dev/null
  $PY experiments/gpu_imports.py; } 2>&1 | grep -v '^Warp\|^   ' | tee -a "$LOG"

if [ -n "${INSTALL_ONLY:-}" ]; then exit 0; fi  # a dry run of the install alone
stage parity 150 $PY -m pytest tests/test_warp_sim.py -q --warp-device "$DEVICE" -p no:cacheprovider
# shellcheck disable=SC2086
stage bench_env 100 $PY experiments/bench.py env --backend warp --device "$DEVICE" \
  --sizes $SIZES --warp-steps 20 --results "$RESULTS"
stage chunks 60 $PY experiments/bench.py warp-chunks --device "$DEVICE" --num-envs "$CHUNK_ENVS" \
  --steps 10 --skip-cpu --results "$RESULTS"
if $PY -c "import legoh.envs.physics" 2>/dev/null; then
  rest=$(( $(left) - 15 )); (( TRAIN_SECONDS > rest )) && TRAIN_SECONDS=$rest
  stage oracle_train "$TRAIN_SECONDS" $PY run.py sim=warp sim.warp_device="$DEVICE" \
    device="$DEVICE" algo.num_envs="${TRAIN_ENVS:-4096}" algo.total_frames=1000000000 \
    hydra.run.dir="$RESULTS/oracle_run"
else
  echo "== oracle_train: skipped (HikingEnv has no Warp backend yet: legoh.envs.physics)" \
    | tee -a "$LOG"
fi
$PY experiments/gpu_report.py "$RESULTS" 2>&1 | tail -n 20
echo "total $(( $(date +%s) - START ))s" | tee -a "$LOG"
if [ -n "${OUT:-}" ]; then
  mkdir -p "$OUT/results"
  find "$RESULTS" -maxdepth 2 -type f \( -name '*.md' -o -name '*.json' -o -name '*.log' \
    -o -name '*.png' -o -name '*.csv' \) -size -5M -exec cp --parents {} "$OUT/results/" \;
fi
