#!/usr/bin/env python3
"""Runs a command and samples, every 0.2 s, the disk blocks of the files it
holds open under DIR, unlinked ones included (the octree writer's spill
has no name), plus the files under DIR by name; prints the peak of their
sum and of the unnamed files alone, and the command's exit status, as JSON
on stderr. The filesystem's `df` counts every other process on a shared
machine; this counts only the command's files.
Usage: temp_disk_of.py DIR COMMAND [ARGS...]"""
import json
import os
import subprocess
import sys
import time

directory = os.path.realpath(sys.argv[1])
start = time.time()
child = subprocess.Popen(sys.argv[2:])
peak_total = peak_unnamed = peak_named = 0


def children(pid):
    out = []
    for p in os.listdir("/proc"):
        try:
            if p.isdigit() and open(f"/proc/{p}/stat").read().split()[3] == str(pid):
                out.append(int(p))
        except OSError:  # gone since listed
            pass
    return out


def sample():
    unnamed = named = 0
    seen = set()
    # Named files first: an O_TMPFILE given a name by linkat (the writer's
    # output) still reads "#inode (deleted)" through its descriptor.
    for root, _, files in os.walk(directory):
        for name in files:
            try:
                st = os.stat(os.path.join(root, name))
            except OSError:
                continue
            seen.add((st.st_dev, st.st_ino))
            named += st.st_blocks * 512
    for pid in [child.pid] + children(child.pid):
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
                if not target.startswith(directory + "/") or not target.endswith(" (deleted)"):
                    continue
                st = os.stat(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if (st.st_dev, st.st_ino) in seen:
                continue
            seen.add((st.st_dev, st.st_ino))
            unnamed += st.st_blocks * 512
    return unnamed, named


while child.poll() is None:
    unnamed, named = sample()
    peak_unnamed = max(peak_unnamed, unnamed)
    peak_named = max(peak_named, named)
    peak_total = max(peak_total, unnamed + named)
    time.sleep(0.2)
print(json.dumps({"exit": child.returncode, "seconds": round(time.time() - start, 1), "peak_bytes": peak_total,
                  "peak_unnamed_bytes": peak_unnamed, "peak_named_bytes": peak_named}), file=sys.stderr)
sys.exit(child.returncode)
