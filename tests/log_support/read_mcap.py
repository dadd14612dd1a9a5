"""Reads an MCAP file with the official Python `mcap` reader and prints what it found as JSON.

Used by tests/mcap_python_reader.rs as an independent oracle for rigtwin's session log writer.
Usage: python3 read_mcap.py FILE.mcap
"""

import json
import sys

from mcap.reader import make_reader


def main(path: str) -> None:
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        header = reader.get_header()
        summary = reader.get_summary()
        channels = {}
        for channel_id, channel in sorted(summary.channels.items()):
            schema = summary.schemas.get(channel.schema_id)
            schema_doc = None
            if schema is not None and schema.encoding == "jsonschema":
                schema_doc = json.loads(schema.data)
            channels[channel.topic] = {
                "id": channel_id,
                "message_encoding": channel.message_encoding,
                "schema_name": schema.name if schema else None,
                "schema_encoding": schema.encoding if schema else None,
                "schema_is_object": isinstance(schema_doc, dict),
            }
        counts = {}
        sequences = {}
        log_times = {}
        payload_errors = []
        first_payloads = {}
        # File order (not log-time order): what a streaming consumer sees.
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic = channel.topic
            counts[topic] = counts.get(topic, 0) + 1
            sequences.setdefault(topic, []).append(message.sequence)
            log_times.setdefault(topic, []).append(message.log_time)
            try:
                value = json.loads(message.data)
            except ValueError as e:
                payload_errors.append(f"{topic} seq {message.sequence}: {e}")
                continue
            first_payloads.setdefault(topic, value)
        contiguous = {t: s == list(range(len(s))) for t, s in sequences.items()}
        times_sorted = {t: ts == sorted(ts) for t, ts in log_times.items()}
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        attachments = {
            a.name: {"media_type": a.media_type, "size": len(a.data)}
            for a in reader.iter_attachments()
        }
        stats = summary.statistics
        out = {
            "profile": header.profile,
            "library": header.library,
            "channels": channels,
            "counts": counts,
            "sequences_contiguous_from_0": contiguous,
            "log_times_sorted": times_sorted,
            "payload_errors": payload_errors,
            "first_payloads": first_payloads,
            "metadata": metadata,
            "attachments": attachments,
            "statistics": {
                "message_count": stats.message_count if stats else None,
                "channel_count": stats.channel_count if stats else None,
                "chunk_count": stats.chunk_count if stats else None,
            },
        }
    json.dump(out, sys.stdout, indent=1, sort_keys=True)


if __name__ == "__main__":
    main(sys.argv[1])
