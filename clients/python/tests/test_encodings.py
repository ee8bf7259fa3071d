"""Frames in the ``sensor_msgs/Image`` encodings of the encoding table: ``perturb.encodings()``
and ``perturb.apply_encoded()`` against ``perturb apply`` on a bag of the same frames."""

import numpy as np
import pytest

import perturb
from conftest import need, run

ID, SEVERITY, SEED, SEQ = "C-A1", 3, 7, 5


def test_the_table_lists_the_encodings_camera_drivers_publish():
    table = {e["name"]: e for e in perturb.encodings()}
    for name in ["rgb8", "bgr8", "mono8", "mono16", "rgb16", "bayer_rggb8", "bayer_grbg16", "yuv422", "yuv422_yuy2"]:
        assert name in table, name
    rggb = table["bayer_rggb8"]
    assert (rggb["layout"], rggb["working"], rggb["opencv"], rggb["tile"]) == ("bayer", "rgb8", "COLOR_BayerBG2BGR", [2, 2])
    assert table["yuv422"]["aliases"] == ["uyvy"] and table["yuv422"]["tile"] == [2, 1]
    assert (table["mono16"]["bits"], table["mono16"]["bytes_per_pixel"]) == (16, 2)
    assert table["bgr8"]["opencv"] is None and "8UC3" in table["bgr8"]["aliases"]


def test_bad_frames_raise_naming_the_field_and_value():
    with pytest.raises(perturb.PerturbError, match="width 5 is odd"):
        perturb.apply_encoded(bytes(100), "bayer_rggb8", 5, 4, 6, ID, SEVERITY)
    with pytest.raises(perturb.PerturbError, match="step 7 is smaller than width 4 x 2"):
        perturb.apply_encoded(bytes(100), "yuv422", 4, 4, 7, ID, SEVERITY)
    with pytest.raises(perturb.PerturbError, match="data length 10 is shorter"):
        perturb.apply_encoded(bytes(10), "mono16", 4, 4, 8, ID, SEVERITY)
    with pytest.raises(perturb.PerturbError, match="`nv21`"):
        perturb.apply_encoded(bytes(100), "nv21", 4, 4, 8, ID, SEVERITY)
    with pytest.raises(perturb.PerturbError, match="bit depth 20"):
        perturb.apply_encoded(bytes(64), "mono16", 4, 4, 8, ID, SEVERITY, bit_depth=20)


def _frames(frame):
    """(encoding, width, height, step, is_bigendian, bytes) made from the KITTI frame."""
    h, w = frame.shape[0] // 2 * 2, frame.shape[1] // 2 * 2
    rgb = frame[:h, :w].astype(np.uint16)
    # bayer_rggb8: each site its own colour, two bytes of padding per row.
    mosaic = np.zeros((h, w + 2), np.uint8)
    mosaic[0::2, 0:w:2] = rgb[0::2, 0::2, 0]
    mosaic[0::2, 1:w:2] = rgb[0::2, 1::2, 1]
    mosaic[1::2, 0:w:2] = rgb[1::2, 0::2, 1]
    mosaic[1::2, 1:w:2] = rgb[1::2, 1::2, 2]
    grey = (rgb.sum(axis=2) // 3).astype(np.uint8)
    # yuv422 (UYVY): grey luma, neutral chroma.
    uyvy = np.full((h, w * 2), 128, np.uint8)
    uyvy[:, 1::2] = 16 + (grey.astype(np.uint16) * 219 // 255)
    # mono16, big-endian.
    mono16 = (grey.astype(">u2") * 257).astype(">u2")
    return [
        ("bayer_rggb8", w, h, w + 2, 0, mosaic.tobytes()),
        ("yuv422", w, h, 2 * w, 0, uyvy.tobytes()),
        ("mono16", w, h, 2 * w, 1, mono16.tobytes()),
    ]


def test_apply_encoded_matches_perturb_apply_on_a_bag(cli, frame, tmp_path):
    need("rosbags", "pip install rosbags")
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    Image, Header, Time = (ts.types[t] for t in ["sensor_msgs/msg/Image", "std_msgs/msg/Header", "builtin_interfaces/msg/Time"])
    frames = _frames(frame)
    bag = tmp_path / "in"
    with Writer(bag, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/camera/image_raw", Image.__msgtype__, typestore=ts)
        for i, (enc, width, height, step, be, data) in enumerate(frames):
            msg = Image(
                header=Header(stamp=Time(sec=1, nanosec=i), frame_id="cam"),
                height=height, width=width, encoding=enc, is_bigendian=be, step=step,
                data=np.frombuffer(data, np.uint8),
            )
            w.write(conn, 1000 + i, ts.serialize_cdr(msg, Image.__msgtype__))
    out = tmp_path / "out"
    run(cli, "apply", "--id", ID, "--severity", SEVERITY, "--seed", SEED, "--seq", SEQ, bag, "-o", out)
    got = []
    with Reader(out) as r:
        for c, _, raw in r.messages():
            if c.topic == "/camera/image_raw":
                got.append(ts.deserialize_cdr(raw, c.msgtype))
    assert len(got) == len(frames)
    for i, ((enc, width, height, step, be, data), m) in enumerate(zip(frames, got)):
        # The message at index i on its topic has sequence number --seq + i.
        mine = perturb.apply_encoded(data, enc, width, height, step, ID, SEVERITY, SEED, SEQ + i, is_bigendian=be)
        assert (m.encoding, m.step, m.is_bigendian, m.width, m.height) == (enc, step, be, width, height)
        assert len(mine) == len(data) and mine != data, enc
        assert bytes(m.data) == mine, f"{enc}: apply_encoded differs from perturb apply"
    # Row padding passes through.
    enc, width, height, step, be, data = frames[0]
    mine = perturb.apply_encoded(data, enc, width, height, step, ID, SEVERITY, SEED, SEQ)
    pad = np.frombuffer(mine, np.uint8).reshape(height, step)[:, width:]
    assert np.array_equal(pad, np.frombuffer(data, np.uint8).reshape(height, step)[:, width:])
