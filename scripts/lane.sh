#!/usr/bin/env bash
# A training lane: the runs of a queue file, one after another, each on one libtorch thread,
# each trained by a fixed binary built from a named commit. Two lanes side by side use the
# two cores of a working machine; a lane started again skips what is done and resumes what
# was interrupted, so the same command continues a queue.
#
#   scripts/lane.sh run QUEUE         train the queue's runs (log: runs/lanes/QUEUE-NAME.log)
#   scripts/lane.sh collect REL...    copy finished runs from runs/REL to docs/results/REL, and
#                                     print what their write-up quotes (scripts/run-facts.py)
#   scripts/lane.sh status QUEUE      each run's state, latest step and training time left, and
#                                     the whole queue's env steps and hours to go
#   scripts/lane.sh check QUEUE       check every line (run does this first)
#   scripts/lane.sh stop QUEUE        end the lane: its run checkpoints; `run` resumes it
#
# A queue line is `REL COMMIT CONFIG SEED [--set KEY=VALUE ...] [--score-with COMMIT2]`
# (`#` starts a comment): the run trains into runs/REL with runs/bin/vge-COMMIT, built once
# from a git worktree of COMMIT (runs/src/COMMIT), and CONFIG is read from that commit, so a
# queue keeps training the same program and the same config whatever the checkout has
# become since. A run is skipped when docs/results/REL/score.json or runs/REL/score.json
# exists, and so is one whose folder another process holds (its vge.lock). The queue is read
# afresh before each run, so a queue file replaced while a run trains (write a new file and
# rename it over the old one; an edit in place could be read half-written) decides the next
# run. A run with a checkpoint resumes (bit for bit on the same binary, thread count and CPU
# model); a run folder without one (stopped before its first checkpoint) is moved aside to
# runs/REL.abandoned-TIME and the run starts again; a run that finished training without its
# score is scored. `--score-with` scores the finished run again with vge-COMMIT2
# (`vge score --force`), for scores the training binary lacks (per-object ones);
# runs/REL.scored-with-COMMIT2 marks it done.
#
# `collect` copies what a result needs (config, metrics, evaluations, scores, plots, the final
# and selected policies, the lane's training log) and never checkpoints, replay buffers,
# snapshots or TensorBoard files.
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$repo"
unset LIBTORCH_USE_PYTORCH LIBTORCH_INCLUDE LIBTORCH_LIB LIBTORCH_BYPASS_VERSION_CHECK

usage() { sed -n '7,13p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//' >&2; exit 2; }

# runs/bin/vge-COMMIT, built from a worktree of COMMIT under a lock (two lanes may ask at once).
binary_of() {
  local commit full bin src
  commit=$1
  full=$(git rev-parse --verify --quiet "$commit^{commit}") || { echo "lane: no commit $commit in this repository" >&2; return 1; }
  bin=runs/bin/vge-$commit
  mkdir -p runs/bin runs/src
  (
    flock 9
    if [ ! -x "$bin" ]; then
      [ -e .deps/libtorch ] || scripts/setup-libtorch.sh >&2
      src=runs/src/$commit
      [ -d "$src" ] || git worktree add --detach "$src" "$full" >&2
      mkdir -p "$src/.deps"
      ln -sfn "$(readlink -f .deps/libtorch)" "$src/.deps/libtorch"
      echo "lane: building vge at $commit (once)" >&2
      (cd "$src" && cargo build --release --bin vge >&2)
      cp "$src/target/release/vge" "$bin.tmp" && mv "$bin.tmp" "$bin"
    fi
  ) 9>"runs/bin/.build-$commit.lock"
  echo "$bin"
}

