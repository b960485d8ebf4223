#!/usr/bin/env python3
"""One row per volume and way from bench/peers_codecs.py's output: ivol's
default file, ivol's smallest (the smallest of its settings; the octree of a
keep rule, which holds other voxels, left out), the smallest peer whose file
came back bit for bit, and how they compare (issue 22's table).

    python3 bench/peers_summary.py PEERS_OUTPUT.txt [...]

Several outputs may hold the same scan (its --work): their tables are
merged, so that a run of some methods (--only) adds to a run of all.
"""
import re
import sys


def rows(path):
    """(scan, volume, way) -> the table's rows; the scan is the run's --work."""
    scan = volume = None
    table = []
    for line in open(path, encoding="utf-8"):
        work = re.match(r"# bench/peers_codecs.py --work (\S+)", line)
        if work:
            scan = work.group(1)
            continue
        heading = re.match(r"## (\S+) \S+, (\S+) \(", line)
        if heading:
            volume = (scan, heading.group(1), heading.group(2))
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if volume is None or len(cells) < 6 or not re.fullmatch(r"\d+", cells[1]):
            continue
        table.append((volume, cells[0], int(cells[1]), cells[5] == "yes"))
    return table


def main(paths):
    print("| volume | way | ivol default | ivol smallest (setting) | smallest peer | its bytes | default vs it |"
          " smallest vs it |\n|---|---|---:|---|---|---:|---:|---:|")
    # The runs' tables merged (a run of every method and one of --only some
    # add up), volumes in the order first seen.
    table = [row for path in paths for row in rows(path)]
    won = total = 0
    for volume in dict.fromkeys(v for v, _, _, _ in table):
        mine = [(b, m) for v, m, b, ok in table if v == volume and m.startswith("ivol") and "--keep" not in m]
        peers = [(b, m) for v, m, b, ok in table if v == volume and not m.startswith("ivol") and ok]
        if not mine or not peers:
            continue
        default = mine[0][0]
        smallest = min(mine)
        peer = min(peers)
        setting = "default" if smallest[1] == mine[0][1] else smallest[1].split(",", 1)[1].strip()
        total += 1
        won += smallest[0] < peer[0]
        print("| %s | %s | %s | %s (`%s`) | %s | %s | %+.2f %% | **%+.2f %%** |" % (
            volume[1], volume[2], format(default, ","), format(smallest[0], ","), setting, peer[1],
            format(peer[0], ","), 100.0 * default / peer[0] - 100, 100.0 * smallest[0] / peer[0] - 100))
    print("\nivol's smallest below every peer in %d of %d rows" % (won, total))


if __name__ == "__main__":
    main(sys.argv[1:])
