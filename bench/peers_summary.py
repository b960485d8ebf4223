#!/usr/bin/env python3
"""One row per volume and way from bench/peers_codecs.py's output: ivol's
default file, ivol's smallest (the smallest of its settings; the octree of a
keep rule, which holds other voxels, left out), the smallest peer whose file
came back bit for bit, and how they compare (issue 22's table).

    python3 bench/peers_summary.py PEERS_OUTPUT.txt [...]
"""
import re
import sys


def rows(path):
    volume = None
    table = []
    for line in open(path, encoding="utf-8"):
        heading = re.match(r"## (\S+) \S+, (\S+) \(", line)
        if heading:
            volume = (heading.group(1), heading.group(2))
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if volume is None or len(cells) < 6 or not re.fullmatch(r"\d+", cells[1]):
            continue
        table.append((volume, cells[0], int(cells[1]), cells[5] == "yes"))
    return table


def main(paths):
    print("| volume | way | ivol default | ivol smallest (setting) | smallest peer | its bytes | default vs it |"
          " smallest vs it |\n|---|---|---:|---|---|---:|---:|---:|")
    won = total = 0
    for path in paths:
        table = rows(path)
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
                volume[0], volume[1], format(default, ","), format(smallest[0], ","), setting, peer[1],
                format(peer[0], ","), 100.0 * default / peer[0] - 100, 100.0 * smallest[0] / peer[0] - 100))
    print("\nivol's smallest below every peer in %d of %d rows" % (won, total))


if __name__ == "__main__":
    main(sys.argv[1:])