# Every line well formed, its commit and config present, no run twice: a typo found when the
# lane reaches its line would cost the hours before it.
check() {
  local queue=$1 n=0 bad=0 rel commit config seed rest score_commit
  local -A line_of=()
  [ -f "$queue" ] || { echo "lane: no queue file $queue" >&2; return 1; }
  while read -r rel commit config seed rest <&3; do
    n=$((n + 1))
    case $rel in ''|\#*) continue ;; esac
    if [ -z "$seed" ]; then
      echo "$queue:$n: expected REL COMMIT CONFIG SEED [--set KEY=VALUE ...] [--score-with COMMIT]" >&2; bad=1; continue
    fi
    split_score_with
    if [ -n "$score_commit" ] && ! git rev-parse --verify --quiet "$score_commit^{commit}" >/dev/null; then
      echo "$queue:$n: --score-with: no commit $score_commit in this repository" >&2; bad=1
    fi
    if ! git rev-parse --verify --quiet "$commit^{commit}" >/dev/null; then
      echo "$queue:$n: no commit $commit in this repository" >&2; bad=1
    elif ! git cat-file -e "$commit:$config" 2>/dev/null; then
      echo "$queue:$n: $config does not exist at commit $commit" >&2; bad=1
    fi
    [[ $seed =~ ^[0-9]+$ ]] || { echo "$queue:$n: seed '$seed' is not a whole number" >&2; bad=1; }
    [[ -z $rest || $rest =~ ^(--set\ [^\ ]+=[^\ ]+\ ?)+$ ]] || { echo "$queue:$n: after the seed only --set KEY=VALUE words and --score-with COMMIT: $rest" >&2; bad=1; }
    if [ -n "${line_of[$rel]:-}" ]; then echo "$queue:$n: $rel is also on line ${line_of[$rel]}" >&2; bad=1; fi
    line_of[$rel]=$n
  done 3<"$queue"
  return $bad
}

# Takes `--score-with COMMIT` out of $rest into $score_commit (empty without one).
split_score_with() {
  score_commit=
  if [[ " $rest " =~ \ --score-with\ ([^\ ]+)\  ]]; then
    score_commit=${BASH_REMATCH[1]}
    rest=$(sed -E 's/(^| )--score-with [^ ]+//; s/^ +//' <<<"$rest")
  fi
}

# The checkpoint folder `vge train --resume` reads, as vge picks it: checkpoint/, else
# checkpoint.old/ (left by a save killed between its two renames); fails when there is none.
resume_checkpoint() {
  local c
  for c in "$1/checkpoint" "$1/checkpoint.old"; do
    [ -d "$c" ] && { echo "$c"; return 0; }
  done
  return 1
}
has_checkpoint() { resume_checkpoint "$1" >/dev/null; }

# Another process (a lane, a `vge train` by hand) holds the run folder's lock.
in_use() { [ -f "$1/vge.lock" ] && ! flock -n "$1/vge.lock" true; }

