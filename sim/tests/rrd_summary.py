"""Reads a Rerun recording (.rrd) with the rerun-sdk of the `rerun` crate that wrote it
(0.36.3; scripts/test.sh installs it in .deps/py) and prints one JSON object:

  steps        the distinct values of the `step` timeline, sorted
  sim_time_s   the largest `sim_time` (s)
  entities     {path: {"static": [components], "temporal": [components], "steps": [steps]}}
  scalars      {path: [[step, value], ...]} for every entity holding Scalars

The Rust tests (sim/tests/recording.rs, cli/tests/record.rs, tests/tests/recording.rs)
check these against the episode they recorded."""
import json
import sys

from rerun.experimental import RrdReader

reader = RrdReader(sys.argv[1])
if len(reader.recordings()) != 1:
    sys.exit(f"expected one recording in {sys.argv[1]}, found {reader.recordings()}")

entities = {}
scalars = {}
all_steps = set()
sim_time_ns = 0
for chunk in reader.stream().collect().stream():
    path = chunk.entity_path
    if path.startswith("/__"):  # the recording's properties
        continue
    batch = chunk.to_record_batch()
    names = [n for n in batch.schema.names if ":" in n]
    entry = entities.setdefault(path, {"static": [], "temporal": [], "steps": []})
    if chunk.is_static:
        entry["static"] = sorted(set(entry["static"]) | set(names))
        continue
    entry["temporal"] = sorted(set(entry["temporal"]) | set(names))
    steps = batch.column("step").to_pylist()
    entry["steps"] = sorted(set(entry["steps"]) | set(steps))
    all_steps |= set(steps)
    if "sim_time" in batch.schema.names:
        times = batch.column("sim_time").cast("int64").to_pylist()
        sim_time_ns = max([sim_time_ns] + times)
    if "Scalars:scalars" in names:
        values = batch.column("Scalars:scalars").to_pylist()
        scalars.setdefault(path, []).extend([s, v[0]] for s, v in zip(steps, values))

for series in scalars.values():
    series.sort()
print(
    json.dumps(
        {"steps": sorted(all_steps), "sim_time_s": sim_time_ns / 1e9, "entities": entities, "scalars": scalars}
    )
)
