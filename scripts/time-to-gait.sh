#!/usr/bin/env bash
# The time to a gait with a machine to itself: each seed of a config trained alone, with the
# config's own threads (the default: two cores, the governor picking the schedule), until its
# first periodic test at >= SUCCESS, then stopped with SIGTERM (vge train checkpoints and exits
# 143). `vge time-to-gait` reads the figure from the folders; `vge train --resume` (or a queue
# line naming the same folder) finishes each run bit for bit for its held-out scores.
#
#   scripts/time-to-gait.sh VGE CONFIG OUT SEED... [-- --set KEY=VALUE ...]
#
# VGE is a fixed binary (runs/bin/vge-COMMIT), OUT a folder under runs/ (one seed-S folder
# each, its output in OUT/seed-S.log, where a queue line's run logs). Stop the lanes first
# (`vge queue stop`): the figure is the machine's alone. SUCCESS defaults to 0.5 (env
# TIME_TO_GAIT_SUCCESS). A seed that never passes trains to its end.
set -euo pipefail

if [[ ${1:-} == -h || ${1:-} == --help || $# -lt 4 ]]; then
  sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//'
  [[ ${1:-} == -h || ${1:-} == --help ]] && exit 0
  exit 2
fi
vge=$1 config=$2 out=$3
shift 3
seeds=()
while [[ $# -gt 0 && $1 != "--" ]]; do seeds+=("$1"); shift; done
[[ ${1:-} == "--" ]] && shift
extra=("$@")
success=${TIME_TO_GAIT_SUCCESS:-0.5}
[[ -x $vge ]] || { echo "time-to-gait: $vge is not an executable" >&2; exit 2; }
[[ -f $config ]] || { echo "time-to-gait: no config $config" >&2; exit 2; }

# The first row of eval.csv whose success column is >= SUCCESS, as "step success".
first_pass() {
  [[ -f $1 ]] || return 0
  awk -F, -v s="$success" 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "success") c = i; next }
    c && $c + 0 >= s + 0 { print $1, $c; exit }' "$1"
}

mkdir -p "$out"
for seed in "${seeds[@]}"; do
  dir=$out/seed-$seed
  if [[ -e $dir ]]; then
    echo "time-to-gait: $dir exists: skipped (resume it with vge train --resume $dir)" >&2
    continue
  fi
  echo "$(date -u +%FT%TZ) seed $seed: $vge train --config $config --seed $seed --out $dir ${extra[*]}"
  "$vge" train --config "$config" --seed "$seed" --out "$dir" "${extra[@]}" >>"$dir.log" 2>&1 &
  pid=$!
  passed=""
  while kill -0 "$pid" 2>/dev/null; do
    sleep 5
    passed=$(first_pass "$dir/eval.csv")
    if [[ -n $passed ]]; then
      echo "$(date -u +%FT%TZ) seed $seed: first test at >= $success: step, success = $passed; stopping it"
      kill -TERM "$pid"
      break
    fi
  done
  set +e; wait "$pid"; rc=$?; set -e
  echo "$(date -u +%FT%TZ) seed $seed: vge train exited $rc${passed:+ after its first pass}"
done
