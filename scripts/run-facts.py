#!/usr/bin/env python3
"""Print a finished, scored run's facts as the results READMEs report them.

Usage: scripts/run-facts.py RUN_DIR [RUN_DIR ...]

Reads RUN_DIR/score.json (held-out scores), final-eval.json (wall time), metrics.csv (the
critic's mean Q against the discounted return collected, the BC term, the controller's
share), eval.csv (the periodic tests), train.log and the lanes' logs (runs/lanes/*.log: when
each segment of a run started and ended), and prints one table row and the numbers a bullet
quotes. Standard library only, so it runs with any Python 3.
"""

import csv
import json
import re
import sys
from pathlib import Path

# The comparison reports the critic and the returns from here on: the first 100k steps
# are the warm-up, where neither means much yet.
FROM_STEP = 100_000


def steps_label(step):
    return "1M" if step == 1_000_000 else f"{step // 1000}k"


def column(rows, name, from_step=0):
    """(step, value) of one metrics.csv column, empty fields skipped."""
    out = []
    for row in rows:
        step = int(row["step"])
        if step >= from_step and row.get(name, "") != "":
            out.append((step, float(row[name])))
    return out


def value_range(pairs):
    values = [v for _, v in pairs]
    return (min(values), max(values)) if values else None


def fmt_range(r, digits=1):
    return "-" if r is None else f"{r[0]:.{digits}f} to {r[1]:.{digits}f}"


def segments(run):
    """Each training segment in train.log: (resumed from step or 0, wall s, how it ended)."""
    log = run / "train.log"
    if not log.is_file():
        return []
    out = []
    for line in log.read_text().splitlines():
        if line.startswith("training "):
            m = re.search(r"resuming from step (\d+)", line)
            out.append([int(m.group(1)) if m else 0, None, "killed (no end line)"])
        elif out and line.startswith("time this session: "):
            out[-1][1] = float(line.split()[3])
        elif out and line.startswith("stopped at step "):
            out[-1][2] = f"stopped checkpointed at {int(line.split()[3].rstrip(':')):,}"
        elif out and line.startswith("done: "):
            out[-1][2] = "done"
    return out


def lane_events(run):
    """(time, start|end, lane) of the run in runs/lanes/*.log, the run named as in its queue."""
    parts = run.resolve().parts
    if "results" not in parts:
        return []
    rel = "/".join(parts[parts.index("results") + 1:])
    events = []
    lanes = Path(__file__).resolve().parent.parent / "runs" / "lanes"
    for log in sorted(lanes.glob("*.log")):
        for line in log.read_text().splitlines():
            fields = line.split()
            if len(fields) >= 3 and fields[1] in ("start", "end") and fields[2] == rel:
                events.append((fields[0], fields[1], log.stem))
    return sorted(events)


def facts(run):
    run = Path(run)
    missing = [f for f in ("score.json", "final-eval.json", "metrics.csv", "eval.csv")
               if not (run / f).is_file()]
    if missing:
        raise SystemExit(f"{run}: missing {', '.join(missing)}: not a finished, scored run")
    score = json.loads((run / "score.json").read_text())
    final_eval = json.loads((run / "final-eval.json").read_text())
    with open(run / "metrics.csv", newline="") as f:
        metrics = list(csv.DictReader(f))
    with open(run / "eval.csv", newline="") as f:
        periodic = list(csv.DictReader(f))

    sel, fin = score["selected"], score["final"]
    wall = final_eval.get("wall_s")
    print(f"== {run}")
    print("row: selected: success (drops) | selected at | final: success (drops) | "
          "final: rotation (rad) | wall (s)")
    print(f"  {sel['success_rate']:.2f} ({sel['drop_rate']:.2f}) | {steps_label(sel['step'])} | "
          f"{fin['success_rate']:.2f} ({fin['drop_rate']:.2f}) | "
          f"{fin['mean_rotation_rad']:.2f} | {'-' if wall is None else f'{wall:,.0f}'}")
    print(f"selected: rotation {sel['mean_rotation_rad']:.2f} rad, "
          f"{sel['mean_contact_switches']:.1f} contact switches per episode")
    last = score.get("last_snapshots")
    if last:
        print(f"last {len(last['snapshots'])} snapshots: success {last['success_rate']:.2f}")

    q = column(metrics, "mean_q", FROM_STEP)
    ret = column(metrics, "mc_return", FROM_STEP)
    print(f"from {FROM_STEP // 1000}k: mean Q {fmt_range(value_range(q))}, "
          f"collected discounted return {fmt_range(value_range(ret))}")
    if q and ret:
        print(f"  at {steps_label(q[-1][0])}: mean Q {q[-1][1]:.1f}, return {ret[-1][1]:.1f}")
    bc = value_range(column(metrics, "bc_loss"))
    if bc is not None and (bc[0] != 0.0 or bc[1] != 0.0):
        print(f"bc_loss: {fmt_range(bc, 2)}")
    share = column(metrics, "controller_share")
    if share and any(v > 0 for _, v in share):
        nonzero = [p for p in share if p[1] > 0]
        print(f"controller share: {share[0][1]:.0%} at {steps_label(share[0][0])}, "
              f"{nonzero[-1][1]:.0%} at {steps_label(nonzero[-1][0])} (last step it acted)")
    print("periodic tests (step: success, drops): " + "; ".join(
        f"{steps_label(int(r['step']))}: {float(r['success']):.0%}, {float(r['drops']):.0%}"
        for r in periodic))
    segs = segments(run)
    if segs:
        print(f"segments (train.log): {len(segs)}: " + "; ".join(
            f"from {frm:,}, {'-' if s is None else f'{s:,.0f} s'}, {end}" for frm, s, end in segs))
    events = lane_events(run)
    if events:
        print("lanes: " + "; ".join(f"{t} {what} ({lane})" for t, what, lane in events))


def main():
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__.strip())
        return 0 if len(sys.argv) >= 2 else 2
    for run in sys.argv[1:]:
        facts(run)
    return 0


if __name__ == "__main__":
    sys.exit(main())
