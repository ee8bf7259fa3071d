#!/usr/bin/python3
"""Independent ROS 1 bag peer for the bag crate's tests: Debian's python3-rosbag.

  ros1_bag.py write OUT.bag --compression none|bz2|lz4   writes the sample the tests expect
  ros1_bag.py read BAG                                    one JSON line per message (rosbag.Bag)

The sample: 6 messages in log-time order alternating /cam/image_raw (sensor_msgs/Image, 8x4 rgb8)
and /lidar/points (sensor_msgs/PointCloud2, 5 points x,y,z,intensity float32), then one
std_msgs/String on /note. Message k has header seq 100+k, stamp (1000+k, 7*k), log time
1600000000 s + 0.1 k s. Chunks are cut small so the bag has several.
"""
import hashlib
import json
import struct
import sys

import rosbag
import rospy
from sensor_msgs.msg import Image, PointCloud2, PointField
from std_msgs.msg import String


def sample():
    out = []
    for k in range(6):
        t = rospy.Time(1600000000, 100000000 * k)
        if k % 2 == 0:
            m = Image()
            m.height, m.width, m.encoding, m.is_bigendian, m.step = 4, 8, "rgb8", 0, 24
            m.data = bytes((i * 7 + k) % 256 for i in range(96))
            m.header.frame_id = "cam"
            topic = "/cam/image_raw"
        else:
            m = PointCloud2()
            m.height, m.width = 1, 5
            m.fields = [PointField(n, 4 * i, PointField.FLOAT32, 1) for i, n in enumerate("x y z intensity".split())]
            m.is_bigendian, m.point_step, m.row_step, m.is_dense = False, 16, 80, True
            m.data = b"".join(struct.pack("<4f", k, i, 2.0, 0.5) for i in range(5))
            m.header.frame_id = "velodyne"
            topic = "/lidar/points"
        m.header.seq = 100 + k
        m.header.stamp = rospy.Time(1000 + k, 7 * k)
        out.append((topic, m, t))
    out.append(("/note", String(data="hello ros1"), rospy.Time(1600000001, 0)))
    return out


def write(path, compression):
    with rosbag.Bag(path, "w", compression=compression, chunk_threshold=300) as b:
        for topic, m, t in sample():
            b.write(topic, m, t)


def describe(topic, msg, t):
    d = {"topic": topic, "type": msg._type, "time": t.to_nsec()}
    if hasattr(msg, "header"):
        d.update(seq=msg.header.seq, sec=msg.header.stamp.secs, nsec=msg.header.stamp.nsecs,
                 frame_id=msg.header.frame_id, sha256=hashlib.sha256(bytes(msg.data)).hexdigest(),
                 width=msg.width, height=msg.height)
        if msg._type == "sensor_msgs/PointCloud2":
            d["fields"] = [f.name for f in msg.fields]
            d["is_dense"] = bool(msg.is_dense)
        else:
            d["encoding"] = msg.encoding
    else:
        d["data"] = msg.data
    return d


def read(path):
    with rosbag.Bag(path) as b:
        info = b.get_type_and_topic_info()
        print(json.dumps({"messages": b.get_message_count(),
                          "topics": {k: [v.msg_type, v.message_count] for k, v in info.topics.items()}}))
        for topic, msg, t, conn in b.read_messages(return_connection_header=True):
            md5 = conn.get("md5sum")
            md5 = md5.decode() if isinstance(md5, bytes) else md5
            print(json.dumps(describe(topic, msg, t) | {"md5": md5}))


if __name__ == "__main__":
    if sys.argv[1] == "write":
        write(sys.argv[2], sys.argv[4] if len(sys.argv) > 4 else "none")
    elif sys.argv[1] == "read":
        read(sys.argv[2])
    else:
        sys.exit("usage: ros1_bag.py write OUT --compression C | read BAG")
