#!/usr/bin/env bash
# Issue 22, target 4: lossless raw -> .ivol conversion against `zstd -3 -T2`
# on the same raw bytes, side by side in one run, and codec 3's own encode
# and decode speed per core (build/bench/codec_bench, the thread's CPU time).
#
#   bash bench/run_codec_speed.sh --work DIR [--build DIR] [--ivol BINARY ...] [--codec-bench BINARY ...]
#                                 [--repeat N]
#
# DIR holds r.raw (256^3 float32, as bench/run_bricked.sh leaves it) and the
# 16-bit files v-f16.raw and v-u16.raw made from it (run_bricked.sh makes
# them too). Each --ivol adds a binary to compare (e.g. a build of main);
# default: the build's own; each --codec-bench likewise a codec_bench (e.g.
# bench/codec_bench.cpp linked with main's predicted_codec.cpp), run
# alternately N times. Every command runs N times (default 3),
# alternating, and the best wall time and its CPU time (user + sys) are
# printed: on a shared machine the best run is the one least disturbed.
set -euo pipefail
cd "$(dirname "$0")/.."
build=build
work=
repeat=3
binaries=()
benches=()
while [ $# -gt 0 ]; do
  case "$1" in
    --work) work=$2; shift ;;
    --build) build=$2; shift ;;
    --ivol) binaries+=("$2"); shift ;;
    --codec-bench) benches+=("$2"); shift ;;
    --repeat) repeat=$2; shift ;;
    *) echo "usage: bash bench/run_codec_speed.sh --work DIR [--build DIR] [--ivol BINARY ...] [--codec-bench BINARY ...] [--repeat N]" >&2
       exit 1 ;;
  esac
  shift
done
[ -n "$work" ] && [ -f "$work/v-u16.raw" ] || { echo "run_codec_speed: --work DIR with v-f16.raw, v-u16.raw" >&2; exit 1; }
[ ${#binaries[@]} -gt 0 ] || binaries=("$build/tools/ivol")
[ ${#benches[@]} -gt 0 ] || benches=("$build/bench/codec_bench")
out=$(mktemp -d /tmp/ivol-codec-speed.XXXXXX)
trap 'rm -rf "$out"' EXIT
size=$(/usr/bin/python3 -c "import os; print(round((os.path.getsize('$work/v-u16.raw') // 2) ** (1 / 3)))")
echo "# bench/run_codec_speed.sh ($(date -u +%FT%TZ), $(nproc) cores, $(uname -m), load $(cut -d' ' -f1-3 /proc/loadavg))"
echo "# $(zstd --version | head -1)"
# best_of LABEL OUTPUT CMD...: the best wall time of $repeat runs, its CPU time, the output's bytes.
best_of() {
  local label=$1 output=$2
  shift 2
  local best="" line
  for ((i = 0; i < repeat; i++)); do
    /usr/bin/time -o "$out/time" -f "%e %U %S" "$@" >/dev/null
    line=$(tail -1 "$out/time")
    if [ -z "$best" ] || /usr/bin/python3 -c "import sys; sys.exit(0 if ${line%% *} < ${best%% *} else 1)"; then
      best=$line
    fi
  done
  read -r wall user sys <<<"$best"
  printf "| %s | %d | %.2f | %.2f | %.0f |\n" "$label" "$(stat -c %s "$output")" "$wall" \
    "$(echo "$user + $sys" | bc)" "$(/usr/bin/python3 -c "print(2 * $size ** 3 / 1e6 / $wall)")"
}
printf "| what | bytes | wall s (best of %d) | CPU s | MB/s (wall) |\n|---|---:|---:|---:|---:|\n" "$repeat"
for kind in f16 u16; do
  raw=$work/v-$kind.raw
  best_of "$kind zstd -3 -T2" "$out/z.zst" zstd -q -f -3 -T2 "$raw" -o "$out/z.zst"
  for binary in "${binaries[@]}"; do
    best_of "$kind ivol convert ($binary)" "$out/v.ivol" "$binary" -q convert "$raw" "$out/v.ivol" \
      --dims "$size,$size,$size" --type "$kind" -f
  done
done
echo
for ((i = 0; i < repeat; i++)); do
  for bench in "${benches[@]}"; do
    echo "$bench: $("$bench" "$work/r.raw" "$size" 5 | tr '\n' ' ')"
  done
done
