#!/usr/bin/env bash
# Peak temporary disk of `ivol convert` into an octree, two binaries side by
# side (e.g. before/after a change): each run writes into a tmpfs of its own,
# whose used bytes are sampled every 5 ms (spill + output, whatever names
# they have or lack), and the files they write are compared byte for byte.
# Needs root (mount). Usage: bench/temp_disk.sh BEFORE_IVOL AFTER_IVOL [N]
set -euo pipefail
before=$1 after=$2 n=${3:-256}
work=$(mktemp -d /tmp/ivol-temp-disk.XXXXXX)
cleanup() { umount "$work"/mnt 2>/dev/null || true; rm -rf "$work"; }
trap cleanup EXIT
here=$(cd "$(dirname "$0")" && pwd)
python3 "$here/make_noisy_volume.py" "$n" "$work/in.raw"
input_bytes=$(stat -c %s "$work/in.raw")
mkdir "$work/mnt" "$work/bin"
echo "input: $n^3 u16 with noise, $input_bytes bytes"
printf '%-16s %-7s %14s %14s %14s %10s %8s\n' case binary file_bytes peak_used peak-file reported s
for mode in lossless keep; do
  args=(--dims "$n,$n,$n" --type u16 --structure octree)
  [ "$mode" = keep ] && args+=(--keep threshold=1000,margin=2)
  for which in before after; do
    bin=$before; [ "$which" = after ] && bin=$after
    ln -sf "$(readlink -f "$bin")" "$work/bin/ivol"  # one argv[0]: the provenance is the same
    mount -t tmpfs -o size=$((4 * input_bytes + (64 << 20))) tmpfs "$work/mnt"
    base=$(df -B1 --output=used "$work/mnt" | tail -1)
    peak=0
    start=$(date +%s.%N)
    (cd "$work/mnt" && env -u TMPDIR SOURCE_DATE_EPOCH=0 "$work/bin/ivol" convert -q "${args[@]}" "$work/in.raw" out.ivol > "$work/report.json"
     ) &
    pid=$!
    while kill -0 $pid 2>/dev/null; do
      used=$(df -B1 --output=used "$work/mnt" | tail -1)
      [ "$used" -gt "$peak" ] && peak=$used
      sleep 0.005
    done
    wait $pid
    seconds=$(echo "$(date +%s.%N) - $start" | bc)
    file=$(stat -c %s "$work/mnt/out.ivol")
    reported=-
    if [ "$which" = after ]; then
      (cd "$work/mnt" && env -u TMPDIR SOURCE_DATE_EPOCH=0 "$work/bin/ivol" convert -q --json -f "${args[@]}" "$work/in.raw" again.ivol \
         > "$work/report.json")
      reported=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['temp_bytes'])" "$work/report.json")
      rm "$work/mnt/again.ivol"
    fi
    cp "$work/mnt/out.ivol" "$work/$mode.$which.ivol"
    umount "$work/mnt"
    printf '%-16s %-7s %14d %14d %14d %10s %8.2f\n' "$mode" "$which" "$file" $((peak - base)) \
      $((peak - base - file)) "$reported" "$seconds"
  done
  if cmp -s "$work/$mode.before.ivol" "$work/$mode.after.ivol"; then echo "$mode: same bytes"; else echo "$mode: FILES DIFFER"; fi
done
