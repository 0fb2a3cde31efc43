"""Reads an ndds recording with the Python `mcap` package (a reader ndds did not write) and
checks its JSON channels against their JSON Schemas with `jsonschema`.

    python read_bag.py FILE

Prints one JSON object: the profile, every channel (topic, message encoding, schema name and
encoding, metadata), message counts per topic, and for the JSON channels how many messages
were validated and the first error, if any. Exits 1 on a validation error.
"""

import json
import sys
from collections import Counter

import jsonschema
from mcap.reader import make_reader


def main(path):
    counts = Counter()
    validated = Counter()
    errors = []
    validators = {}
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        summary = reader.get_summary()
        channels = []
        for channel in summary.channels.values():
            schema = summary.schemas.get(channel.schema_id)
            channels.append(
                {
                    "topic": channel.topic,
                    "message_encoding": channel.message_encoding,
                    "schema_name": schema.name if schema else None,
                    "schema_encoding": schema.encoding if schema else None,
                    "metadata": dict(channel.metadata),
                }
            )
        for schema, channel, message in reader.iter_messages():
            counts[channel.topic] += 1
            if channel.message_encoding != "json":
                continue
            validator = validators.get(channel.id)
            if validator is None:
                document = json.loads(schema.data)
                jsonschema.Draft7Validator.check_schema(document)
                validator = jsonschema.Draft7Validator(document)
                validators[channel.id] = validator
            value = json.loads(message.data)
            failure = next(iter(validator.iter_errors(value)), None)
            if failure is not None and len(errors) < 5:
                errors.append(f"{channel.topic}: {failure.message}")
            validated[channel.topic] += 1
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    print(
        json.dumps(
            {
                "profile": header.profile,
                "library": header.library,
                "channels": channels,
                "counts": counts,
                "validated": validated,
                "errors": errors,
                "metadata": metadata,
            }
        )
    )
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
