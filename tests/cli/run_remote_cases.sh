#!/usr/bin/env bash
# .ivol files read over HTTP by range (libformat/src/http_source.hpp), from a
# local server that answers ranges as object stores do
# (tests/support/range_http_server.py): the same voxels as the local file,
# a slice for a small share of the file's bytes in a few requests, a server
# without ranges refused, a file replaced while open refused. $IVOL is the
# binary under test.
set -u
cli_dir=$(cd "$(dirname "$0")" && pwd)
: "${IVOL:?set IVOL to the ivol binary}"
server_script=$(cd "$(dirname "$0")/../support" && pwd)/range_http_server.py
work=$(mktemp -d)
server=""
stop_server() { [ -n "$server" ] && kill "$server" 2>/dev/null && wait "$server" 2>/dev/null; server=""; }
trap 'stop_server; rm -rf "$work"' EXIT
cd "$work" || exit 1
source "$cli_dir/cases.sh"
start_server() {
  stop_server
  rm -f port counts.json
  /usr/bin/python3 "$server_script" "$work/served" port counts.json "$@" &
  server=$!
  for _ in $(seq 100); do [ -s port ] && break; sleep 0.05; done
  url="http://127.0.0.1:$(cat port)"
}
counted() { /usr/bin/python3 -c "import json; print(json.load(open('counts.json'))['$1']['$2'])"; }

mkdir served
# A scan-like volume (noise over a smooth part): a file of megabytes, not a
# phantom's few kilobytes.
/usr/bin/python3 -c "
import numpy as np
z, y, x = np.mgrid[0:160, 0:160, 0:160]
part = np.where((x - 80) ** 2 + (y - 80) ** 2 < 60 ** 2, 20000, 1000)
rng = np.random.default_rng(7)
(part + rng.integers(0, 64, part.shape)).astype('<u2').tofile('v.raw')"
"$IVOL" -q convert v.raw served/truth.ivol --dims 160,160,160 --type u16 || exit 1
size=$(stat -c %s served/truth.ivol)
nx=160 ny=160 nz=160
mid=$((nz / 2))

start_server
same_voxels() {
  "$IVOL" -q extract served/truth.ivol --box "0,0,$mid,$nx,$ny,$((mid + 1))" -o local.raw &&
    "$IVOL" -q extract "$url/truth.ivol" --box "0,0,$mid,$nx,$ny,$((mid + 1))" -o remote.raw &&
    cmp local.raw remote.raw &&
    "$IVOL" info "$url/truth.ivol" | grep -q "bricked" &&
    "$IVOL" -q convert "$url/truth.ivol" whole.raw --level 2 && "$IVOL" -q convert served/truth.ivol whole-local.raw --level 2 &&
    cmp whole.raw whole-local.raw
}
check "remote-reads-give-the-local-voxels" same_voxels

# Every kind of read, over HTTP and locally, against the source voxels: the
# bricked grid holds them losslessly; the octree keeps them where the
# object is (its own local read is the reference there, and its level of
# detail is compared with the local one).
"$IVOL" -q convert v.raw served/oct.ivol --dims 160,160,160 --type u16 --structure octree \
  --keep threshold=otsu,margin=2 || exit 1
boxes=("0,0,80,160,160,81" "0,80,0,160,81,160" "80,0,0,81,160,160" "47,51,60,111,115,124" "0,0,0,160,160,160")
reads_match() {
  local file box n=0
  for file in truth.ivol oct.ivol; do
    for box in "${boxes[@]}"; do
      "$IVOL" -q extract "$url/$file" --box "$box" -o remote.raw -f &&
        "$IVOL" -q extract "served/$file" --box "$box" -o local.raw -f && cmp local.raw remote.raw || return 1
      if [ "$file" = truth.ivol ]; then
        /usr/bin/python3 -c "
import numpy as np, sys
x0, y0, z0, x1, y1, z1 = map(int, '$box'.split(','))
v = np.fromfile('v.raw', dtype='<u2').reshape(160, 160, 160)[z0:z1, y0:y1, x0:x1]
got = np.fromfile('remote.raw', dtype='<u2').reshape(v.shape)
sys.exit(0 if np.array_equal(got, v) else 1)" || { echo "$file $box differs from the source"; return 1; }
      fi
      n=$((n + 1))
    done
    "$IVOL" -q convert "$url/$file" remote.raw --level 2 -f && "$IVOL" -q convert "served/$file" local.raw --level 2 -f &&
      cmp local.raw remote.raw || return 1
  done
  echo "$n reads and 2 levels of detail the same over HTTP"
}
check "remote-reads-match-the-source" reads_match

