#!/usr/bin/env bash
# Interrupted runs (README, "Errors and exit codes"): SIGINT (Ctrl-C),
# SIGTERM (`timeout`, a batch system's limit) or SIGHUP while an output is
# being written ends the command by that signal and leaves nothing behind: no
# temporary file beside the output, no output, and a file that was there
# before (-f) untouched. Each signal is sent once the output's temporary
# file exists, so that it arrives in the middle of the writing.
set -u
cli_dir=$(cd "$(dirname "$0")" && pwd)
: "${IVOL:?set IVOL to the ivol binary}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
source "$cli_dir/cases.sh"  # check NAME CONDITION-COMMAND...

/usr/bin/python3 "$cli_dir/../../bench/make_noisy_volume.py" 160 "$work/noisy.raw"
"$IVOL" -q convert "$work/noisy.raw" "$work/noisy.ivol" --dims 160,160,160 --type u16
"$IVOL" -q phantom pencil-holder -o "$work/scan.h5" --views 360 --detector 128

# interrupt SIGNAL OUTPUT CMD...: runs CMD, sends SIGNAL once OUTPUT's
# temporary file (".NAME.tmp-*" beside it) exists, and checks that CMD died
# of it and left no temporary file; the caller checks OUTPUT.
interrupt() {
  local signal=$1 output=$2
  shift 2
  local dir name pid status number
  dir=$(dirname "$output")
  name=$(basename "$output")
  "$@" >"$work/log" 2>&1 &
  pid=$!
  for _ in $(seq 3000); do  # up to 30 s
    compgen -G "$dir/.$name.tmp-*" >/dev/null && break
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.01
  done
  if ! compgen -G "$dir/.$name.tmp-*" >/dev/null; then
    wait "$pid"
    echo "the run ended (exit $?) before its temporary file appeared: make the input larger"
    return 1
  fi
  kill -s "$signal" "$pid"
  wait "$pid"
  status=$?
  number=$(kill -l "$signal")
  [ "$status" -eq $((128 + number)) ] || { echo "exit $status, not killed by SIG$signal"; cat "$work/log"; return 1; }
  if compgen -G "$dir/.$name.tmp-*" >/dev/null; then
    echo "left:" "$dir"/."$name".tmp-*
    return 1
  fi
}

mkdir -p "$work/out"
for signal in INT TERM HUP; do
  check "convert-to-tif-$signal" interrupt "$signal" "$work/out/v.tif" "$IVOL" -q convert "$work/noisy.ivol" "$work/out/v.tif"
  check "convert-to-tif-$signal-no-output" [ ! -e "$work/out/v.tif" ]
  check "recon-$signal" interrupt "$signal" "$work/out/r.ivol" \
    "$IVOL" -q recon "$work/scan.h5" --geometry "$work/scan.xml" --pitch 3.4865 --size 192 --voxel 1.06 -o "$work/out/r.ivol"
  check "recon-$signal-no-output" [ ! -e "$work/out/r.ivol" ]
done
# -f over a file that was there: the interrupted replacement keeps it.
cp "$work/noisy.ivol" "$work/out/old.ivol"
check convert-force-TERM interrupt TERM "$work/out/old.ivol" "$IVOL" -q convert "$work/noisy.raw" "$work/out/old.ivol" \
  --dims 160,160,160 --type u16 --zstd-level 19 -f
check convert-force-TERM-keeps-the-old-file cmp "$work/noisy.ivol" "$work/out/old.ivol"
check out-holds-only-the-old-file [ "$(ls -A "$work/out")" = "old.ivol" ]
finish
