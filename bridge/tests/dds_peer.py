#!/usr/bin/env python3
"""An independent DDS peer for the bridge's interoperability tests: Eclipse Cyclone DDS through the
PyPI package `cyclonedds` (its wheel bundles libddsc), with the ROS 2 naming and type conventions
(`rt/` topics, `sensor_msgs::msg::dds_::Image_` types), sensor-data QoS (best effort, keep last 5,
volatile) unless --reliable.

  dds_peer.py listen  --topic /cam --type image --count N [--timeout S] [--interface lo]
      prints one JSON line per received sample: stamp, frame_id, geometry, sha256 of data,
      CLOCK_MONOTONIC arrival (t_arrival_ns); types image, compressed_image, cloud, string,
      bool, camera_info
  dds_peer.py publish --topic /cam --type image|compressed_image|cloud --count N
                      [--width W --height H] [--points P] [--lie]
      waits for a matched reader, publishes N samples (stamp sec=1000+i, nanosec=i*1000+7,
      frame_id 'peer_frame', data bytes (i*31 + k*7) mod 251; compressed: a PNG of those
      pixels), prints one JSON line per sample; --lie makes every odd sample malformed

Exit status: 0 on success, 2 when the module is missing (the Rust tests turn that into a skip),
1 on a timeout before `count` samples.
"""
import argparse
import hashlib
import json
import struct
import sys
import time
import zlib
from dataclasses import dataclass

try:
    from cyclonedds.core import Qos, Policy
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.topic import Topic
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader, InvalidSample
    from cyclonedds.idl import IdlStruct
    import cyclonedds.idl.annotations as annotate
    import cyclonedds.idl.types as types
except ImportError as e:  # pragma: no cover
    print(f"cyclonedds is not installed ({e}); pip install cyclonedds", file=sys.stderr)
    sys.exit(2)


@dataclass
@annotate.final
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: types.int32
    nanosec: types.uint32


@dataclass
@annotate.final
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
@annotate.final
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header
    height: types.uint32
    width: types.uint32
    encoding: str
    is_bigendian: types.uint8
    step: types.uint32
    data: types.sequence[types.uint8]


@dataclass
@annotate.final
class CompressedImage(IdlStruct, typename="sensor_msgs::msg::dds_::CompressedImage_"):
    header: Header
    format: str
    data: types.sequence[types.uint8]


@dataclass
@annotate.final
class PointField(IdlStruct, typename="sensor_msgs::msg::dds_::PointField_"):
    name: str
    offset: types.uint32
    datatype: types.uint8
    count: types.uint32


@dataclass
@annotate.final
class PointCloud2(IdlStruct, typename="sensor_msgs::msg::dds_::PointCloud2_"):
    header: Header
    height: types.uint32
    width: types.uint32
    fields: types.sequence[PointField]
    is_bigendian: bool
    point_step: types.uint32
    row_step: types.uint32
    data: types.sequence[types.uint8]
    is_dense: bool


@dataclass
@annotate.final
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


@dataclass
@annotate.final
class Bool(IdlStruct, typename="std_msgs::msg::dds_::Bool_"):
    data: bool


@dataclass
@annotate.final
class RegionOfInterest(IdlStruct, typename="sensor_msgs::msg::dds_::RegionOfInterest_"):
    x_offset: types.uint32
    y_offset: types.uint32
    height: types.uint32
    width: types.uint32
    do_rectify: bool


@dataclass
@annotate.final
class CameraInfo(IdlStruct, typename="sensor_msgs::msg::dds_::CameraInfo_"):
    header: Header
    height: types.uint32
    width: types.uint32
    distortion_model: str
    d: types.sequence[types.float64]
    k: types.array[types.float64, 9]
    r: types.array[types.float64, 9]
    p: types.array[types.float64, 12]
    binning_x: types.uint32
    binning_y: types.uint32
    roi: RegionOfInterest


