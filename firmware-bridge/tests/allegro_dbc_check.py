#!/usr/bin/env python3
"""Decode frames made by vge's Allegro encoder with cantools and docs/allegro-v4.dbc, and check
each signal against the physical value the Rust decoder read from the same frame.

Input (file argument), one frame per line:
    ID_HEX D DATA_HEX MESSAGE signal=value ...   a data frame (DATA_HEX "-" when empty)
    ID_HEX R - MESSAGE                           a remote request for MESSAGE's data frame
A data frame passes when the DBC message at ID is MESSAGE with the frame's length, its signals
are exactly the ones given, each decodes to its value within 1% of a count of its scale, and
cantools encodes the values (range-checked against the DBC's limits, the torque clips) back to
the same bytes. A remote frame passes when its id names MESSAGE. Every DBC message must be
exercised. Exits 0 when all pass; else prints the mismatches and exits 1. Used by the test
`allegro_frames_decode_with_the_dbc` (firmware-bridge/tests/allegro_protocol.rs).
"""
import pathlib
import sys

import cantools


def main() -> int:
    root = pathlib.Path(__file__).resolve().parent.parent.parent
    db = cantools.database.load_file(str(root / "docs" / "allegro-v4.dbc"))
    problems, frames, remote, signals, seen = [], 0, 0, 0, set()
    for line in pathlib.Path(sys.argv[1]).read_text().splitlines():
        fields = line.split()
        frame_id, kind, hex_data, name = int(fields[0], 16), fields[1], fields[2], fields[3]
        frames += 1
        try:
            msg = db.get_message_by_frame_id(frame_id)
        except KeyError:
            problems.append(f"{frame_id:#05x}: no DBC message")
            continue
        if msg.name != name:
            problems.append(f"{frame_id:#05x}: DBC message {msg.name}, encoder made {name}")
            continue
        seen.add(msg.name)
        if kind == "R":
            remote += 1
            continue
        data = b"" if hex_data == "-" else bytes.fromhex(hex_data)
        if len(data) != msg.length:
            problems.append(f"{name}: {len(data)} bytes, DBC length {msg.length}")
            continue
        expected = {k: float(v) for k, v in (pair.split("=") for pair in fields[4:])}
        decoded = msg.decode(data, decode_choices=False)
        if set(decoded) != set(expected):
            problems.append(f"{name}: DBC signals {sorted(decoded)}, encoder gave {sorted(expected)}")
            continue
        for sig_name, value in expected.items():
            signals += 1
            tol = abs(msg.get_signal_by_name(sig_name).scale) * 0.01
            if abs(decoded[sig_name] - value) > tol:
                problems.append(f"{name}.{sig_name}: decoded {decoded[sig_name]}, expected {value} (tol {tol})")
        try:
            again = msg.encode(expected)
        except Exception as e:  # cantools raises on values outside the DBC's ranges
            problems.append(f"{name}: cantools cannot encode {expected}: {e}")
            continue
        if again != data:
            problems.append(f"{name}: cantools encodes {again.hex()}, the frame is {data.hex()}")
    missing = sorted(m.name for m in db.messages if m.name not in seen)
    if missing:
        problems.append(f"DBC messages no frame exercised: {missing}")
    print(
        f"allegro_dbc_check: {frames} frames ({remote} remote), {signals} signals, "
        f"{len(seen)} of {len(db.messages)} DBC messages"
    )
    for p in problems:
        print("allegro_dbc_check: MISMATCH", p)
    return 1 if problems or frames == 0 else 0


if __name__ == "__main__":
    sys.exit(main())
