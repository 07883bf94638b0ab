"""The aggregates of lab/src/stats.rs computed by rliable itself (stats_vs_rliable.rs).

Reads JSON on stdin: {"part": "groups" or "pairs", "reps": R, "groups": {name: [[run scores
of task 0], [task 1], ...]}, "pairs": [[x, y], ...], "taus": [...]}, and prints JSON. Part
"groups": per group the IQM and mean with their percentile intervals, and the performance
profile at taus with its band. Part "pairs": per pair the probability of improvement with its
interval. All with rliable's defaults (stratified bootstrap, percentile method, 95%).
"""
import json
import sys

import numpy as np
from rliable import library as rly
from rliable import metrics

request = json.load(sys.stdin)
part = request["part"]
if part not in ("groups", "pairs"):
    sys.exit(f"unknown part {part!r}: 'groups' or 'pairs'")
reps = request["reps"]
# rliable's runs x tasks matrices.
groups = {name: np.array(by_task, dtype=float).T for name, by_task in request["groups"].items()}

# rliable's bootstraps draw their indices from numpy's global generator.
np.random.seed(0)
out = {}
if part == "groups":
    out = {"groups": {}, "profiles": {}}
    points, intervals = rly.get_interval_estimates(
        groups,
        lambda x: np.array([metrics.aggregate_iqm(x), metrics.aggregate_mean(x)]),
        reps=reps,
    )
    for name in groups:
        out["groups"][name] = {
            "iqm": [float(points[name][0]), float(intervals[name][0][0]), float(intervals[name][1][0])],
            "mean": [float(points[name][1]), float(intervals[name][0][1]), float(intervals[name][1][1])],
        }
    profiles, bands = rly.create_performance_profile(groups, np.array(request["taus"]), reps=reps)
    for name in groups:
        out["profiles"][name] = {
            "points": [float(v) for v in profiles[name]],
            "low": [float(v) for v in bands[name][0]],
            "high": [float(v) for v in bands[name][1]],
        }
else:
    out = {"pairs": []}
    pair_scores = {f"{x}>{y}": [groups[x], groups[y]] for x, y in request["pairs"]}
    points, intervals = rly.get_interval_estimates(pair_scores, metrics.probability_of_improvement, reps=reps)
    for x, y in request["pairs"]:
        key = f"{x}>{y}"
        low, high = np.ravel(intervals[key])
        out["pairs"].append([x, y, float(points[key]), float(low), float(high)])
print(json.dumps(out))