TYPES = {"image": Image, "compressed_image": CompressedImage, "cloud": PointCloud2,
         "string": String, "bool": Bool, "camera_info": CameraInfo}


def participant(args):
    """A participant on args.domain; with --interface, Cyclone may use only those interfaces
    (multicast forced on for loopback, which often lacks the MULTICAST flag), as the bridge's
    `[dds] interfaces` does."""
    if args.interface:
        nics = "".join(
            f'<NetworkInterface name="{n}" multicast="{"true" if n == "lo" else "default"}"/>'
            for n in args.interface)
        # loopback only: unicast discovery on 127.0.0.1 too, as the bridge does
        discovery = ('<Discovery><ParticipantIndex>auto</ParticipantIndex>'
                     '<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex>'
                     '<Peers><Peer address="127.0.0.1"/></Peers></Discovery>'
                     if all(n == "lo" for n in args.interface) else '')
        xml = (f'<CycloneDDS><Domain Id="{args.domain}"><General><Interfaces>{nics}</Interfaces>'
               f'</General>{discovery}</Domain></CycloneDDS>')
        _DOMAINS.append(Domain(args.domain, xml))  # must outlive the participant
    return DomainParticipant(args.domain)


_DOMAINS = []


def qos(args):
    rel = Policy.Reliability.Reliable(max_blocking_time=100_000_000) if args.reliable else Policy.Reliability.BestEffort
    return Qos(rel, Policy.History.KeepLast(args.depth), Policy.Durability.Volatile)


def dds_topic(name):
    return "rt/" + name.lstrip("/")


def pattern(i, n):
    # bytes (i*31 + k*7) mod 251, built fast
    period = bytes(((i * 31 + k * 7) % 251) for k in range(251))
    reps = n // 251 + 1
    return (period * reps)[:n]


def describe(s, kind):
    t = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
    if kind == "string":
        return {"data": s.data, "t_arrival_ns": t}
    if kind == "bool":
        return {"data": s.data, "t_arrival_ns": t}
    if kind == "camera_info":
        return {"sec": s.header.stamp.sec, "nanosec": s.header.stamp.nanosec,
                "frame_id": s.header.frame_id, "width": s.width, "height": s.height,
                "distortion_model": s.distortion_model, "d": list(s.d), "k": list(s.k),
                "t_arrival_ns": t}
    data = bytes(s.data)
    out = {
        "t_arrival_ns": t,
        "sec": s.header.stamp.sec,
        "nanosec": s.header.stamp.nanosec,
        "frame_id": s.header.frame_id,
        "len": len(data),
        "sha256": hashlib.sha256(data).hexdigest(),
    }
    if kind == "image":
        out.update(width=s.width, height=s.height, encoding=s.encoding, step=s.step)
    elif kind == "cloud":
        out.update(width=s.width, height=s.height, point_step=s.point_step,
                   fields=[[f.name, f.offset, f.datatype, f.count] for f in s.fields])
    else:
        out.update(format=s.format)
    return out


def listen(args):
    dp = participant(args)
    topic = Topic(dp, dds_topic(args.topic), TYPES[args.type], qos=qos(args))
    reader = DataReader(dp, topic, qos=qos(args))
    print(json.dumps({"ready": True}), flush=True)
    got = 0
    deadline = time.time() + args.timeout
    while got < args.count and time.time() < deadline:
        for s in reader.take(N=16):
            # A writer that goes away (the bridge stopping) arrives as an InvalidSample: an
            # instance-state change without data, not a message.
            if isinstance(s, InvalidSample):
                continue
            print(json.dumps(describe(s, args.type)), flush=True)
            got += 1
        time.sleep(0.005)
    return 0 if got >= args.count else 1


def png(width, height, rgb):
    """A minimal rgb8 PNG (filter 0 on every row), built with zlib only."""
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    rows = b"".join(b"\x00" + rgb[y * width * 3:(y + 1) * width * 3] for y in range(height))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")


