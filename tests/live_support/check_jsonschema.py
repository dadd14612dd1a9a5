"""Checks JSON Schemas and messages with the Python `jsonschema` package (an oracle not written
here). Input: a JSON file {topic: {"schema": "<JSON Schema text>", "messages": [payload, ...]}}.
Prints JSON: {topic: {"schema_error": null | str, "checked": n, "invalid": [str, ...]}}."""

import json
import sys

import jsonschema


def main(path):
    with open(path) as f:
        topics = json.load(f)
    out = {}
    for topic, t in topics.items():
        report = {"schema_error": None, "checked": 0, "invalid": []}
        try:
            schema = json.loads(t["schema"])
            cls = jsonschema.validators.validator_for(schema)
            cls.check_schema(schema)
            validator = cls(schema)
        except Exception as e:  # noqa: BLE001 - any failure is the finding
            report["schema_error"] = f"{type(e).__name__}: {e}"
            out[topic] = report
            continue
        for m in t["messages"]:
            report["checked"] += 1
            errors = sorted(validator.iter_errors(m), key=str)
            if errors:
                report["invalid"].append(str(errors[0].message))
        out[topic] = report
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1])
