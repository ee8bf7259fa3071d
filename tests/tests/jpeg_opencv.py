"""OpenCV's side of tests/tests/jpeg_opencv.rs: the JPEG round trip of PerturbationDrive's
`jpeg_filter` (cv2.imencode(".jpg", img, [IMWRITE_JPEG_QUALITY, q]) then cv2.imdecode) of each
frame the test wrote, with the frame handed to OpenCV in its true colours (BGR order).

usage: python3 -c "$(cat jpeg_opencv.py)" DIR (the test passes it with -c)

Reads DIR/frames.txt, one frame a line: NAME WIDTH HEIGHT CHANNELS (3: rgb8 bytes in
DIR/NAME.raw, 1: mono8), and for each quality in DIR/qualities.txt writes DIR/NAME.qQ.cv: the
decoded frame in the same layout (rgb8 or mono8). Prints OpenCV's version.
"""

import pathlib
import sys

import cv2
import numpy as np


def main():
    d = pathlib.Path(sys.argv[1])
    qualities = [int(q) for q in (d / "qualities.txt").read_text().split()]
    for line in (d / "frames.txt").read_text().splitlines():
        name, w, h, c = line.split()
        w, h, c = int(w), int(h), int(c)
        img = np.fromfile(d / f"{name}.raw", np.uint8).reshape((h, w, c) if c == 3 else (h, w))
        # The true colours in OpenCV's order: an RGB frame becomes a BGR Mat.
        mat = np.ascontiguousarray(img[:, :, ::-1]) if c == 3 else img
        for q in qualities:
            ok, buf = cv2.imencode(".jpg", mat, [int(cv2.IMWRITE_JPEG_QUALITY), q])
            assert ok, f"imencode failed on {name}"
            out = cv2.imdecode(buf, cv2.IMREAD_COLOR if c == 3 else cv2.IMREAD_GRAYSCALE)
            if c == 3:
                out = out[:, :, ::-1]
            np.ascontiguousarray(out).tofile(d / f"{name}.q{q}.cv")
    print(cv2.__version__)


main()
