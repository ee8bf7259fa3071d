#!/usr/bin/env python3
"""Reads a rosbag2 bag with the independent `rosbags` package and prints one JSON line per
message: topic, type, log time, and for sensor messages the header stamp, frame_id, geometry and
the sha256 of the data; for std_msgs/String the string. Exit 2 when rosbags is missing."""
import hashlib
import json
import sys
from pathlib import Path

try:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
except ImportError as e:  # pragma: no cover
    print(f"rosbags is not installed ({e}); pip install rosbags", file=sys.stderr)
    sys.exit(2)


def main():
    bag = Path(sys.argv[1])
    store = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([bag], default_typestore=store) as reader:
        print(json.dumps({"message_count": reader.message_count,
                          "topics": {c.topic: c.msgtype for c in reader.connections}}))
        for conn, t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            out = {"topic": conn.topic, "type": conn.msgtype, "log_time": t}
            if hasattr(msg, "header"):
                out.update(sec=msg.header.stamp.sec, nanosec=msg.header.stamp.nanosec,
                           frame_id=msg.header.frame_id)
            if hasattr(msg, "data") and not isinstance(msg.data, str):
                out["sha256"] = hashlib.sha256(bytes(msg.data)).hexdigest()
                out["len"] = len(msg.data)
            if hasattr(msg, "width"):
                out.update(width=msg.width, height=msg.height)
            if isinstance(getattr(msg, "data", None), str):
                out["string"] = msg.data
            print(json.dumps(out))


if __name__ == "__main__":
    main()
