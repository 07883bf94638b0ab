"""The run-level reading of VGE + FG against plain RL on the five objects (PLAN.md's addendum).

`vge compare` (compare.md beside this file) treats each object as a task and reports
P(A > B) for the selected policies only. This script adds what it does not compute:

- the run-level reading: each run's worst-object and mean-over-objects held-out success,
  for the selected and the final policy, one score per run (one task), 3 runs against 3;
- P(VGE > RL) for the final policies with each object a task.

It also recomputes the object-level IQM, mean and selected-policy P(VGE > RL) that
`vge compare` reports, as a check of this script against `lab/src/stats.rs`: the point
estimates must agree exactly; the intervals differ only by the random draws (numpy's
generator here, ChaCha8 in `vge`).

The statistics follow `lab/src/stats.rs` (rliable's definitions):
- IQM: `scipy.stats.trim_mean(x, 0.25)` of all runs x tasks: drop floor(n / 4) from each
  end of the sorted scores and average the rest (with 3 runs and one task nothing is cut,
  so the IQM is the mean);
- mean: the mean over tasks of each task's mean over runs;
- intervals: 95% stratified bootstrap percentile intervals, 10000 resamples; a resample
  draws, within each task, as many runs as it has, with replacement; bounds are
  numpy.percentile (linear) at 2.5 and 97.5 of the statistic over the resamples; the IQM's
  resamples are drawn before the mean's, from one generator per group and policy;
- P(X > Y): the mean over tasks of P(x > y) + P(x = y) / 2 over all pairs of a run of X
  and a run of Y; its interval resamples X and Y independently, each stratified by task.

Run from the repository root:
    .deps/py/bin/python docs/results/multi-object/compare-rl/run_level.py
It writes run-level.csv and run-level.md beside itself.
"""

import json
import zlib
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent
GROUPS = {
    "vge": [Path(f"docs/results/multi-object/seed-{s}") for s in range(3)],
    "rl": [Path(f"docs/results/multi-object-rl/seed-{s}") for s in range(3)],
}
OBJECTS = ["cube", "sphere", "cylinder", "dodecahedron", "icosahedron"]
POLICIES = ["selected", "final"]
RESAMPLES = 10_000
CONFIDENCE = 0.95
SEED = 0


def rng_for(label):
    """One generator per statistic, seeded from its label as `vge compare` does."""
    return np.random.default_rng(SEED ^ zlib.crc32(label.encode()))


def iqm(values):
    s = np.sort(np.ravel(values))
    cut = len(s) // 4
    return float(s[cut : len(s) - cut].mean())


def mean(scores):
    """scores: tasks x runs."""
    return float(np.mean([np.mean(task) for task in scores]))


def resample(scores, rng):
    """Stratified: within each task, runs drawn with replacement."""
    return [task[rng.integers(0, len(task), len(task))] for task in scores]


def interval(draws):
    tail = 100 * (1 - CONFIDENCE) / 2
    return float(np.percentile(draws, tail)), float(np.percentile(draws, 100 - tail))


def estimate(scores, statistic, rng):
    draws = [statistic(resample(scores, rng)) for _ in range(RESAMPLES)]
    return (statistic(scores), *interval(draws))


def prob_improvement(x, y):
    per_task = []
    for xs, ys in zip(x, y):
        a, b = np.asarray(xs)[:, None], np.asarray(ys)[None, :]
        per_task.append(float(((a > b) + 0.5 * (a == b)).mean()))
    return float(np.mean(per_task))


def prob_improvement_estimate(x, y, rng):
    draws = [prob_improvement(resample(x, rng), resample(y, rng)) for _ in range(RESAMPLES)]
    return (prob_improvement(x, y), *interval(draws))


def per_object(run, policy):
    score = json.loads((run / "score.json").read_text())
    figures = score[policy]["per_object"]
    return [figures[o]["success_rate"] for o in OBJECTS]