def make(args, i):
    header = Header(stamp=Time(sec=1000 + i, nanosec=i * 1000 + 7), frame_id="peer_frame")
    if args.type == "image":
        step = args.width * 3
        # --lie: every odd frame claims one row more than its data holds (a malformed message)
        height = args.height + 1 if args.lie and i % 2 == 1 else args.height
        return Image(header=header, height=height, width=args.width, encoding="rgb8",
                     is_bigendian=0, step=step, data=list(pattern(i, step * args.height)))
    if args.type == "compressed_image":
        rgb = pattern(i, args.width * args.height * 3)
        data = png(args.width, args.height, rgb)
        if args.lie and i % 2 == 1:
            data = data[: len(data) // 2]  # a truncated PNG
        return CompressedImage(header=header, format="png", data=list(data))
    if args.type == "string":
        return String(data=f"message {i}")
    if args.type == "bool":
        return Bool(data=bool(args.value))
    if args.type == "camera_info":
        return CameraInfo(header=header, height=args.height, width=args.width,
                          distortion_model="plumb_bob", d=[0.1 * i, -0.2, 0.0, 0.0, 0.01],
                          k=[500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0],
                          r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                          p=[500.0, 0.0, 320.0, 0.0, 0.0, 500.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0],
                          binning_x=0,
                          binning_y=0, roi=RegionOfInterest(0, 0, 0, 0, False))
    if args.type == "cloud":
        fields = [PointField("x", 0, 7, 1), PointField("y", 4, 7, 1), PointField("z", 8, 7, 1),
                  PointField("intensity", 12, 7, 1)]
        # finite floats: pattern bytes are < 251, so exponents stay finite (no NaN/inf)
        return PointCloud2(header=header, height=1, width=args.points, fields=fields,
                           is_bigendian=False, point_step=16, row_step=16 * args.points,
                           data=list(pattern(i, 16 * args.points)), is_dense=True)
    raise SystemExit("unknown type")


def publish(args):
    dp = participant(args)
    topic = Topic(dp, dds_topic(args.topic), TYPES[args.type], qos=qos(args))
    writer = DataWriter(dp, topic, qos=qos(args))
    deadline = time.time() + args.timeout
    while not writer.get_matched_subscriptions():
        if time.time() > deadline:
            print("no reader matched", file=sys.stderr)
            return 1
        time.sleep(0.05)
    time.sleep(args.settle)
    for i in range(args.count):
        s = make(args, i)
        writer.write(s)
        d = describe(s, args.type)
        if args.type == "compressed_image":
            d["pixels_sha256"] = hashlib.sha256(pattern(i, args.width * args.height * 3)).hexdigest()
        d["lie"] = bool(args.lie and i % 2 == 1)
        print(json.dumps(d), flush=True)
        time.sleep(1.0 / args.rate)
    time.sleep(args.settle)
    return 0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["listen", "publish"])
    ap.add_argument("--topic", required=True)
    ap.add_argument("--type", choices=list(TYPES), required=True)
    ap.add_argument("--count", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=30.0)
    ap.add_argument("--domain", type=int, default=0)
    ap.add_argument("--depth", type=int, default=5)
    ap.add_argument("--reliable", action="store_true")
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--height", type=int, default=48)
    ap.add_argument("--points", type=int, default=1000)
    ap.add_argument("--rate", type=float, default=10.0)
    ap.add_argument("--settle", type=float, default=0.5)
    ap.add_argument("--lie", action="store_true", help="make every odd sample malformed")
    ap.add_argument("--value", type=int, default=1, help="bool: the value published")
    ap.add_argument("--interface", action="append", default=[],
                    help="network interface (name) DDS may use, e.g. lo; repeatable")
    args = ap.parse_args()
    return listen(args) if args.mode == "listen" else publish(args)


if __name__ == "__main__":
    sys.exit(main())
