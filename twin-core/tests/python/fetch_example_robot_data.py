"""Downloads the example-robot-data 6.0.0 wheel from PyPI into CACHE and extracts its robots.

Usage: python fetch_example_robot_data.py CACHE. Leaves CACHE/cmeel.prefix/share/example-robot-data
and the marker CACHE/example-robot-data-6.0.0.extracted; does nothing when the marker exists. Safe to run concurrently (a lock file in CACHE).
"""
import fcntl
import glob
import os
import subprocess
import sys
import zipfile

cache = sys.argv[1]
marker = os.path.join(cache, "example-robot-data-6.0.0.extracted")
os.makedirs(cache, exist_ok=True)
# Tests in several binaries and threads call this at once: one fetches, the others wait for it.
lock = open(os.path.join(cache, ".fetch.lock"), "w")
fcntl.flock(lock, fcntl.LOCK_EX)
if not os.path.exists(marker):
    if not glob.glob(cache + "/example_robot_data-6.0.0-*.whl"):
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "-q",
                        "example-robot-data==6.0.0", "-d", cache], check=True, timeout=900)
    for whl in glob.glob(cache + "/example_robot_data-6.0.0-*.whl"):
        with zipfile.ZipFile(whl) as z:
            z.extractall(cache, [n for n in z.namelist() if "/example-robot-data/robots/" in n])
    open(marker, "w").close()
