#!/usr/bin/env python3
"""Summarise MCAP files with Foxglove's `mcap` package, as JSON on stdout.

Usage: read_mcap.py FILE.mcap [FILE-0001.mcap ...]
       read_mcap.py --messages TOPIC FILE.mcap [...]   (every message of TOPIC, decoded, as a JSON list)
       read_mcap.py --recover FILE.mcap [...]   (what a linear read recovers from each file)
       read_mcap.py --rewrite OUT.mcap FILE.mcap [...]   (every record rewritten by Python's writer)

Per channel (topic): schema name and encoding, message encoding, whether the schema parses as
JSON, message count, first and last log/publish times, whether log and publish times never go
backwards (in file order), and the first/last `seq` of the JSON messages and whether they are
contiguous. Also every metadata record. Used by tests/tests/recording.rs.

--recover: each file read from its start (no index needed), chunk CRCs checked, until its end
or the first error (a file cut short by a full disk has no summary and ends in a partial
chunk): per file the messages per topic, whether it read to its end, and the error that
stopped it; the IMU's `seq` over all files and whether it is contiguous.

--rewrite: the files' schemas, channels, messages (in file order, with their times and
sequence numbers) and metadata written into one file by the `mcap` package's own Writer
with its defaults (zstd chunks of 1 MiB, its own indexes and summary): a recording as another
MCAP writer makes it. Prints {"messages": N, "compression": ..., "bytes": size}.
"""

import json
import sys

from mcap.reader import NonSeekingReader, make_reader
from mcap.writer import CompressionType, Writer


def summarise(paths):
    channels = {}
    metadata = {}
    for path in paths:
        with open(path, "rb") as f:
            reader = make_reader(f)
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                c = channels.get(channel.topic)
                if c is None:
                    try:
                        json.loads(schema.data) if schema else None
                        schema_json = schema is not None
                    except ValueError:
                        schema_json = False
                    c = channels[channel.topic] = {
                        "schema_name": schema.name if schema else None,
                        "schema_encoding": schema.encoding if schema else None,
                        "schema_is_json": schema_json,
                        "message_encoding": channel.message_encoding,
                        "count": 0,
                        "first_log_time": message.log_time,
                        "last_log_time": message.log_time,
                        "first_publish_time": message.publish_time,
                        "last_publish_time": message.publish_time,
                        "log_time_monotonic": True,
                        "publish_time_monotonic": True,
                        "first_seq": None,
                        "last_seq": None,
                        "seq_contiguous": True,
                        "json_ok": True,
                    }
                if message.log_time < c["last_log_time"]:
                    c["log_time_monotonic"] = False
                if message.publish_time < c["last_publish_time"]:
                    c["publish_time_monotonic"] = False
                c["last_log_time"] = message.log_time
                c["last_publish_time"] = message.publish_time
                c["count"] += 1
                try:
                    seq = json.loads(message.data)["seq"]
                except (ValueError, KeyError):
                    c["json_ok"] = False
                    continue
                if c["first_seq"] is None:
                    c["first_seq"] = seq
                elif seq != c["last_seq"] + 1:
                    c["seq_contiguous"] = False
                c["last_seq"] = seq
            for record in reader.iter_metadata():
                metadata[record.name] = dict(record.metadata)
    return {"files": len(paths), "channels": channels, "metadata": metadata}


def messages(topic, paths):
    """Every JSON message of `topic`, in file order (tests/tests/replay.rs compares them)."""
    out = []
    for path in paths:
        with open(path, "rb") as f:
            for _schema, channel, message in make_reader(f).iter_messages(
                topics=[topic], log_time_order=False
            ):
                out.append(json.loads(message.data))
    return out


def recover(paths):
    files = []
    imu = {"first_seq": None, "last_seq": None, "seq_contiguous": True}
    for path in paths:
        topics = {}
        error = None
        with open(path, "rb") as f:
            reader = NonSeekingReader(f, validate_crcs=True)
            try:
                for _schema, channel, message in reader.iter_messages(
                    log_time_order=False
                ):
                    topics[channel.topic] = topics.get(channel.topic, 0) + 1
                    if channel.topic == "imu":
                        seq = json.loads(message.data)["seq"]
                        if imu["first_seq"] is None:
                            imu["first_seq"] = seq
                        elif seq != imu["last_seq"] + 1:
                            imu["seq_contiguous"] = False
                        imu["last_seq"] = seq
            except Exception as e:  # noqa: BLE001 - where the readable part ends, and why
                error = f"{type(e).__name__}: {e}"
        files.append(
            {
                "path": path,
                "messages": sum(topics.values()),
                "topics": topics,
                "complete": error is None,
                "error": error,
            }
        )
    return {"files": files, "messages": sum(f["messages"] for f in files), "imu": imu}


def rewrite(out_path, paths):
    count = 0
    with open(out_path, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start(profile="", library="python mcap (tests/python/read_mcap.py --rewrite)")
        schemas = {}
        channels = {}
        metadata = []
        for path in paths:
            with open(path, "rb") as f:
                reader = make_reader(f)
                for schema, channel, message in reader.iter_messages(log_time_order=False):
                    key = (path, channel.id)
                    if key not in channels:
                        skey = (schema.name, schema.encoding, schema.data)
                        if skey not in schemas:
                            schemas[skey] = writer.register_schema(
                                name=schema.name, encoding=schema.encoding, data=schema.data
                            )
                        channels[key] = writer.register_channel(
                            topic=channel.topic,
                            message_encoding=channel.message_encoding,
                            schema_id=schemas[skey],
                            metadata=dict(channel.metadata),
                        )
                    writer.add_message(
                        channel_id=channels[key],
                        log_time=message.log_time,
                        data=message.data,
                        publish_time=message.publish_time,
                        sequence=message.sequence,
                    )
                    count += 1
                for record in reader.iter_metadata():
                    metadata.append((record.name, dict(record.metadata)))
        for name, data in metadata:
            writer.add_metadata(name, data)
        writer.finish()
    import os

    return {"messages": count, "compression": "zstd", "bytes": os.path.getsize(out_path)}


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--rewrite":
        if len(sys.argv) < 4:
            sys.exit(__doc__)
        json.dump(rewrite(sys.argv[2], sys.argv[3:]), sys.stdout)
        print()
        sys.exit(0)
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    if sys.argv[1] == "--messages":
        if len(sys.argv) < 4:
            sys.exit(__doc__)
        json.dump(messages(sys.argv[2], sys.argv[3:]), sys.stdout)
        print()
        sys.exit(0)
    if sys.argv[1] == "--recover":
        if len(sys.argv) < 3:
            sys.exit(__doc__)
        json.dump(recover(sys.argv[2:]), sys.stdout, indent=1, sort_keys=True)
        print()
        sys.exit(0)
    json.dump(summarise(sys.argv[1:]), sys.stdout, indent=1, sort_keys=True)
    print()
