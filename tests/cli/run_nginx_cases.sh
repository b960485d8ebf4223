#!/usr/bin/env bash
# .ivol files read from a real web server: Debian's nginx, started on a
# loopback port with a temporary configuration (and stopped at the end).
# Every conformance vector reads over HTTP as it reads locally, bit for bit
# (and an invalid one fails with the same error class); requests and bytes of
# a slice, a box and a preview are counted from nginx's own access log; 404,
# 403, a location without byte ranges, and a file replaced during a read give
# errors that say so, with nothing written. (A connection dropped mid-block
# needs a server that misbehaves on purpose: run_remote_cases.sh.) Exits 77
# (skipped) where nginx is not installed. $IVOL is the binary under test.
set -u
: "${IVOL:?set IVOL to the ivol binary}"
cli_dir=$(cd "$(dirname "$0")" && pwd)
vectors=$(cd "$cli_dir/../../format-spec/vectors" && pwd)
nginx=$(command -v nginx || echo /usr/sbin/nginx)
[ -x "$nginx" ] || { echo "skip: nginx is not installed (scripts/install-deps.sh installs nginx-light)"; exit 77; }
work=$(mktemp -d)
chmod 755 "$work"  # nginx's workers may run as another user
trap '[ -s "$work/nginx.pid" ] && kill "$(cat "$work/nginx.pid")" 2>/dev/null; rm -rf "$work"' EXIT
cd "$work" || exit 1
source "$cli_dir/cases.sh"

