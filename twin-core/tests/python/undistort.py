"""Undistorts an RGB frame with OpenCV (`cv2.undistort`) and a CameraInfo's K and D (plumb_bob):
the independent check of twin's lens distortion (twin-core/tests/it/render.rs).

Usage: python undistort.py IN.raw OUT.raw '{"width": W, "height": H, "k": [9], "d": [5]}'
IN and OUT are H x W x 3 uint8, top row first.
"""
import json
import sys

import cv2
import numpy as np

src, dst, spec = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
w, h = spec["width"], spec["height"]
image = np.fromfile(src, dtype=np.uint8).reshape(h, w, 3)
k = np.array(spec["k"], dtype=np.float64).reshape(3, 3)
d = np.array(spec["d"], dtype=np.float64)
cv2.undistort(image, k, d).astype(np.uint8).tofile(dst)
