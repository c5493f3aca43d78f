"""Downloads the icub-models 3.2.0 wheel from PyPI into CACHE and extracts its share/iCub folder.

Usage: python fetch_icub_models.py CACHE. Leaves CACHE/icub-models/share/iCub (robots/*/model.urdf,
meshes: `package://iCub/...`, so CACHE/icub-models/share is the package path) and the marker
CACHE/icub-models-3.2.0.extracted; does nothing when the marker exists. Safe to run concurrently
(a lock file in CACHE).
"""
import fcntl
import glob
import os
import subprocess
import sys
import zipfile

cache = sys.argv[1]
marker = os.path.join(cache, "icub-models-3.2.0.extracted")
os.makedirs(cache, exist_ok=True)
lock = open(os.path.join(cache, ".fetch-icub.lock"), "w")
fcntl.flock(lock, fcntl.LOCK_EX)
if not os.path.exists(marker):
    if not glob.glob(cache + "/icub_models-3.2.0-*.whl"):
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "-q",
                        "icub-models==3.2.0", "-d", cache], check=True, timeout=900)
    prefix = "icub_models-3.2.0.data/data/share/"
    for whl in glob.glob(cache + "/icub_models-3.2.0-*.whl"):
        with zipfile.ZipFile(whl) as z:
            for n in z.namelist():
                if n.startswith(prefix + "iCub/") and not n.endswith("/"):
                    out = os.path.join(cache, "icub-models/share", n[len(prefix):])
                    os.makedirs(os.path.dirname(out), exist_ok=True)
                    with z.open(n) as src, open(out, "wb") as dst:
                        dst.write(src.read())
    open(marker, "w").close()
