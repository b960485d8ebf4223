#!/usr/bin/env bash
# Bad input, as a table: malformed files for every converter and projection
# reader, reconstructions whose geometry and projections disagree,
# out-of-range options, missing files and a full disk. Each must give a
# clear message, the expected non-zero exit, and leave no output behind (not
# even a temporary file). $IVOL is the binary under test.
set -u
: "${IVOL:?set IVOL to the ivol binary}"
work=$(mktemp -d)
full="$work/full"
cleanup() {
  mountpoint -q "$full" 2>/dev/null && umount "$full"
  rm -rf "$work"
}
trap cleanup EXIT
out="$work/out"
mkdir -p "$out"
passed=0
failed=0

# bad NAME EXIT "TEXT" -- COMMAND...: COMMAND exits EXIT, prints TEXT, and
# leaves $out empty.
bad() {
  local name=$1 want=$2 text=$3
  shift 4
  local got log
  log=$("$@" 2>&1)
  got=$?
  if [ "$got" -ne "$want" ]; then
    echo "FAIL $name: exit $got, expected $want"; echo "$log" | sed 's/^/    /' | head -10
    failed=$((failed + 1))
  elif ! grep -qF -- "$text" <<<"$log"; then
    echo "FAIL $name: output lacks '$text'"; echo "$log" | sed 's/^/    /' | head -10
    failed=$((failed + 1))
  elif [ -n "$(ls -A "$out")" ]; then
    echo "FAIL $name: left $(ls -A "$out" | tr '\n' ' ')in the output folder"
    failed=$((failed + 1))
    rm -rf "${out:?}"/* "${out:?}"/.[!.]* 2>/dev/null
  else
    echo "ok   $name"
    passed=$((passed + 1))
  fi
}

# Inputs: a small volume, malformed files of every format, a small scan.
/usr/bin/python3 - "$work" <<'PY'
import sys, numpy as np
d = sys.argv[1]
np.arange(16 * 16 * 16, dtype=np.float32).tofile(d + "/v.raw")
open(d + "/garbage.tif", "wb").write(b"II*\x00" + bytes(range(256)) * 4)
open(d + "/garbage.h5", "wb").write(b"\x89HDF\r\n\x1a\n" + bytes(1000))
open(d + "/garbage.vdb", "wb").write(b" BDV" + bytes(range(200)))
open(d + "/garbage.xml", "w").write("<RTKThreeDCircularGeometry version='3'><Projection><GantryAngle>x")
PY
"$IVOL" -q convert "$work/v.raw" "$work/v.ivol" --dims 16,16,16
head -c 2000 "$work/v.ivol" > "$work/truncated.ivol"
# A file on which Debian 12's libhdf5 crashes (found by fuzzing; the first
# byte is the harness's format selector).
tail -c +2 "$(dirname "$0")/../fuzz/regressions/libhdf5/converters-hdf5-null-read" > "$work/libhdf5-crash.h5"
"$IVOL" -q phantom pencil-holder --views 20 --detector 32 --radius 12 -o "$work/p.raw"
"$IVOL" -q phantom pencil-holder --views 24 --detector 32 --radius 12 -o "$work/q.h5"
scan=(--geometry "$work/p.xml" --pitch 1.5 --detector 32,32 --views 20)
grid=(--size 16 --voxel 1.5)

bad convert-garbage-tiff   2 "garbage.tif"            -- "$IVOL" convert "$work/garbage.tif" "$out/x.ivol"
bad convert-garbage-hdf5   2 "garbage.h5"             -- "$IVOL" convert "$work/garbage.h5" "$out/x.ivol"
bad convert-libhdf5-crash  2 "libhdf5-crash.h5: libhdf5 crashed" -- "$IVOL" convert "$work/libhdf5-crash.h5" "$out/x.ivol"
bad recon-libhdf5-crash    2 "libhdf5-crash.h5: libhdf5 crashed" -- "$IVOL" recon "$work/libhdf5-crash.h5" --sid 600 --sdd 1200 --pitch 1.5 --size 16 --voxel 1.5 -o "$out/x.ivol"
bad convert-garbage-vdb    2 "garbage.vdb"            -- "$IVOL" convert "$work/garbage.vdb" "$out/x.ivol"
bad convert-raw-size       2 "16384"                  -- "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16,17
bad convert-truncated-ivol 2 "truncated"              -- "$IVOL" convert "$work/truncated.ivol" "$out/x.raw"
bad convert-missing        2 "nothing.raw"            -- "$IVOL" convert "$work/nothing.raw" "$out/x.ivol" --dims 2,2,2
bad convert-bad-dims       1 "--dims"                 -- "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16
bad recon-views-mismatch   2 "20"                     -- "$IVOL" recon "$work/p.raw" --geometry "$work/q.xml" --pitch 1.5 --detector 32,32 --views 20 --size 16 --voxel 1.5 -o "$out/x.ivol"
bad recon-raw-too-short    2 "p.raw"                  -- "$IVOL" recon "$work/p.raw" --geometry "$work/p.xml" --pitch 1.5 --detector 32,33 --views 20 --size 16 --voxel 1.5 -o "$out/x.ivol"
bad recon-garbage-xml      2 "garbage.xml"            -- "$IVOL" recon "$work/p.raw" --geometry "$work/garbage.xml" --pitch 1.5 --detector 32,32 --views 20 --size 16 --voxel 1.5 -o "$out/x.ivol"
bad recon-garbage-h5       2 "garbage.h5"             -- "$IVOL" recon "$work/garbage.h5" --sid 600 --sdd 1200 --pitch 1.5 --size 16 --voxel 1.5 -o "$out/x.ivol"
bad recon-garbage-tiff     2 "garbage.tif"            -- "$IVOL" recon "$work/garbage.tif" --sid 600 --sdd 1200 --pitch 1.5 --size 16 --voxel 1.5 -o "$out/x.ivol"
bad recon-no-geometry      1 "--sid"                  -- "$IVOL" recon "$work/q.h5" --pitch 1.5 --size 16 --voxel 1.5 -o "$out/x.ivol"
bad recon-sdd-below-sid    1 "SDD > SID"     -- "$IVOL" recon "$work/q.h5" --sid 600 --sdd 500 --pitch 1.5 --size 16 --voxel 1.5 -o "$out/x.ivol"
bad recon-size-zero        1 "--size"                 -- "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 0 --voxel 1.5 -o "$out/x.ivol"
bad recon-voxel-negative   1 "--voxel"                -- "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 16 --voxel -1 -o "$out/x.ivol"
bad recon-pitch-text       1 "--pitch"                -- "$IVOL" recon "$work/p.raw" --geometry "$work/p.xml" --detector 32,32 --views 20 "${grid[@]}" --pitch wide -o "$out/x.ivol"
bad recon-cutoff-range     1 "--cutoff"               -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --cutoff 1.5 -o "$out/x.ivol"
bad recon-window           1 "--window"               -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --window box -o "$out/x.ivol"
bad recon-preview-factor   1 "--preview-factor"       -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --structure octree --preview-factor 3 -o "$out/x.ivol"
bad recon-threshold-text   1 "--threshold"            -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --structure octree --threshold high -o "$out/x.ivol"
bad recon-keep-and-struct  1 "--keep and --structure" -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --structure octree --keep threshold=1 -o "$out/x.ivol"
bad recon-device-memory    2 "device memory"          -- "$IVOL" recon "$work/p.raw" "${scan[@]}" --device-memory 1 --size 4000,4000,16 --voxel 0.01 -o "$out/x.ivol"
bad phantom-detector       1 "--detector"             -- "$IVOL" phantom thin-pipe --detector 0 -o "$out/x.h5"
bad slice-index            1 "--index"                -- "$IVOL" slice "$work/v.ivol" --index 99 -o "$out/x.png"
bad extract-box            1 "box"                    -- "$IVOL" extract "$work/v.ivol" --box 0,0,0,99,99,99 -o "$out/x.raw"

# The row-band parts (row_bands.sh, hdf5_row_bands.sh) run under this cap
# and check with these two.
bands_cap=(prlimit --as=209715200)  # 200 MiB: ivol starts in about 150
[ "${IVOL_SANITIZED:-0}" = 1 ] && bands_cap=()

# bands_ok NAME COMMAND...: COMMAND exits 0 and says it went in bands.
bands_ok() {
  local name=$1 log got
  shift
  log=$("$@" 2>&1)
  got=$?
  if [ "$got" -eq 0 ] && grep -qF "in bands of rows" <<<"$log"; then
    echo "ok   $name"
    passed=$((passed + 1))
  else
    echo "FAIL $name: exit $got (or not in bands)"; echo "$log" | sed 's/^/    /' | head -10
    failed=$((failed + 1))
  fi
}

# bands_check NAME PYTHON: the check (numpy, tifffile, h5py) prints "same".
bands_check() {
  local name=$1 said
  said=$(/usr/bin/python3 -c "$2" 2>&1)
  if [ "$said" = same ]; then
    echo "ok   $name"
    passed=$((passed + 1))
  else
    echo "FAIL $name: $(tail -3 <<<"$said")"
    failed=$((failed + 1))
  fi
}

# More cases, one file per concern (each sources this table's helpers: bad,
# $work, $out, $IVOL and the inputs above).
for part in "$(dirname "$0")"/bad_input.d/*.sh; do
  [ -e "$part" ] && source "$part"
done

# A full disk: a 256 KiB tmpfs (needs the right to mount; said when missing).
mkdir -p "$full"
if mount -t tmpfs -o size=256k tmpfs "$full" 2>/dev/null; then
  /usr/bin/python3 -c "import numpy as np; np.random.default_rng(1).random(64**3, dtype=np.float32).tofile('$work/noise.raw')"
  out="$full"
  bad full-disk-convert    2 "No space left"          -- "$IVOL" convert "$work/noise.raw" "$full/x.ivol" --dims 64,64,64 --no-disk-check
  bad full-disk-tiff       2 "No space left"             -- "$IVOL" convert "$work/noise.raw" "$full/x.tif" --dims 64,64,64
  bad full-disk-recon      2 "No space left"          -- "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 64 --voxel 0.4 --encoding float32 -o "$full/x.ivol" --no-disk-check
  bad full-disk-phantom    2 "No space left"          -- "$IVOL" phantom shepp-logan --views 64 --detector 96 -o "$full/x.h5"
else
  echo "skipped full-disk cases: cannot mount a tmpfs here (needs root or CAP_SYS_ADMIN)"
fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
