"""OpenCV's side of tests/tests/encodings.rs: converts the frames the test wrote, with the codes
cv_bridge uses for each encoding, and writes the results next to them.

usage: python3 -c "$(cat encodings_opencv.py)" DIR WIDTH HEIGHT (the test passes it with -c)

Reads DIR/frame.rgb (rgb8), DIR/bayer_<tile>8.raw and DIR/bayer_rggb16.raw (little-endian);
writes DIR/cv_bayer_<tile>8.bgr (cvtColor with cv_bridge's code), DIR/cv_bayer_rggb16.bgr
(16-bit BGR, little-endian), DIR/cv_<uyvy|yuy2>.yuv (cvtColor(RGB2YUV_*) of the frame) and
DIR/cv_<uyvy|yuy2>.rgb (cvtColor(YUV2RGB_*) of those bytes). Prints OpenCV's version.
"""

import pathlib
import sys

import cv2
import numpy as np

# cv_bridge's codes: OpenCV names a Bayer code after the second row's second and third pixels.
BAYER = {
    "rggb": cv2.COLOR_BayerBG2BGR,
    "bggr": cv2.COLOR_BayerRG2BGR,
    "gbrg": cv2.COLOR_BayerGR2BGR,
    "grbg": cv2.COLOR_BayerGB2BGR,
}


def main():
    d = pathlib.Path(sys.argv[1])
    w, h = int(sys.argv[2]), int(sys.argv[3])
    rgb = np.fromfile(d / "frame.rgb", np.uint8).reshape(h, w, 3)
    for tile, code in BAYER.items():
        m = np.fromfile(d / f"bayer_{tile}8.raw", np.uint8).reshape(h, w)
        cv2.cvtColor(m, code).tofile(d / f"cv_bayer_{tile}8.bgr")
    m16 = np.fromfile(d / "bayer_rggb16.raw", "<u2").reshape(h, w)
    cv2.cvtColor(m16, BAYER["rggb"]).astype("<u2").tofile(d / "cv_bayer_rggb16.bgr")
    for name, to, back in [
        ("uyvy", cv2.COLOR_RGB2YUV_UYVY, cv2.COLOR_YUV2RGB_UYVY),
        ("yuy2", cv2.COLOR_RGB2YUV_YUY2, cv2.COLOR_YUV2RGB_YUY2),
    ]:
        yuv = cv2.cvtColor(rgb, to)
        yuv.tofile(d / f"cv_{name}.yuv")
        cv2.cvtColor(yuv, back).tofile(d / f"cv_{name}.rgb")
    print(cv2.__version__)


if __name__ == "__main__":
    main()
