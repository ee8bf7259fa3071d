"""Reads a rosbag2 MCAP bag (a folder) with two independent readers, the PyPI `mcap` package
(its chunk index: the compression of every chunk) and `rosbags`, and prints one JSON object:
{"compression": [...], "mcap": [[topic, log_time, sha256], ...], "rosbags": [...]}.

    python3 read_mcap.py BAG_DIR
"""

import glob
import hashlib
import json
import os
import sys

from mcap.reader import make_reader
from rosbags.rosbag2 import Reader

folder = sys.argv[1]
(path,) = glob.glob(os.path.join(folder, "*.mcap"))


def sha(b):
    return hashlib.sha256(bytes(b)).hexdigest()


with open(path, "rb") as f:
    reader = make_reader(f)
    summary = reader.get_summary()
    compression = sorted({c.compression for c in summary.chunk_indexes})
    by_mcap = [
        [channel.topic, message.log_time, sha(message.data)]
        for _, channel, message in reader.iter_messages(log_time_order=True)
    ]

with Reader(folder) as bag:
    by_rosbags = [[c.topic, t, sha(raw)] for c, t, raw in bag.messages()]

print(json.dumps({"compression": compression, "mcap": by_mcap, "rosbags": by_rosbags}))