def main():
    # success[group][policy]: runs x objects
    success = {
        g: {p: np.array([per_object(r, p) for r in runs]) for p in POLICIES} for g, runs in GROUPS.items()
    }
    readings = {
        "objects as tasks": lambda m: [m[:, j] for j in range(m.shape[1])],
        "worst object": lambda m: [m.min(axis=1)],
        "mean over objects": lambda m: [m.mean(axis=1)],
    }
    rows, pairs = [], []
    for reading, to_tasks in readings.items():
        for policy in POLICIES:
            for g in GROUPS:
                scores = to_tasks(success[g][policy])
                label = f"{reading} {g} {policy}"
                rng = rng_for(label)
                rows.append((reading, g, policy, len(GROUPS[g]), estimate(scores, iqm, rng), estimate(scores, mean, rng)))
            for a, b in [("vge", "rl"), ("rl", "vge")]:
                x, y = to_tasks(success[a][policy]), to_tasks(success[b][policy])
                est = prob_improvement_estimate(x, y, rng_for(f"{reading} {policy} {a} > {b}"))
                pairs.append((reading, policy, a, b, est))

    csv = ["reading,group,policy,runs,iqm,iqm_ci_low,iqm_ci_high,mean,mean_ci_low,mean_ci_high"]
    for reading, g, policy, n, (i, il, ih), (m, ml, mh) in rows:
        csv.append(f"{reading},{g},{policy},{n},{i:.4f},{il:.4f},{ih:.4f},{m:.4f},{ml:.4f},{mh:.4f}")
    csv.append("")
    csv.append("reading,policy,a,b,prob_improvement,ci_low,ci_high")
    for reading, policy, a, b, (p, pl, ph) in pairs:
        csv.append(f"{reading},{policy},{a},{b},{p:.4f},{pl:.4f},{ph:.4f}")
    (OUT / "run-level.csv").write_text("\n".join(csv) + "\n")

    def verdict(lo, hi):
        if lo > 0.5:
            return "supported: the interval lies above 0.5"
        if hi < 0.5:
            return "reversed: the interval lies below 0.5"
        return "not supported: the interval holds 0.5"

    md = ["# VGE + FG against plain RL, run by run and object by object", ""]
    md.append(
        "Written by `run_level.py` (this folder) from each run's `score.json`: held-out success, "
        "100 episodes per object. 3 VGE + FG runs against 3 plain RL runs."
    )
    md.append("")
    md.append("Each run, success per object and its two run-level scores:")
    md.append("")
    md.append("| group | run | policy | " + " | ".join(OBJECTS) + " | worst object | mean over objects |")
    md.append("|---|---|---|" + "---|" * (len(OBJECTS) + 2))
    for g, runs in GROUPS.items():
        for policy in POLICIES:
            for r, row in zip(runs, success[g][policy]):
                cells = " | ".join(f"{v:.2f}" for v in row)
                md.append(f"| {g} | {r.name} | {policy} | {cells} | {row.min():.2f} | {row.mean():.3f} |")
    md.append("")
    md.append("| reading | group | policy | runs | IQM [95% CI] | mean [95% CI] |")
    md.append("|---|---|---|---|---|---|")
    for reading, g, policy, n, (i, il, ih), (m, ml, mh) in rows:
        md.append(f"| {reading} | {g} | {policy} | {n} | {i:.2f} [{il:.2f}, {ih:.2f}] | {m:.2f} [{ml:.2f}, {mh:.2f}] |")
    md.append("")
    md.append("| reading | policy | A | B | P(A > B) | 95% interval | what the interval supports |")
    md.append("|---|---|---|---|---|---|---|")
    for reading, policy, a, b, (p, pl, ph) in pairs:
        md.append(f"| {reading} | {policy} | {a} | {b} | {p:.2f} | [{pl:.2f}, {ph:.2f}] | {verdict(pl, ph)} |")
    md.append("")
    md.append(
        "Definitions as in `lab/src/stats.rs` (rliable's): IQM the mean of the middle half of the "
        "scores (with 3 runs and one task nothing is cut, so the run-level IQM is the mean); "
        "intervals 95% stratified bootstrap percentile intervals over 10000 resamples (numpy's "
        "generator, seeded per statistic); P(A > B) the probability that a run of A scores above "
        "a run of B, ties half, averaged over tasks. \"objects as tasks\": each object a task, as "
        "`vge compare` reads these runs (its compare.md gives the reported object-level IQM, mean "
        "and selected-policy P; the rows here agree with its point estimates and differ in the "
        "intervals only by the random draws). \"worst object\" and \"mean over objects\": one score "
        "per run, one task."
    )
    (OUT / "run-level.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
