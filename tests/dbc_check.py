#!/usr/bin/env python3
"""Decode CAN frames captured on vcan0 with cantools and docs/vge-hand.dbc, and check each
decoded signal against the physical value the Rust encoder was given.

Input (file argument), one frame per line:  ID_HEX DATA_HEX signal=value signal=value ...
A signal matches when |decoded - expected| <= tolerance (half a count of that signal's scale,
plus float slack). Exits 0 when every frame decodes and every signal matches; else prints the
mismatches and exits 1. Used by the HIL test `frames_captured_on_vcan_decode_with_the_dbc`.
"""
import pathlib
import sys

import cantools

def main() -> int:
    root = pathlib.Path(__file__).resolve().parent.parent
    db = cantools.database.load_file(str(root / "docs" / "vge-hand.dbc"))
    lines = pathlib.Path(sys.argv[1]).read_text().splitlines()
    problems, frames, signals = [], 0, 0
    for line in lines:
        fields = line.split()
        frame_id, data = int(fields[0], 16), bytes.fromhex(fields[1])
        msg = db.get_message_by_frame_id(frame_id)
        decoded = msg.decode(data, decode_choices=False)
        frames += 1
        for pair in fields[2:]:
            name, value = pair.split("=")
            sig = msg.get_signal_by_name(name)
            tol = abs(sig.scale) * 0.5 + 1e-6
            signals += 1
            if abs(decoded[name] - float(value)) > tol:
                problems.append(f"{msg.name}.{name}: decoded {decoded[name]}, expected {value} (tol {tol})")
    print(f"dbc_check: {frames} frames, {signals} signals decoded with {len(db.messages)} DBC messages")
    for p in problems:
        print("dbc_check: MISMATCH", p)
    return 1 if problems or frames == 0 else 0

if __name__ == "__main__":
    sys.exit(main())
