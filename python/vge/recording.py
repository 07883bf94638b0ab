"""vge's recorded episodes in the Rerun viewer.

`vge eval --record F.jsonl` and `vge-bridge run --backend sim --record F.jsonl` write an
episode as JSON Lines (a header, then one line per control step; the format is documented in
vge-sim's `recording` module). This module draws it with Rerun's Python SDK
(`pip install rerun-sdk`)::

    python -m vge.recording F.jsonl --spawn      # opens the viewer
    python -m vge.recording F.jsonl -o F.rrd     # writes a Rerun file (`rerun F.rrd`)

or from Python: `vge.recording.to_rerun("F.jsonl", "F.rrd")`.

One row per control step, on two timelines: `step` (control steps since the reset, 1 for the
state after the first action) and `sim_time` (s). Entities (world frame: z up, SI units):

- `world/hand/<finger>/link<j>` (one per joint `j` of the finger): the pose of the body the
  joint moves, as a transform, carrying its collision geoms (`.../geom<g>/shape`).
- `world/object`: the object's pose, as a transform, and its shape.
- `world/contacts/fingertip_points`, `world/contacts/link_points`: contact points of the
  fingertip spheres and of the link capsules with the object, labelled by finger.
- `world/contacts/fingertip_normal_force_1cm_per_N`, `..._link_normal_force_1cm_per_N`: the
  normal force on the object at each contact point, as arrows of 1 cm per newton.
- `action/<finger>/joint<j>_rad`: the step's joint-target changes, one per joint.
- `reward_rad_per_s`: the step's reward; `object_rotation_about_z_rad`: the object's rotation
  about world z since the reset (what the success test measures).

This file imports neither the rest of `vge` nor its Rust extension, so it also runs as a
script: `python python/vge/recording.py F.jsonl -o F.rrd`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

#: The header's `format` and `version` this reader understands.
FORMAT = "vge episode"
VERSION = 2

#: One colour per finger, so that contacts tell which finger made them.
FINGER_COLORS = ((230, 85, 13), (49, 130, 189), (49, 163, 84), (117, 107, 177), (214, 39, 40))
OBJECT_COLOR = (190, 190, 190)


class RecordingError(ValueError):
    """A file that is not a vge recording, or one this reader cannot draw."""


def read(path: str | Path) -> tuple[dict, list[dict]]:
    """The recording's header and its steps."""
    path = Path(path)
    with path.open() as f:
        lines = [line for line in f if line.strip()]
    if not lines:
        raise RecordingError(f"{path}: empty, not a vge recording")
    try:
        header = json.loads(lines[0])
        steps = [json.loads(line) for line in lines[1:]]
    except json.JSONDecodeError as e:
        raise RecordingError(f"{path}: not JSON Lines ({e})") from e
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise RecordingError(f"{path}: not a vge recording (its first line has no format {FORMAT!r})")
    if header.get("version") != VERSION:
        raise RecordingError(f"{path}: recording version {header.get('version')}, this reader reads {VERSION}")
    return header, steps


def _rerun():
    try:
        import rerun
    except ImportError as e:
        raise RecordingError("drawing a recording needs Rerun's SDK: pip install rerun-sdk") from e
    return rerun


def to_rerun(path: str | Path, rrd: str | Path | None = None, spawn: bool = False):
    """Logs the recording at `path` into a new Rerun recording, saved to `rrd` and/or shown in
    a spawned viewer; returns the `rerun.RecordingStream`."""
    header, steps = read(path)
    return _draw(header, steps, rrd, spawn)


def _draw(header: dict, steps: list[dict], rrd, spawn: bool):
    rr = _rerun()
    rec = rr.RecordingStream("vge")
    if rrd is not None:
        rec.save(str(rrd))
    if spawn:
        rec.spawn()
    # The wall clock says nothing about a simulated episode.
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    _log_geometry(rr, rec, header)
    fingers = [f["name"] for f in header["fingers"]]
    arrow_m_per_n = header["force_arrow_m_per_n"]
    for row in steps:
        rec.set_time("step", sequence=row["step"])
        rec.set_time("sim_time", duration=row["sim_time_s"])
        for finger in header["fingers"]:
            for j in finger["joints"]:
                rec.log(f"world/hand/{finger['name']}/link{j}", _transform(rr, row["links"][j]))
        rec.log("world/object", _transform(rr, row["object"]))
        for kind in ("fingertip", "link"):
            contacts = row[f"{kind}_contacts"]
            # Logged every step, empty when nothing touches: the viewer shows the latest value,
            # so a contact that ended must be cleared, not left standing.
            points = [c["point_m"] for c in contacts]
            colors = [FINGER_COLORS[c["finger"] % len(FINGER_COLORS)] for c in contacts]
            rec.log(
                f"world/contacts/{kind}_points",
                rr.Points3D(points, radii=[0.003], colors=colors, labels=[fingers[c["finger"]] for c in contacts]),
            )
            forces = [[arrow_m_per_n * x for x in c["normal_force_n"]] for c in contacts]
            rec.log(
                f"world/contacts/{kind}_normal_force_1cm_per_N",
                rr.Arrows3D(vectors=forces, origins=points, colors=colors),
            )
        for finger in header["fingers"]:
            for j in finger["joints"]:
                rec.log(f"action/{finger['name']}/joint{j}_rad", rr.Scalars(row["action_rad"][j]))
        rec.log("reward_rad_per_s", rr.Scalars(row["reward"]))
        rec.log("object_rotation_about_z_rad", rr.Scalars(row["rotation_about_z_rad"]))
    rec.flush()
    return rec


