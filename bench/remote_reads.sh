#!/usr/bin/env bash
# Issue 20: requests and bytes a remote read costs. Serves the given .ivol
# files from the local range server (tests/support/range_http_server.py,
# loopback; --latency MS delays every response by MS milliseconds, a
# distant store's round trip) and reads from each, through `ivol info`,
# `ivol extract` and `ivol convert --level 3`: the open alone, a z, y and x
# slice through the centre, a 64^3 box at the centre and the 1/8 preview
# (level of detail 3), each read opening the file anew, so the figures
# include the open (header, footer, index, metadata). Where FILE.h5 lies
# beside FILE.ivol (ivol's HDF5 export), the same reads go through HDF5's
# ROS3 driver (h5py, the preview as a [::8, ::8, ::8] read), and a last row
# fetches the whole .ivol in one request. Prints a Markdown table:
# requests, bytes and their share of the file, as the server counted them,
# and the seconds of the read.
#
#   bash bench/remote_reads.sh [--ivol build/tools/ivol] [--latency MS] FILE.ivol...
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
ivol=$here/../build/tools/ivol
latency=0
while [ $# -gt 0 ]; do
  case $1 in
    --ivol) ivol=$2; shift 2 ;;
    --latency) latency=$2; shift 2 ;;
    *) break ;;
  esac
done
work=$(mktemp -d /tmp/ivol-remote.XXXXXX)
server=""
trap '[ -n "$server" ] && kill "$server" 2>/dev/null; rm -rf "$work"' EXIT
mkdir "$work/served"
for f in "$@"; do
  ln -s "$(realpath "$f")" "$work/served/$(basename "$f")"
  [ -e "${f%.ivol}.h5" ] && ln -s "$(realpath "${f%.ivol}.h5")" "$work/served/$(basename "${f%.ivol}.h5")"
done
start() {
  [ -n "$server" ] && kill "$server" 2>/dev/null && wait "$server" 2>/dev/null || true
  rm -f "$work/port" "$work/counts.json"
  /usr/bin/python3 "$here/../tests/support/range_http_server.py" "$work/served" "$work/port" "$work/counts.json" \
    --delay-ms "$latency" &
  server=$!
  for _ in $(seq 100); do [ -s "$work/port" ] && break; sleep 0.05; done
  url="http://127.0.0.1:$(cat "$work/port")"
}
echo "# bench/remote_reads.sh ($(date -u +%FT%TZ), $(nproc) cores, $(uname -m), latency $latency ms a response)"
printf "| file | bytes | read | requests | bytes read | share | s |\n|---|---:|---|---:|---:|---:|---:|\n"
for f in "$@"; do
  name=$(basename "$f")
  size=$(stat -L -c %s "$f")
  dims=$("$ivol" info --json "$f" | /usr/bin/python3 -c "import json,sys; d=json.load(sys.stdin); print(*d['dimensions'])")
  read -r nx ny nz <<<"$dims"
  cx=$((nx / 2)) cy=$((ny / 2)) cz=$((nz / 2))
  declare -a names=("open (info)" "z slice" "y slice" "x slice" "64^3 box" "1/8 preview")
  declare -a cmds=(
    "info URL/$name"
    "extract URL/$name --box 0,0,$cz,$nx,$ny,$((cz + 1)) -o $work/out.raw -f"
    "extract URL/$name --box 0,$cy,0,$nx,$((cy + 1)),$nz -o $work/out.raw -f"
    "extract URL/$name --box $cx,0,0,$((cx + 1)),$ny,$nz -o $work/out.raw -f"
    "extract URL/$name --box $((cx - 32)),$((cy - 32)),$((cz - 32)),$((cx + 32)),$((cy + 32)),$((cz + 32)) -o $work/out.raw -f"
    "convert URL/$name $work/out.raw --level 3 -f"
  )
  for n in "${!names[@]}"; do
    start
    t0=$(date +%s.%N)
    # shellcheck disable=SC2086
    "$ivol" -q ${cmds[$n]//URL/$url} >/dev/null
    t1=$(date +%s.%N)
    /usr/bin/python3 - "$work/counts.json" "$name" "$size" "${names[$n]}" "$t0" "$t1" <<'PY'
import json, sys
counts, name, size, what, t0, t1 = sys.argv[1:]
c = json.load(open(counts))[name]
print("| %s | %d | %s | %d | %d | %.2f %% | %.2f |" % (name, int(size), what, c["requests"], c["bytes"],
      100.0 * c["bytes"] / int(size), float(t1) - float(t0)))
PY
  done
  h5=${name%.ivol}.h5
  if [ -e "$work/served/$h5" ]; then
    h5size=$(stat -L -c %s "$work/served/$h5")
    for what in "open (info)" "z slice" "y slice" "x slice" "64^3 box" "1/8 preview"; do
      start
      /usr/bin/python3 - "$url/$h5" "$what" "$work/counts.json" "$h5" "$h5size" <<'PY'
import json, sys, time
import h5py
url, what, counts, name, size = sys.argv[1:]
t0 = time.time()
with h5py.File(url, "r", driver="ros3") as f:
    found = []
    f.visititems(lambda key, item: found.append(item) if isinstance(item, h5py.Dataset) and item.ndim == 3 else None)
    d = found[0]  # ivol's export: /exchange/data
    z, y, x = (n // 2 for n in d.shape)
    read = {"open (info)": lambda: d.shape, "z slice": lambda: d[z], "y slice": lambda: d[:, y],
            "x slice": lambda: d[:, :, x], "64^3 box": lambda: d[z - 32:z + 32, y - 32:y + 32, x - 32:x + 32],
            "1/8 preview": lambda: d[::8, ::8, ::8]}[what]
    read()
t1 = time.time()
time.sleep(0.3)  # the server rewrites its counts after each response
c = json.load(open(counts))[name]
print("| %s (HDF5 ROS3) | %d | %s | %d | %d | %.2f %% | %.2f |" % (name, int(size), what, c["requests"], c["bytes"],
      100.0 * c["bytes"] / int(size), t1 - t0))
PY
    done
  fi
  start
  t0=$(date +%s.%N)
  curl -s -o "$work/whole" "$url/$name"
  t1=$(date +%s.%N)
  printf "| %s | %d | whole file (curl) | 1 | %d | 100 %% | %.2f |\n" "$name" "$size" "$size" "$(echo "$t1 - $t0" | bc -l)"
  rm -f "$work/whole"
done
