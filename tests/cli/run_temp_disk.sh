#!/usr/bin/env bash
# Temporary disk of convert and recon (README, "Disk a run needs"): the
# octree writer's spill file goes to --temp-dir, else $TMPDIR, else beside
# the output; it is never seen by name and is gone afterwards; its peak size
# (--json temp_bytes) stays within 1.2x the file, lossless or coarsened; and
# where it went does not change a byte of the file.
set -u
cli_dir=$(cd "$(dirname "$0")" && pwd)
: "${IVOL:?set IVOL to the ivol binary}"
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
source "$cli_dir/cases.sh"  # check NAME CONDITION-COMMAND...
field() { /usr/bin/python3 -c "import json,sys; print(json.load(open(sys.argv[1]))[sys.argv[2]])" "$1" "$2"; }
within() { /usr/bin/python3 -c "import sys; t, f = int(sys.argv[1]), int(sys.argv[2]); sys.exit(0 if 0 < t <= 1.2 * f else 1)" "$1" "$2"; }
empty() { [ -z "$(ls -A "$1")" ]; }

export SOURCE_DATE_EPOCH=0  # the same provenance in every file
/usr/bin/python3 "$here/../../bench/make_noisy_volume.py" 48 "$work/noisy.raw"
mkdir -p "$work/opt" "$work/env" "$work/a" "$work/b" "$work/c" "$work/d"
convert=(convert -q --json --dims 48,48,48 --type u16 --structure octree "$work/noisy.raw")

# --temp-dir, lossless noisy values
(cd "$work/a" && "$IVOL" "${convert[@]}" out.ivol --temp-dir "$work/opt" > ../a.json)
check convert-temp-dir-used [ "$(field "$work/a.json" temp_directory)" = "$work/opt" ]
check convert-temp-bytes-within-1.2x within "$(field "$work/a.json" temp_bytes)" "$(field "$work/a.json" file_bytes)"
check convert-temp-dir-left-empty empty "$work/opt"
check convert-output-dir-only-output [ "$(ls -A "$work/a")" = "out.ivol" ]
# TMPDIR without the option; the option wins over TMPDIR; neither: beside the output
(cd "$work/b" && TMPDIR="$work/env" "$IVOL" "${convert[@]}" out.ivol > ../b.json)
check convert-tmpdir-used [ "$(field "$work/b.json" temp_directory)" = "$work/env" ]
(cd "$work/c" && TMPDIR="$work/env" "$IVOL" "${convert[@]}" out.ivol --temp-dir "$work/opt" > ../c.json)
check convert-option-over-tmpdir [ "$(field "$work/c.json" temp_directory)" = "$work/opt" ]
(cd "$work/d" && env -u TMPDIR "$IVOL" "${convert[@]}" out.ivol > ../d.json)
check convert-default-beside-output [ "$(field "$work/d.json" temp_directory)" = "." ]
check convert-env-dirs-left-empty empty "$work/env"
# (one command line, so one provenance: TMPDIR's spill against the output's directory)
check convert-same-bytes-wherever-the-spill-went cmp "$work/b/out.ivol" "$work/d/out.ivol"
check convert-file-verifies "$IVOL" -q verify "$work/a/out.ivol"
# Coarsened outside the object (--keep): within 1.2x too
"$IVOL" "${convert[@]}" "$work/keep.ivol" --keep threshold=1000,margin=2 --temp-dir "$work/opt" > "$work/keep.json"
check convert-keep-temp-within-1.2x within "$(field "$work/keep.json" temp_bytes)" "$(field "$work/keep.json" file_bytes)"
# A bricked grid has no spill
"$IVOL" convert -q --json --dims 48,48,48 --type u16 "$work/noisy.raw" "$work/bricked.ivol" > "$work/bricked.json"
check convert-bricked-no-temp [ "$(field "$work/bricked.json" temp_bytes)" = 0 ]

# recon: dense (a bricked grid: no spill), dense with --keep (the octree
# writer) and --structure octree
"$IVOL" -q phantom pencil-holder --views 24 --detector 48 --radius 12 -o "$work/p.raw"
scan=(--geometry "$work/p.xml" --pitch 1.5 --detector 48,48 --views 24)
"$IVOL" recon "$work/p.raw" "${scan[@]}" --size 32 --voxel 0.8 -o "$work/d.ivol" --temp-dir "$work/opt" --json \
  > "$work/d.json" 2> "$work/d.err"
check recon-dense-bricked-no-temp [ "$(field "$work/d.json" structure)/$(field "$work/d.json" temp_bytes)" = bricked/0 ]
"$IVOL" recon "$work/p.raw" "${scan[@]}" --size 32 --voxel 0.8 --keep threshold=otsu,margin=2 -o "$work/r.ivol" \
  --temp-dir "$work/opt" --json > "$work/r.json" 2> "$work/r.err"
check recon-temp-bytes-within-1.2x within "$(field "$work/r.json" temp_bytes)" "$(field "$work/r.json" file_bytes)"
"$IVOL" recon "$work/p.raw" "${scan[@]}" --size 32 --voxel 0.8 --structure octree -o "$work/s.ivol" \
  --temp-dir "$work/opt" --json > "$work/s.json" 2> "$work/s.err"
check recon-structure-temp-bytes-within-1.2x within "$(field "$work/s.json" temp_bytes)" "$(field "$work/s.json" file_bytes)"
check recon-temp-dir-left-empty empty "$work/opt"

finish