def _transform(rr, pose):
    return rr.Transform3D(translation=pose[:3], quaternion=rr.Quaternion(xyzw=pose[3:]))


def _log_geometry(rr, rec, header: dict) -> None:
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    for f, finger in enumerate(header["fingers"]):
        color = FINGER_COLORS[f % len(FINGER_COLORS)]
        name = finger["name"]
        # Each link's collision geoms, placed in the frame of the body its joint moves.
        for j in finger["joints"]:
            for g, geom in enumerate(header["link_geoms"][j]):
                path = f"world/hand/{name}/link{j}/geom{g}"
                rec.log(path, _transform(rr, geom["pose"]), static=True)
                rec.log(f"{path}/shape", _geom_shape(rr, geom, color), static=True)
    rec.log("world/object", _object_shape(rr, header["object"]), static=True)


def _geom_shape(rr, geom: dict, color):
    """One collision geom in its own frame (MuJoCo's conventions: capsules and cylinders on z)."""
    shape, size = geom["shape"], geom["size_m"]
    if shape == "sphere":
        return rr.Ellipsoids3D(centers=[[0, 0, 0]], radii=[size[0]], colors=[color])
    if shape == "capsule":
        return rr.Capsules3D(lengths=[2 * size[1]], radii=[size[0]], translations=[[0, 0, -size[1]]], colors=[color])
    if shape == "cylinder":
        return rr.Cylinders3D(lengths=[2 * size[1]], radii=[size[0]], colors=[color])
    if shape == "box":
        return rr.Boxes3D(half_sizes=[size], colors=[color])
    raise RecordingError(f"link geom shape {shape!r}: this reader draws sphere, capsule, cylinder and box")


def _object_shape(rr, obj: dict):
    half = 0.5 * obj["width_m"]
    shape = obj["shape"]
    if "mesh_vertices_m" in obj:
        return rr.Mesh3D(
            vertex_positions=obj["mesh_vertices_m"], triangle_indices=obj["mesh_triangles"], albedo_factor=OBJECT_COLOR
        )
    if shape == "cube":
        return rr.Boxes3D(half_sizes=[[half] * 3], colors=[OBJECT_COLOR])
    if shape == "sphere":
        return rr.Ellipsoids3D(centers=[[0, 0, 0]], radii=[half], colors=[OBJECT_COLOR])
    if shape == "cylinder":
        # The collider's cylinder stands on its axis, world z, as Rerun's does.
        return rr.Cylinders3D(lengths=[obj["width_m"]], radii=[half], colors=[OBJECT_COLOR])
    raise RecordingError(f"object shape {shape!r} has no mesh in the recording and no drawing here")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m vge.recording",
        description="Draws an episode recorded by `vge eval --record F.jsonl` (or `vge-bridge run --record`) "
        "in the Rerun viewer.",
    )
    parser.add_argument("recording", type=Path, help="the JSON Lines file vge wrote")
    parser.add_argument("-o", "--out", type=Path, help="write a Rerun file (.rrd) here")
    parser.add_argument("--spawn", action="store_true", help="open the Rerun viewer with the episode")
    args = parser.parse_args(argv)
    if args.out is None and not args.spawn:
        parser.error("nothing to do: give -o F.rrd, --spawn, or both")
    try:
        header, steps = read(args.recording)
        _draw(header, steps, args.out, args.spawn)
    except (OSError, RecordingError) as e:
        print(f"python -m vge.recording: {e}", file=sys.stderr)
        return 1
    except (KeyError, IndexError, TypeError) as e:
        print(
            f"python -m vge.recording: {args.recording}: malformed recording ({type(e).__name__}: {e})",
            file=sys.stderr,
        )
        # A half-drawn file would pass for the episode.
        if args.out is not None:
            args.out.unlink(missing_ok=True)
        return 1
    where = f" into {args.out}" if args.out else ""
    print(f"{len(steps)} steps of {header['object']['shape']}{where}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
