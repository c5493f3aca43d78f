"""Renders an MJCF with MuJoCo's own Python `Renderer` (MUJOCO_GL=egl): the independent reference
that twin's renderer (twin_core::mj::Renderer) is compared against, and its timing.

Usage: python render_reference.py SCENE.xml WIDTH HEIGHT CAMERA OUT_DIR FRAMES [QPOS_FILE]
  CAMERA: a camera name, or -1 for MuJoCo's default free camera.
  QPOS_FILE: little-endian float64 qpos to set before mj_forward (default: the model's qpos0).
Writes into OUT_DIR, top row first (as the Python Renderer returns them):
  rgb_shadows.raw    uint8 H x W x 3, MuJoCo's default flags (shadows and reflections on)
  rgb_plain.raw      uint8 H x W x 3, shadows and reflections off
  rgb_plain_aliased.raw  the same without multisampling (<visual><quality offsamples="0">)
  depth.raw          float32 H x W, metres
  segmentation.raw   int32 H x W x 2 (object id, object type; -1 background)
and prints JSON: the mean milliseconds a frame of each kind over FRAMES renders (after one warm-up).
"""
import json
import os
import sys
import time

os.environ.setdefault("MUJOCO_GL", "egl")
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

scene, width, height, camera, out_dir, frames = sys.argv[1:7]
width, height, frames = int(width), int(height), int(frames)
camera = -1 if camera == "-1" else camera
model = mujoco.MjModel.from_xml_path(scene)
data = mujoco.MjData(model)
if len(sys.argv) > 7:
    data.qpos[:] = np.fromfile(sys.argv[7], dtype="<f8")
mujoco.mj_forward(model, data)
# The offscreen buffer must hold the image (twin grows it; the Python Renderer refuses).
model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
model.vis.global_.offheight = max(model.vis.global_.offheight, height)
renderer = mujoco.Renderer(model, height, width)


def timed(render):
    render()
    start = time.perf_counter()
    for _ in range(frames):
        out = render()
    return out, (time.perf_counter() - start) * 1e3 / max(frames, 1)


def rgb():
    renderer.update_scene(data, camera)
    return renderer.render()


ms = {}
image, ms["rgb_shadows"] = timed(rgb)
image.astype(np.uint8).tofile(os.path.join(out_dir, "rgb_shadows.raw"))
renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
image, ms["rgb_plain"] = timed(rgb)
image.astype(np.uint8).tofile(os.path.join(out_dir, "rgb_plain.raw"))
aliased_model = mujoco.MjModel.from_xml_path(scene)
aliased_model.vis.global_.offwidth = model.vis.global_.offwidth
aliased_model.vis.global_.offheight = model.vis.global_.offheight
aliased_model.vis.quality.offsamples = 0
aliased = mujoco.Renderer(aliased_model, height, width)
aliased.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
aliased.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0


def rgb_aliased():
    aliased.update_scene(data, camera)
    return aliased.render()


image, ms["rgb_plain_aliased"] = timed(rgb_aliased)
image.astype(np.uint8).tofile(os.path.join(out_dir, "rgb_plain_aliased.raw"))
renderer.enable_depth_rendering()
image, ms["depth"] = timed(rgb)
image.astype("<f4").tofile(os.path.join(out_dir, "depth.raw"))
renderer.disable_depth_rendering()
renderer.enable_segmentation_rendering()
image, ms["segmentation"] = timed(rgb)
image.astype("<i4").tofile(os.path.join(out_dir, "segmentation.raw"))
print(json.dumps({"ms": ms, "mujoco": mujoco.__version__}))
