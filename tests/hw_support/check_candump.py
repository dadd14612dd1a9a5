"""Decodes a candump log with cantools against rig.dbc and compares every frame's signal
values with rigtwin's own decoding (the .decoded.jsonl beside the log).

Usage: check_candump.py RIG_DBC CANDUMP_LOG DECODED_JSONL
Prints a JSON report: frames, per-message counts, mismatches (first 20). Exit 0 when every
value is equal, 1 otherwise."""

import json
import sys

import cantools
from cantools.logreader import Parser


def main():
    dbc_path, log_path, decoded_path = sys.argv[1:4]
    db = cantools.database.load_file(dbc_path)
    with open(decoded_path) as f:
        ours = [json.loads(line) for line in f if line.strip()]
    mismatches = []
    counts = {}
    n = 0
    with open(log_path) as f:
        for n, entry in enumerate(Parser(f), start=0):
            frame = entry
            if n >= len(ours):
                mismatches.append({"line": n, "what": "frame missing from rigtwin's decoding"})
                break
            mine = ours[n]
            if mine["id"] != frame.frame_id:
                mismatches.append({"line": n, "what": f"id {frame.frame_id:#x} vs rigtwin {mine['id']:#x}"})
                continue
            try:
                msg = db.get_message_by_frame_id(frame.frame_id)
            except KeyError:
                msg = None
            if msg is None or len(frame.data) != msg.length:
                # Not a rig message: rigtwin must have reported it as undecodable too.
                if "error" not in mine:
                    mismatches.append({"line": n, "what": "cantools cannot decode, rigtwin did"})
                counts["(undecodable)"] = counts.get("(undecodable)", 0) + 1
                continue
            values = msg.decode(bytes(frame.data), decode_choices=False, scaling=True)
            if "error" in mine:
                # rigtwin rejects field values cantools takes (e.g. an unknown fault code);
                # only layout errors may differ from cantools, which checks no value sets.
                counts["(rejected by rigtwin)"] = counts.get("(rejected by rigtwin)", 0) + 1
                continue
            counts[msg.name] = counts.get(msg.name, 0) + 1
            if mine.get("name") != msg.name:
                mismatches.append({"line": n, "what": f"name {msg.name} vs rigtwin {mine.get('name')}"})
            theirs_keys = set(values)
            mine_keys = set(mine["signals"])
            if theirs_keys != mine_keys:
                mismatches.append({"line": n, "what": f"signals {sorted(theirs_keys ^ mine_keys)} differ"})
                continue
            for k, v in values.items():
                m = mine["signals"][k]
                if v != m:
                    mismatches.append({"line": n, "message": msg.name, "signal": k, "cantools": v, "rigtwin": m})
    frames = n + 1 if ours else 0
    if frames != len(ours):
        mismatches.append({"what": f"{frames} frames in the log, {len(ours)} decoded by rigtwin"})
    report = {"frames": frames, "counts": counts, "mismatches": mismatches[:20], "mismatch_count": len(mismatches)}
    print(json.dumps(report))
    sys.exit(0 if not mismatches else 1)


main()
