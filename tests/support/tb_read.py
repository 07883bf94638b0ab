"""Reads a TensorBoard log directory with TensorBoard's own EventAccumulator and prints
every scalar as `tag step value`, one per line (used by tests/tensorboard.rs)."""
import sys

from tensorboard.backend.event_processing import event_accumulator

acc = event_accumulator.EventAccumulator(sys.argv[1], size_guidance={event_accumulator.SCALARS: 0})
acc.Reload()
for tag in sorted(acc.Tags()["scalars"]):
    for e in acc.Scalars(tag):
        print(f"{tag} {e.step} {e.value:.6f}")
