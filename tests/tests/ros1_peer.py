#!/usr/bin/python3
"""Independent ROS 1 peers for the tests: Debian's rospy (run with /usr/bin/python3).

  ros1_peer.py pub --topic T --type image|cloud|string|bool|pose|camera_info --count N [--rate HZ] [--size WxH]
                   [--points N] [--frame-id F] [--wait-subscribers K] [--stamp-base S]
      publishes N messages with distinct headers once K subscribers are connected; prints one
      JSON line per message (the header as published, rospy's seq, the data's sha256)
  ros1_peer.py sub --topic T --type image|cloud|string|clock --count N [--timeout S] [--no-hash]
      prints {"ready": true} once subscribed, then one JSON line per message received (header,
      geometry, sha256 of the data, CLOCK_MONOTONIC arrival in ns); exits after N or the timeout

Every process must get ROS_MASTER_URI, ROS_HOSTNAME=127.0.0.1 and a private ROS_HOME.
"""
import argparse
import hashlib
import json
import struct
import sys
import time

import rospy
from geometry_msgs.msg import PoseStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, PointCloud2, PointField
from std_msgs.msg import Bool, String

HASH = True
TYPES = {"image": Image, "cloud": PointCloud2, "string": String, "clock": Clock, "bool": Bool,
         "pose": PoseStamped, "camera_info": CameraInfo}


def out(d):
    print(json.dumps(d), flush=True)


def describe(m):
    d = {"t_arrival_ns": time.clock_gettime_ns(time.CLOCK_MONOTONIC)}
    if isinstance(m, Clock):
        d["clock_ns"] = m.clock.to_nsec()
        return d
    if isinstance(m, (String, Bool)):
        d["data"] = m.data
        return d
    if isinstance(m, PoseStamped):
        d.update(x=m.pose.position.x, y=m.pose.position.y, sec=m.header.stamp.secs,
                 nsec=m.header.stamp.nsecs)
        return d
    if isinstance(m, CameraInfo):
        d.update(seq=m.header.seq, sec=m.header.stamp.secs, nsec=m.header.stamp.nsecs,
                 frame_id=m.header.frame_id, width=m.width, height=m.height,
                 distortion_model=m.distortion_model, D=list(m.D), K=list(m.K))
        return d
    d.update(seq=m.header.seq, sec=m.header.stamp.secs, nsec=m.header.stamp.nsecs,
             frame_id=m.header.frame_id, width=m.width, height=m.height, len=len(m.data))
    if HASH:
        d["sha256"] = hashlib.sha256(bytes(m.data)).hexdigest()
    if isinstance(m, Image):
        d["encoding"] = m.encoding
    else:
        d["fields"] = [f.name for f in m.fields]
        d["point_step"] = m.point_step
    return d


def make(kind, k, a):
    if kind == "string":
        return String(data=f"message {k}")
    if kind == "bool":
        # false before message --switch-at, true from it on
        return Bool(data=k >= a.switch_at)
    if kind == "pose":
        x0, y0, dx, dy = (float(v) for v in a.path.split(","))
        m = PoseStamped()
        m.header.frame_id = "map"
        m.header.stamp = rospy.Time(a.stamp_base + k, 1000 * k + 7)
        m.pose.position.x, m.pose.position.y = x0 + k * dx, y0 + k * dy
        m.pose.orientation.w = 1.0
        return m
    if kind == "camera_info":
        m = CameraInfo(height=48, width=64, distortion_model="plumb_bob")
        m.D = [0.01 * k, -0.2, 0.0, 0.0, 0.01]
        m.K = [500.0, 0.0, 32.0, 0.0, 500.0, 24.0, 0.0, 0.0, 1.0]
        m.R = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        m.P = [500.0, 0.0, 32.0, 0.0, 0.0, 500.0, 24.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        m.header.frame_id = a.frame_id
        m.header.stamp = rospy.Time(a.stamp_base + k, 1000 * k + 7)
        return m
    if kind == "image":
        w, h = (int(x) for x in a.size.split("x"))
        m = Image(height=h, width=w, encoding="rgb8", is_bigendian=0, step=w * 3)
        base = bytes((i * 13 + k * 7) % 251 for i in range(w * 3))
        m.data = base * h
    else:
        n = a.points
        m = PointCloud2(height=1, width=n, is_bigendian=False, point_step=16, row_step=16 * n,
                        is_dense=True)
        m.fields = [PointField(name, 4 * i, PointField.FLOAT32, 1)
                    for i, name in enumerate(["x", "y", "z", "intensity"])]
        m.data = b"".join(struct.pack("<4f", 5.0 + (i % 97) * 0.1, (i % 13) - 6.0, 0.1 * (i % 7), 40.0 + k)
                          for i in range(n))
    m.header.frame_id = a.frame_id
    m.header.stamp = rospy.Time(a.stamp_base + k, 1000 * k + 7)
    return m


def pub(a):
    rospy.init_node(f"perturb_test_pub_{a.name}", anonymous=True, disable_signals=True)
    p = rospy.Publisher(a.topic, TYPES[a.type], queue_size=a.count + 1, tcp_nodelay=True)
    deadline = time.time() + a.timeout
    while p.get_num_connections() < a.wait_subscribers:
        if time.time() > deadline:
            sys.exit(f"no subscriber connected to {a.topic} within {a.timeout} s")
        time.sleep(0.05)
    time.sleep(0.2)
    period = 1.0 / a.rate if a.rate > 0 else 0
    start = time.time()
    for k in range(a.count):
        if period:
            delay = start + k * period - time.time()
            if delay > 0:
                time.sleep(delay)
        m = make(a.type, k, a)
        t_pub = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
        p.publish(m)
        d = describe(m)
        d.pop("t_arrival_ns", None)
        d["t_pub_ns"] = t_pub
        out(d)
    time.sleep(a.linger)


def sub(a):
    rospy.init_node(f"perturb_test_sub_{a.name}", anonymous=True, disable_signals=True)
    got = []

    def cb(m):
        got.append(describe(m))
        out(got[-1])

    rospy.Subscriber(a.topic, TYPES[a.type], cb, queue_size=1000, buff_size=2 ** 26, tcp_nodelay=True)
    out({"ready": True})
    deadline = time.time() + a.timeout
    while len(got) < a.count and time.time() < deadline:
        time.sleep(0.02)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["pub", "sub"])
    ap.add_argument("--topic", required=True)
    ap.add_argument("--type", required=True, choices=list(TYPES))
    ap.add_argument("--count", type=int, default=10)
    ap.add_argument("--rate", type=float, default=10.0)
    ap.add_argument("--size", default="64x48")
    ap.add_argument("--points", type=int, default=500)
    ap.add_argument("--frame-id", default="sensor")
    ap.add_argument("--stamp-base", type=int, default=1_600_000_000)
    ap.add_argument("--wait-subscribers", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=30.0)
    ap.add_argument("--linger", type=float, default=0.5)
    ap.add_argument("--name", default="x")
    ap.add_argument("--no-hash", action="store_true", help="skip the sha256 (latency runs)")
    ap.add_argument("--switch-at", type=int, default=0, help="bool: true from this message on")
    ap.add_argument("--path", default="0,0,1,0", help="pose: x0,y0,dx,dy per message")
    a = ap.parse_args()
    global HASH
    HASH = not a.no_hash
    pub(a) if a.mode == "pub" else sub(a)
    rospy.signal_shutdown("done")


if __name__ == "__main__":
    main()
