"""`python -m vge.recording`: an episode recorded by `vge eval --record` drawn into a Rerun
file that Rerun's own reader opens, with one row per control step; files that are not vge
recordings are refused naming what is wrong."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from vge import recording


def test_a_recorded_episode_becomes_a_rerun_file_with_a_row_per_step(vge_cli, repo, tmp_path):
    episode = tmp_path / "episode.jsonl"
    out = subprocess.run(
        [vge_cli, "eval", "--policy", repo / "policies/cube.vgep", "--episodes", "1", "--episode-s", "1",
         "--record", episode],
        capture_output=True, text=True,
    )
    assert out.returncode == 0, out.stderr
    header, steps = recording.read(episode)
    assert header["object"]["shape"] == "cube"
    assert [s["step"] for s in steps] == list(range(1, 21)), "1 s at 20 Hz"

    rrd = tmp_path / "episode.rrd"
    draw = subprocess.run(
        [sys.executable, "-m", "vge.recording", episode, "-o", rrd], capture_output=True, text=True
    )
    assert draw.returncode == 0, draw.stderr
    assert "20 steps of cube" in draw.stderr
    from rerun.experimental import RrdReader

    reader = RrdReader(str(rrd))
    assert len(reader.recordings()) == 1
    step_values = set()
    for chunk in reader.stream().collect().stream():
        if chunk.entity_path == "/world/object" and not chunk.is_static:
            step_values |= set(chunk.to_record_batch().column("step").to_pylist())
    assert step_values == set(range(1, 21))


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "empty"),
        ("{not json\n", "not JSON Lines"),
        ('{"format": "something else"}\n', "not a vge recording"),
        ('{"format": "vge episode", "version": 99}\n', "recording version 99"),
    ],
)
def test_files_that_are_not_recordings_are_refused_naming_why(tmp_path, text, message):
    path = tmp_path / "bad.jsonl"
    path.write_text(text)
    with pytest.raises(recording.RecordingError, match=message) as e:
        recording.read(path)
    assert str(path) in str(e.value)
    cli = subprocess.run([sys.executable, "-m", "vge.recording", path, "-o", tmp_path / "x.rrd"],
                         capture_output=True, text=True)
    assert cli.returncode == 1 and message in cli.stderr, cli.stderr
    assert not (tmp_path / "x.rrd").exists()


def test_a_malformed_step_is_reported_not_raised(tmp_path):
    path = tmp_path / "cut.jsonl"
    header = {"format": "vge episode", "version": recording.VERSION, "control_dt_s": 0.05, "force_arrow_m_per_n": 0.01,
              "fingers": [], "object": {"shape": "cube", "width_m": 0.1}}
    path.write_text(json.dumps(header) + "\n" + json.dumps({"step": 1}) + "\n")
    cli = subprocess.run([sys.executable, "-m", "vge.recording", path, "-o", tmp_path / "x.rrd"],
                         capture_output=True, text=True)
    assert cli.returncode == 1 and "malformed recording" in cli.stderr, cli.stderr
    assert "Traceback" not in cli.stderr
    assert not (tmp_path / "x.rrd").exists(), "no half-drawn file"


def test_nothing_to_do_is_a_usage_error(tmp_path):
    cli = subprocess.run([sys.executable, "-m", "vge.recording", tmp_path / "a.jsonl"], capture_output=True, text=True)
    assert cli.returncode == 2 and "nothing to do" in cli.stderr
