"""Reads an MCAP file with the Python `mcap` package and prints what it holds as one JSON object (tests/record.rs
checks it). Mode `indexed` opens the file through its summary (`make_reader`, as Foxglove's tooling does) and fails
on a file without one; mode `stream` reads records from the start and reports where the file is cut."""

import base64
import json
import struct
import sys

from mcap.reader import NonSeekingReader, make_reader


def jpeg_size(data: bytes):
    """(width, height) from a JPEG's start-of-frame marker, or None when it is not a baseline/progressive JPEG."""
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 9 < len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        (length,) = struct.unpack(">H", data[i + 2 : i + 4])
        if marker in (0xC0, 0xC1, 0xC2):
            height, width = struct.unpack(">HH", data[i + 5 : i + 9])
            return width, height
        i += 2 + length
    return None


def first_image(message) -> dict:
    """A foxglove.CompressedImage message (JSON encoding) decoded the way Foxglove does: format and the image."""
    image = json.loads(message.data)
    jpeg = base64.b64decode(image["data"])
    size = jpeg_size(jpeg)
    return {
        "format": image.get("format"),
        "frame_id": image.get("frame_id"),
        "bytes": len(jpeg),
        "width": size[0] if size else None,
        "height": size[1] if size else None,
    }


def main() -> None:
    path, mode = sys.argv[1], sys.argv[2]
    out = {"channels": {}, "schemas": {}, "messages": 0, "cut": None, "summary": None, "first_image": None}
    with open(path, "rb") as f:
        if mode == "indexed":
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None:
                raise SystemExit(f"{path} has no summary")
            out["summary"] = {
                "message_count": summary.statistics.message_count if summary.statistics else None,
                "channels": len(summary.channels),
                "chunks": len(summary.chunk_indexes),
            }
        else:
            reader = NonSeekingReader(f, validate_crcs=True)
        try:
            # In file order: sorting by log time would read the whole file before yielding anything, and a cut
            # file would then yield nothing at all.
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                entry = out["channels"].setdefault(
                    channel.topic,
                    {
                        "encoding": channel.message_encoding,
                        "schema": schema.name if schema else None,
                        "has_header": "flow.header" in channel.metadata,
                        "count": 0,
                    },
                )
                entry["count"] += 1
                if schema is not None and schema.name == "foxglove.CompressedImage" and out["first_image"] is None:
                    out["first_image"] = first_image(message)
                if schema is not None:
                    out["schemas"][schema.name] = schema.encoding
                out["messages"] += 1
        except Exception as e:  # noqa: BLE001 - a cut file ends in whatever error its last record gives
            if mode == "indexed":
                raise
            out["cut"] = f"{type(e).__name__}: {e}"
    print(json.dumps(out))


if __name__ == "__main__":
    main()