mkdir -p www/vectors www/private tmp
cp "$vectors"/valid/*.ivol "$vectors"/invalid/*.ivol www/vectors/
port=$(/usr/bin/python3 -c "import socket; s = socket.socket(); s.bind(('127.0.0.1', 0)); print(s.getsockname()[1])")
cat >nginx.conf <<CONF
worker_processes 2;
pid $work/nginx.pid;
error_log $work/error.log;
events { worker_connections 256; }
http {
  log_format counted '\$uri \$status \$body_bytes_sent "\$http_range"';
  access_log $work/access.log counted;
  client_body_temp_path $work/tmp/body;
  proxy_temp_path $work/tmp/proxy;
  fastcgi_temp_path $work/tmp/fastcgi;
  uwsgi_temp_path $work/tmp/uwsgi;
  scgi_temp_path $work/tmp/scgi;
  default_type application/octet-stream;
  server {
    listen 127.0.0.1:$port;
    root $work/www;
    location /private/ { deny all; }
    location /whole/ { alias $work/www/; max_ranges 0; }
    location /slow/ { alias $work/www/; limit_rate 8k; }
  }
}
CONF
"$nginx" -p "$work" -c "$work/nginx.conf" -e "$work/error.log" 2>nginx.err || {
  cat nginx.err
  echo "FAIL nginx did not start"
  exit 1
}
url="http://127.0.0.1:$port"
for _ in $(seq 100); do curl -s -o /dev/null "$url/" && break; sleep 0.05; done
chmod -R a+rX www

# Every vector: a valid one converts to the same bytes over HTTP as locally
# (and verifies); an invalid one fails with the same exit status and error
# class as locally.
error_class() { grep -o "error ([a-z-]*)" "$1" | head -1; }
vectors_match() {
  local bad=0 f name
  for f in www/vectors/*.ivol; do
    name=$(basename "$f")
    "$IVOL" -q convert "$f" "local-$name.raw" -f 2>local.err
    local want=$?
    "$IVOL" -q convert "$url/vectors/$name" "remote-$name.raw" -f 2>remote.err
    local got=$?
    if [ "$want" -ne "$got" ]; then
      echo "$name: exit $got over HTTP, $want locally"; cat remote.err local.err; bad=1
    elif [ "$want" -eq 0 ] && ! cmp -s "local-$name.raw" "remote-$name.raw"; then
      echo "$name: different bytes over HTTP"; bad=1
    elif [ "$want" -ne 0 ] && [ "$(error_class local.err)" != "$(error_class remote.err)" ]; then
      echo "$name: $(error_class remote.err) over HTTP, $(error_class local.err) locally"; bad=1
    fi
    rm -f "local-$name.raw" "remote-$name.raw"
  done
  [ "$bad" -eq 0 ]
}
check "every-vector-reads-over-http-as-locally" vectors_match

# Larger files of each structure, and random boxes of them.
/usr/bin/python3 -c "
import numpy as np
z, y, x = np.mgrid[0:96, 0:96, 0:96]
part = np.where((x - 48) ** 2 + (y - 40) ** 2 < 30 ** 2, 20000, 1000)
rng = np.random.default_rng(3)
(part + rng.integers(0, 64, part.shape)).astype('<u2').tofile('v.raw')"
"$IVOL" -q convert v.raw www/bricked.ivol --dims 96,96,96 --type u16 || exit 1
"$IVOL" -q convert v.raw www/octree.ivol --dims 96,96,96 --type u16 --structure octree \
  --keep threshold=otsu,margin=2 || exit 1
"$IVOL" -q convert v.raw www/bricked16.ivol --dims 96,96,96 --type u16 --brick 16 || exit 1
chmod a+r www/*.ivol
random_boxes() {
  local f box
  for f in bricked bricked16 octree; do
    for box in $(/usr/bin/python3 -c "
import random
random.seed(11)
for _ in range(6):
    lo = [random.randrange(0, 95) for _ in range(3)]
    hi = [random.randrange(l + 1, 97) for l in lo]
    print(','.join(map(str, lo + hi)))"); do
      "$IVOL" -q extract "www/$f.ivol" --box "$box" -o l.raw -f && "$IVOL" -q extract "$url/$f.ivol" --box "$box" -o r.raw -f &&
        cmp l.raw r.raw || { echo "$f $box differs"; return 1; }
    done
  done
}
check "random-boxes-read-over-http-as-locally" random_boxes

# Requests and bytes as nginx logged them (the open included). Bounds: what
# the reader fetches with planning and merging, with a little room, on files
# this small (a 96³ volume: a 32³ brick is a third of a side, an octree
# block of 8192 values a large part of the file); a reader that fetched the
# whole file, or block by block, fails them. The 512³ figures are
# bench/remote_reads.sh's.
costs() {  # costs FILE READ-ARGUMENTS... : prints "requests bytes"
  local file=$1
  shift
  : >access.log
  kill -USR1 "$(cat nginx.pid)"  # reopen the log
  sleep 0.2
  "$IVOL" -q "$@" >/dev/null || return 1
  sleep 0.2
  awk -v f="/$file" '$1 == f { n++; b += $3 } END { print n + 0, b + 0 }' access.log
}
within() {  # within NAME FILE MAX-REQUESTS MAX-PERCENT READ-ARGUMENTS...
  local file=$2 max_requests=$3 max_percent=$4
  shift 4
  local got size
  got=$(costs "$file" "$@") || return 1
  size=$(stat -c %s "www/$file")
  echo "$file: $got (requests, bytes) of $size bytes"
  /usr/bin/python3 -c "
import sys
n, b = map(int, sys.argv[1].split()); size = int(sys.argv[2])
sys.exit(0 if 0 < n <= int(sys.argv[3]) and 0 < b <= float(sys.argv[4]) / 100 * size else 1)" "$got" "$size" "$max_requests" "$max_percent"
}
check "nginx-log-bricked-z-slice" within x bricked.ivol 4 50 extract "$url/bricked.ivol" --box 0,0,48,96,96,49 -o s.raw -f
check "nginx-log-bricked16-z-slice" within x bricked16.ivol 4 35 extract "$url/bricked16.ivol" --box 0,0,48,96,96,49 -o s.raw -f
# An x slice meets 6 separate bricks in each of 6 layers: nginx answers a
# layer's bricks in one multipart/byteranges response.
check "nginx-log-bricked16-x-slice-several-ranges" within x bricked16.ivol 8 35 extract "$url/bricked16.ivol" --box 48,0,0,49,96,96 -o s.raw -f
check "nginx-log-octree-z-slice" within x octree.ivol 10 60 extract "$url/octree.ivol" --box 0,0,48,96,96,49 -o s.raw -f
check "nginx-log-octree-box" within x octree.ivol 10 65 extract "$url/octree.ivol" --box 30,30,30,62,62,62 -o b.raw -f
check "nginx-log-octree-preview" within x octree.ivol 8 25 convert "$url/octree.ivol" p.raw --level 2 -f
# An archive re-encoded from where it lies (ivol convert URL OUT.ivol): the
# same file as from the local copy but for the provenance (the source's
# address and size, no SHA-256: the file is read by ranges, not downloaded);
# the whole file read once, in a few requests.
reencoded_over_http() {
  "$IVOL" -q convert "$url/octree.ivol" remote-again.ivol -f && "$IVOL" -q convert www/octree.ivol local-again.ivol -f &&
    "$IVOL" -q convert remote-again.ivol remote-again.raw -f && "$IVOL" -q convert local-again.ivol local-again.raw -f &&
    cmp remote-again.raw local-again.raw &&
    "$IVOL" info --json remote-again.ivol | grep -q '"sha256_omitted"' &&
    "$IVOL" info --json remote-again.ivol | grep -q "\"path\": \"$url/octree.ivol\""
}
check "nginx-reencode-as-locally" reencoded_over_http
check "nginx-log-reencode" within x octree.ivol 12 110 convert "$url/octree.ivol" again.ivol -f

refused() {  # refused NAME TEXT COMMAND...: exit 2, TEXT in the error, no output file
  local text=$2
  shift 2
  rm -f out.raw
  "$IVOL" -q "$@" 2>err
  local status=$?
  cat err
  [ "$status" -eq 2 ] && grep -q -- "$text" err && [ ! -e out.raw ]
}
check "nginx-404-is-named" refused x "nothing.ivol: HTTP 404 (no such file" convert "$url/nothing.ivol" out.raw
cp www/bricked.ivol www/private/ && chmod a+r www/private/bricked.ivol
check "nginx-403-is-named" refused x "HTTP 403 (access denied" convert "$url/private/bricked.ivol" out.raw
whole_with_warning() {
  rm -f out.raw
  "$IVOL" -q convert "$url/whole/bricked.ivol" out.raw 2>err && "$IVOL" -q convert www/bricked.ivol local.raw -f &&
    cmp out.raw local.raw && grep -q "the server ignores range requests" err
}
check "nginx-without-ranges-is-read-once-with-a-warning" whole_with_warning
# A file replaced on the server during a read (nginx's ETag is its mtime and
# size): the read, throttled to 8 KiB/s a connection, ends with an error, never mixed data.
# The open's first 16 KiB take 2 s, so the change lands before the requests
# that follow (a read that planned every brick at once, within the open's
# first half second, would get the old file whole and consistent).
replaced_during_read() {
  rm -f out.raw
  IVOL_HTTP_CACHE_MIB=1 "$IVOL" -q convert "$url/slow/bricked.ivol" out.raw 2>err &
  local reader=$!
  sleep 0.5
  touch -d "1 minute" www/bricked.ivol
  wait "$reader"
  local status=$?
  cat err
  [ "$status" -eq 2 ] && grep -q "changed on the server while it was open" err && [ ! -e out.raw ]
}
check "nginx-file-replaced-during-a-read-is-refused" replaced_during_read

finish