run_queue() {
  local queue log rel commit config seed rest score_commit dir bin score_bin rc aside picked
  # Runs this lane has started (or failed to start), and skips it has logged, by REL.
  local -A tried=() noted=()
  queue=$1
  check "$queue" || { echo "lane: $queue has errors (above); nothing started" >&2; exit 1; }
  mkdir -p runs/lanes
  log=runs/lanes/$(basename "$queue" .txt).log
  echo "lane: $queue, log $log"
  # The queue is read afresh before each run: its first line neither done, nor held by
  # another process, nor tried by this lane is the next run. So lines reordered or added
  # while a run trains (write a new file and rename it over the queue) take effect at the
  # next run.
  while :; do
    picked=
    while read -r rel commit config seed rest <&3; do
      case $rel in ''|\#*) continue ;; esac
      [ -z "${tried[$rel]:-}" ] || continue
      dir=runs/$rel
      split_score_with
      if [ -f "docs/results/$rel/score.json" ] ||
        { [ -f "$dir/score.json" ] && { [ -z "$score_commit" ] || [ -f "$dir.scored-with-$score_commit" ]; }; }; then
        [ -n "${noted[done:$rel]:-}" ] || echo "$(date -u +%FT%TZ) skip $rel (done)" >>"$log"
        noted[done:$rel]=1; continue
      fi
      if in_use "$dir"; then
        [ -n "${noted[use:$rel]:-}" ] || echo "$(date -u +%FT%TZ) skip $rel (in use: pid $(cat "$dir/vge.lock") holds its lock)" >>"$log"
        noted[use:$rel]=1; continue
      fi
      picked=1; break
    done 3<"$queue"
    [ -n "$picked" ] || break
    tried[$rel]=1
    bin=$(binary_of "$commit") || { echo "$(date -u +%FT%TZ) fail $rel (no binary for $commit)" >>"$log"; continue; }
    echo "$(date -u +%FT%TZ) start $rel with vge-$commit" >>"$log"
    set +e
    rc=0
    if [ -f "$dir/score.json" ]; then
      : # trained and scored; only the scoring with --score-with's binary is left
    elif [ -f "$dir/final-eval.json" ]; then
      RAYON_NUM_THREADS=1 "$bin" score --threads 1 "$dir" >>"$dir.log" 2>&1; rc=$?
    elif has_checkpoint "$dir"; then
      RAYON_NUM_THREADS=1 "$bin" train --resume "$dir" >>"$dir.log" 2>&1; rc=$?
    else
      if [ -e "$dir" ]; then
        # Stopped before its first checkpoint: nothing to resume, and vge refuses to train
        # into a folder holding a run. Kept beside it, not deleted, and logged.
        aside=$dir.abandoned-$(date -u +%Y%m%dT%H%M%SZ)
        mv "$dir" "$aside"
        echo "$(date -u +%FT%TZ) moved $rel aside to ${aside#runs/} (no checkpoint to resume); starting again" >>"$log"
      fi
      mkdir -p "$(dirname "$dir")"
      # shellcheck disable=SC2086 # the --set words are meant to split
      RAYON_NUM_THREADS=1 "$bin" train --config "runs/src/$commit/$config" --seed "$seed" --out "$dir" $rest >>"$dir.log" 2>&1; rc=$?
    fi
    echo "$(date -u +%FT%TZ) end $rel (exit $rc)" >>"$log"
    if [ -n "$score_commit" ] && [ -f "$dir/score.json" ]; then
      if score_bin=$(binary_of "$score_commit"); then
        echo "$(date -u +%FT%TZ) score $rel again with vge-$score_commit" >>"$log"
        RAYON_NUM_THREADS=1 "$score_bin" score --force --threads 1 "$dir" >>"$dir.log" 2>&1; rc=$?
        [ "$rc" -eq 0 ] && echo "vge-$score_commit" >"$dir.scored-with-$score_commit"
        echo "$(date -u +%FT%TZ) scored $rel (exit $rc)" >>"$log"
      else
        echo "$(date -u +%FT%TZ) fail $rel (no binary for $score_commit)" >>"$log"
      fi
    fi
    set -e
  done
  echo "$(date -u +%FT%TZ) queue done" >>"$log"
}