# Requests and bytes of one read, as the server counted them (the open
# included): the blocks a read touches are planned first and fetched
# together, adjacent ranges merged. The bounds are the figures measured
# with planning and merging, plus a little: a read that fetched block by
# block (one request per block, 25 for a z slice of the bricked file), or
# whole pages around every block, fails them.
costs() {
  local file=$1 box=$2 max_requests=$3 max_percent=$4
  shift 4
  start_server "$@"
  "$IVOL" -q extract "$url/$file" --box "$box" -o cost.raw -f || return 1
  local size requests bytes
  size=$(stat -c %s "served/$file")
  requests=$(counted "$file" requests)
  bytes=$(counted "$file" bytes)
  echo "$file $box: $requests requests (at most $max_requests), $bytes of $size bytes" \
    "($((100 * bytes / size)) %, at most $max_percent %)"
  [ "$requests" -le "$max_requests" ] && [ $((100 * bytes)) -le $((max_percent * size)) ]
}
# The open: the file's first 16 KiB, the footer with the 16 KiB before it
# (this file's index of 4 KiB among them), nothing more: 32,800 bytes in 2
# requests (107,372 when each end was a 64 KiB page).
open_costs() {
  start_server
  "$IVOL" info "$url/truth.ivol" >/dev/null || return 1
  echo "open: $(counted truth.ivol requests) requests, $(counted truth.ivol bytes) bytes"
  [ "$(counted truth.ivol requests)" -le 2 ] && [ "$(counted truth.ivol bytes)" -le 40000 ]
}
check "open-reads-both-ends-exactly" open_costs
check "bricked-z-slice-requests-and-bytes" costs truth.ivol 0,0,80,160,160,81 4 25
check "bricked-x-slice-requests-and-bytes" costs truth.ivol 80,0,0,81,160,160 30 25
check "bricked-box-requests-and-bytes" costs truth.ivol 47,51,60,111,115,124 13 26
check "octree-z-slice-requests-and-bytes" costs oct.ivol 0,0,80,160,160,81 26 24
check "octree-x-slice-requests-and-bytes" costs oct.ivol 80,0,0,81,160,160 28 40
check "octree-box-requests-and-bytes" costs oct.ivol 47,51,60,111,115,124 22 39
# The server answers several ranges to a request (multipart/byteranges, as
# nginx does, and says it is nginx): a y or x slice of the bricked file meets
# 25 separate bricks in 5 layers, all planned at once and fetched in one
# request after the open's two (7 requests when a layer was planned at a
# time, one request each; grid_copy.hpp). A server
# that does not (S3: the whole file, 200) is not asked (its Server header);
# asked anyway (IVOL_HTTP_MULTIRANGE=1), its answer is cut short and the
# ranges go one to a request, the voxels the same.
check "bricked-x-slice-several-ranges-a-request" costs truth.ivol 80,0,0,81,160,160 3 25
check "bricked-y-slice-several-ranges-a-request" costs truth.ivol 0,80,0,160,81,160 3 25
check "bricked-x-slice-object-store-one-range-a-request" costs truth.ivol 80,0,0,81,160,160 30 25 --single-range
several_refused_then_single() {
  start_server --single-range
  IVOL_HTTP_MULTIRANGE=1 "$IVOL" -q extract "$url/truth.ivol" --box 80,0,0,81,160,160 -o forced.raw -f &&
    "$IVOL" -q extract served/truth.ivol --box 80,0,0,81,160,160 -o forced-local.raw -f && cmp forced.raw forced-local.raw &&
    [ "$(counted truth.ivol requests)" -le 31 ]
}
check "several-ranges-refused-then-one-a-request" several_refused_then_single

# A server that ignores ranges: the whole file in one response is used,
# once, with a warning, when it fits the HTTP cache; a larger one is refused
# (limit-exceeded) rather than downloaded whole again and again.
whole_once() {
  start_server --no-ranges
  "$IVOL" -q extract "$url/truth.ivol" --box "0,0,$mid,$nx,$ny,$((mid + 1))" -o nr.raw 2>err
  local status=$?
  cat err
  "$IVOL" -q extract served/truth.ivol --box "0,0,$mid,$nx,$ny,$((mid + 1))" -o nr-local.raw &&
    [ "$status" -eq 0 ] && cmp nr.raw nr-local.raw && grep -q "the server ignores range requests, so the whole file" err &&
    [ "$(counted truth.ivol requests)" -eq 1 ] && [ "$(counted truth.ivol bytes)" -eq "$size" ]
}
check "a-server-without-ranges-is-used-once-with-a-warning" whole_once
refused_without_ranges() {
  start_server --no-ranges
  IVOL_HTTP_CACHE_MIB=1 "$IVOL" -q extract "$url/truth.ivol" --box 0,0,0,4,4,4 -o nr1.raw 2>err
  local status=$?
  cat err
  [ "$status" -eq 2 ] && grep -q "(limit-exceeded).*does not answer range requests (HTTP 200), and the file is larger than the 1 MiB" err &&
    [ ! -e nr1.raw ]
}
check "a-server-without-ranges-is-refused-beyond-the-cache" refused_without_ranges

