#!/usr/bin/env bash
# Issue 20: requests and bytes a remote read costs. Serves the given .ivol
# files from the local range server (tests/support/range_http_server.py,
# loopback, no added latency) and reads from each, through `ivol extract`
# and `ivol convert --level 3`: a z, y and x slice through the centre, a
# 64^3 box at the centre and the 1/8 preview (level of detail 3), each read
# opening the file anew, so the figures include the open (header, footer,
# index, metadata). Prints a Markdown table: requests, bytes and their share
# of the file, as the server counted them, and the seconds of the read.
#
#   bash bench/remote_reads.sh [--ivol build/tools/ivol] FILE.ivol...
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
ivol=$here/../build/tools/ivol
if [ "${1:-}" = "--ivol" ]; then ivol=$2; shift 2; fi
work=$(mktemp -d /tmp/ivol-remote.XXXXXX)
server=""
trap '[ -n "$server" ] && kill "$server" 2>/dev/null; rm -rf "$work"' EXIT
mkdir "$work/served"
for f in "$@"; do ln -s "$(realpath "$f")" "$work/served/$(basename "$f")"; done
start() {
  [ -n "$server" ] && kill "$server" 2>/dev/null && wait "$server" 2>/dev/null || true
  rm -f "$work/port" "$work/counts.json"
  /usr/bin/python3 "$here/../tests/support/range_http_server.py" "$work/served" "$work/port" "$work/counts.json" &
  server=$!
  for _ in $(seq 100); do [ -s "$work/port" ] && break; sleep 0.05; done
  url="http://127.0.0.1:$(cat "$work/port")"
}
echo "# bench/remote_reads.sh ($(date -u +%FT%TZ), $(nproc) cores, $(uname -m))"
printf "| file | bytes | read | requests | bytes read | share | s |\n|---|---:|---|---:|---:|---:|---:|\n"
for f in "$@"; do
  name=$(basename "$f")
  size=$(stat -L -c %s "$f")
  dims=$("$ivol" info --json "$f" | /usr/bin/python3 -c "import json,sys; d=json.load(sys.stdin); print(*d['dimensions'])")
  read -r nx ny nz <<<"$dims"
  cx=$((nx / 2)) cy=$((ny / 2)) cz=$((nz / 2))
  declare -a names=("z slice" "y slice" "x slice" "64^3 box" "1/8 preview")
  declare -a cmds=(
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
    "$ivol" -q ${cmds[$n]//URL/$url}
    t1=$(date +%s.%N)
    /usr/bin/python3 - "$work/counts.json" "$name" "$size" "${names[$n]}" "$t0" "$t1" <<'PY'
import json, sys
counts, name, size, what, t0, t1 = sys.argv[1:]
c = json.load(open(counts))[name]
print("| %s | %d | %s | %d | %d | %.2f %% | %.2f |" % (name, int(size), what, c["requests"], c["bytes"],
      100.0 * c["bytes"] / int(size), float(t1) - float(t0)))
PY
  done
done