collect() {
  local rel dir out f
  for rel in "$@"; do
    dir=runs/$rel
    out=docs/results/$rel
    [ -f "$dir/score.json" ] || { echo "lane: $dir has no score.json: not finished" >&2; exit 1; }
    mkdir -p "$out"
    for f in config.toml metrics.csv eval.csv final-eval.json best-eval.json score.json policy.vgep policy-best.vgep; do
      [ -f "$dir/$f" ] && cp "$dir/$f" "$out/$f"
    done
    for f in "$dir"/*.png; do [ -f "$f" ] && cp "$f" "$out/"; done
    [ -f "$dir.log" ] && cp "$dir.log" "$out/train.log"
    echo "collected $out: $(ls "$out" | tr '\n' ' ')"
    # What its write-up quotes, read from the copies just made.
    python3 "$(dirname "${BASH_SOURCE[0]}")/run-facts.py" "$out"
  done
}

# `, about N min of training left` from the run's budget and its last logged rate (the
# held-out score at the end adds a few minutes); nothing before the first metrics row.
time_left() {
  local total last
  total=$(sed -n 's/^total_steps = //p' "$1/config.toml" 2>/dev/null | head -n 1)
  last=$(tail -n 1 "$1/metrics.csv" 2>/dev/null) || return 0
  awk -F, -v total="$total" '$1 ~ /^[0-9]+$/ && $NF + 0 > 0 && total > 0 {
    printf ", about %.0f min of training left", (total - $1) / $NF / 60 }' <<<"$last"
}

# A line's env-step budget: `--set total_steps=N` on the line, else its config's, else the
# trainer's default (1M).
budget_of() {
  local commit=$1 config=$2 rest=$3 steps
  steps=$(grep -o 'total_steps=[0-9]*' <<<"$rest" | tail -n 1 | cut -d= -f2)
  [ -n "$steps" ] || steps=$(git show "$commit:$config" 2>/dev/null | sed -n 's/^total_steps = //p' | head -n 1)
  steps=${steps//_/}  # TOML allows 1_000_000
  [[ $steps =~ ^[0-9]+$ ]] || steps=1000000
  echo "$steps"
}

status() {
  local rel commit config rest state last ckpt step budget todo=0 waiting=0 rate=""
  while read -r rel commit config _ rest <&3; do
    case $rel in ''|\#*) continue ;; esac
    budget=$(budget_of "$commit" "$config" "$rest")
    if [ -f "docs/results/$rel/score.json" ]; then state="collected"
    elif [ -f "runs/$rel/score.json" ]; then state="finished, not collected"
    elif [ -f "runs/$rel/final-eval.json" ]; then state="trained, not scored"
    elif [ -e "runs/$rel" ]; then
      last=$(tail -n 1 "runs/$rel/metrics.csv" 2>/dev/null || echo 0)
      state="at step ${last%%,*}"
      step=0
      if ckpt=$(resume_checkpoint "runs/$rel"); then
        step=$(sed -n 's/^step = //p' "$ckpt/state.toml" 2>/dev/null || true)
        state+=", ${ckpt##*/} at step $step"
      else state+=", no checkpoint yet"; fi
      if in_use "runs/$rel"; then
        state+=", training now$(time_left "runs/$rel")"
        step=${last%%,*}
        rate=$(awk -F, '$NF + 0 > 0 { print $NF }' <<<"$last")
      elif [ -z "$ckpt" ]; then state+=": starts again"; fi
      [[ $step =~ ^[0-9]+$ ]] || step=0
      todo=$((todo + budget - step)); waiting=$((waiting + 1))
    else state="not started"; todo=$((todo + budget)); waiting=$((waiting + 1)); fi
    printf '%-50s %s\n' "$rel" "$state"
  done 3<"$1"
  # The queue as a whole, to plan sessions: env steps left, and at the running run's rate
  # (runs of other configs train at other rates) how long they take.
  awk -v n="$waiting" -v todo="$todo" 'BEGIN { printf "to go: %d runs, %.2fM env steps", n, todo / 1e6 }'
  if [ -n "$rate" ]; then
    awk -v todo="$todo" -v rate="$rate" 'BEGIN { printf ", about %.1f h at the running run'"'"'s %.0f steps/s", todo / rate / 3600, rate }'
  fi
  echo
}

# Ends the lane running QUEUE: its shell first, so that it starts no further run, then
# SIGTERM to its vge, which saves a checkpoint and exits; returns once it has.
stop() {
  local queue=$1 lane kids
  lane=$(pgrep -f "lane.sh run $queue\$" || true)
  [ -n "$lane" ] || { echo "lane: no lane is running $queue" >&2; return 1; }
  kids=$(pgrep -P "$lane" -d ' ' || true)
  # shellcheck disable=SC2086 # lists of pids
  kill $lane
  if [ -n "$kids" ]; then
    # shellcheck disable=SC2086
    kill -TERM $kids
    # shellcheck disable=SC2086
    while kill -0 $kids 2>/dev/null; do sleep 1; done
  fi
  echo "$(date -u +%FT%TZ) stopped by lane.sh stop" >>"runs/lanes/$(basename "$queue" .txt).log"
  echo "lane: stopped $queue"
}

case ${1:-} in
  run) [ $# -eq 2 ] || usage; run_queue "$2" ;;
  collect) [ $# -ge 2 ] || usage; shift; collect "$@" ;;
  status) [ $# -eq 2 ] || usage; status "$2" ;;
  check) [ $# -eq 2 ] || usage; check "$2" && echo "$2: every line checks" ;;
  stop) [ $# -eq 2 ] || usage; stop "$2" ;;
  *) usage ;;
esac; exit # on the esac line: a lane reads no further, so editing this file cannot reach it