refused_when_replaced() {
  start_server --change-after 1
  "$IVOL" -q convert "$url/truth.ivol" ch.raw 2>err
  local status=$?
  cat err
  [ "$status" -eq 2 ] && grep -q "changed on the server while it was open" err && [ ! -e ch.raw ]
}
check "a-file-replaced-while-open-is-refused" refused_when_replaced

missing() {
  start_server
  "$IVOL" -q info "$url/nothing.ivol" 2>err
  local status=$?
  cat err
  [ "$status" -eq 2 ] && grep -q "nothing.ivol: HTTP 404" err
}
check "a-missing-file-names-the-status" missing

# A connection lost mid-block, or a busy server, is tried again; a fault
# that lasts is an error naming the attempts, and nothing is written.
"$IVOL" -q convert served/truth.ivol local-whole.raw || exit 1
retried() {
  start_server "$@"
  rm -f rt.raw
  IVOL_HTTP_RETRIES=3 "$IVOL" -q convert "$url/truth.ivol" rt.raw && cmp rt.raw local-whole.raw
}
check "a-dropped-connection-is-retried" retried --drop 3
check "a-busy-server-is-retried" retried --busy 3
lasting_fault() {
  start_server --drop 100000
  IVOL_HTTP_RETRIES=2 "$IVOL" -q convert "$url/truth.ivol" lf.raw 2>err
  local status=$?
  cat err
  [ "$status" -eq 2 ] && grep -q "after 3 attempts: Transferred a partial file" err && [ ! -e lf.raw ]
}
check "a-lasting-fault-names-the-attempts" lasting_fault
forbidden() {
  start_server --forbid truth.ivol
  "$IVOL" -q info "$url/truth.ivol" 2>err
  local status=$?
  cat err
  [ "$status" -eq 2 ] && grep -q "truth.ivol: HTTP 403 (access denied" err
}
check "a-forbidden-file-names-the-status" forbidden

# s3:// paths signed with AWS Signature Version 4 by libcurl, checked by a
# server that recomputes each signature with botocore (path-style, on the
# endpoint AWS_ENDPOINT_URL names); wrong or missing credentials get S3's
# 403. Needs Debian's python3-botocore.
if /usr/bin/python3 -c "import botocore" 2>/dev/null; then
  s3_env=(AWS_ENDPOINT_URL= AWS_REGION=eu-west-1 AWS_ACCESS_KEY_ID=AKIDIVOLTEST AWS_SECRET_ACCESS_KEY=s3cr3t/key+1)
  signed_reads() {
    start_server --sigv4 "AKIDIVOLTEST:s3cr3t/key+1:eu-west-1$1"
    s3_env[0]=AWS_ENDPOINT_URL=$url
    rm -f s3.raw s3-slice.raw local-slice.raw
    env "${s3_env[@]}" ${1:+AWS_SESSION_TOKEN=${1#:}} "$IVOL" -q convert s3://archive/truth.ivol s3.raw &&
      cmp s3.raw local-whole.raw &&
      env "${s3_env[@]}" ${1:+AWS_SESSION_TOKEN=${1#:}} "$IVOL" -q extract s3://archive/oct.ivol \
        --box "0,0,$mid,$nx,$ny,$((mid + 1))" -o s3-slice.raw &&
      "$IVOL" -q extract served/oct.ivol --box "0,0,$mid,$nx,$ny,$((mid + 1))" -o local-slice.raw &&
      cmp s3-slice.raw local-slice.raw
  }
  check "s3-signed-reads-match-the-local-file" signed_reads ""
  check "s3-signed-reads-with-a-session-token" signed_reads ":FQoGZXIvYXdzEJr//token"
  unsigned_refused() {
    start_server --sigv4 "AKIDIVOLTEST:s3cr3t/key+1:eu-west-1"
    AWS_ENDPOINT_URL=$url AWS_REGION=eu-west-1 AWS_ACCESS_KEY_ID=AKIDIVOLTEST AWS_SECRET_ACCESS_KEY=wrong \
      "$IVOL" -q info s3://archive/truth.ivol 2>err
    local wrong=$?
    env -u AWS_ACCESS_KEY_ID -u AWS_SECRET_ACCESS_KEY AWS_ENDPOINT_URL="$url" "$IVOL" -q info s3://archive/truth.ivol 2>>err
    local unsigned=$?
    AWS_ACCESS_KEY_ID=AKIDIVOLTEST "$IVOL" -q info s3://archive/truth.ivol 2>>err
    local half=$?
    cat err
    [ "$wrong" -eq 2 ] && [ "$unsigned" -eq 2 ] && [ "$half" -eq 2 ] && [ "$(grep -c "HTTP 403" err)" -eq 2 ] &&
      grep -q "AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY must be set together" err
  }
  check "s3-wrong-or-missing-credentials-are-refused" unsigned_refused
else
  echo "skip s3 cases: python3-botocore is not installed"
fi

finish
