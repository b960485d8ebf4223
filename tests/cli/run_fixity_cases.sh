#!/usr/bin/env bash
# Fixity and standard streams: `ivol verify --json` against sha256sum and
# stat, the statuses of missing, foreign and damaged files, provenance
# sources and command of real conversions (raw and a TIFF folder) against
# sha256sum, `verify --against` on an intact and a changed source, the BagIt
# manifest through `sha256sum -c`, and raw samples through "-" (standard
# output and input) against the files themselves. $IVOL is the binary.
set -u
cli_dir=$(cd "$(dirname "$0")" && pwd)
: "${IVOL:?set IVOL to the ivol binary}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
source "$cli_dir/cases.sh"
expect_exit() {  # expect_exit NAME EXIT TEXT -- COMMAND...
  local name=$1 want=$2 text=$3
  shift 4
  local log got
  log=$("$@" 2>&1)
  got=$?
  if [ "$got" -eq "$want" ] && grep -qF -- "$text" <<<"$log"; then
    echo "ok   $name"; passed=$((passed + 1))
  else
    echo "FAIL $name: exit $got (expected $want), or lacks '$text'"; echo "$log" | sed 's/^/    /' | head -20
    failed=$((failed + 1))
  fi
}
py=/usr/bin/python3

# A 24x20x16 uint16 volume (raw, a name with a space), and the same as a folder of TIFF slices.
$py - "$work" <<'PY'
import sys, os, numpy as np, tifffile
d = sys.argv[1]
v = (np.random.default_rng(5).integers(0, 4000, size=(16, 20, 24))).astype(np.uint16)
v[4:12, 5:15, 6:18] += 20000
v.tofile(d + "/my volume.raw")
os.mkdir(d + "/slices")
for z in range(16):
    tifffile.imwrite(f"{d}/slices/s{z}.tif", v[z])
PY
raw="$work/my volume.raw"
check convert-raw "$IVOL" -q convert "$raw" "$work/v.ivol" --dims 24,20,16 --type u16 --voxel-size 0.5 --quantity "linear attenuation"
check convert-tiff "$IVOL" -q convert "$work/slices" "$work/t.ivol"

# provenance.sources: one entry per input file, bytes and sha256 as stat and sha256sum say.
"$IVOL" info --json "$work/v.ivol" > "$work/v.json"
"$IVOL" info --json "$work/t.ivol" > "$work/t.json"
sha256sum "$raw" "$work"/slices/*.tif > "$work/sums.txt"
check provenance-sources $py - "$work" <<'PY'
import sys, json, os
d = sys.argv[1]
sums = {}
for line in open(d + "/sums.txt"):
    digest, path = line.rstrip("\n").split("  ", 1)
    sums[path] = digest
v = json.load(open(d + "/v.json"))["metadata"]["provenance"]
[src] = v["sources"]
raw = d + "/my volume.raw"
assert src["path"] == raw, src
assert src["sha256"] == sums[raw], (src, sums[raw])
assert src["bytes"] == os.path.getsize(raw) == 24 * 20 * 16 * 2, src
assert src["format"] == "raw" and src["sample_type"] == "u16", src
# the whole command line, options included, quoted as a shell reads it
assert "'" + raw + "'" in v["command"] and "--quantity 'linear attenuation'" in v["command"], v["command"]
assert "--voxel-size 0.5" in v["command"], v["command"]
t = json.load(open(d + "/t.json"))["metadata"]["provenance"]["sources"]
assert len(t) == 16, len(t)
for z, e in enumerate(t):  # natural order, as the TIFF reader reads them
    p = f"{d}/slices/s{z}.tif"
    assert e["path"] == p and e["sha256"] == sums[p] and e["bytes"] == os.path.getsize(p), e
PY

# A reconstruction records its projections and geometry with their roles.
"$IVOL" -q phantom thin-pipe --views 12 --detector 24 --radius 10 -o "$work/scan.raw"
check recon "$IVOL" -q recon "$work/scan.raw" --geometry "$work/scan.xml" --detector 24,24 --views 12 --pitch 1.5 --size 8 --voxel 2 -o "$work/r.ivol"
"$IVOL" info --json "$work/r.ivol" > "$work/r.json"
sha256sum "$work/scan.raw" "$work/scan.xml" > "$work/sums3.txt"
check recon-provenance $py - "$work" <<'PY'
import sys, json
d = sys.argv[1]
sums = {p: h for h, p in (l.rstrip("\n").split("  ", 1) for l in open(d + "/sums3.txt"))}
p = json.load(open(d + "/r.json"))["metadata"]["provenance"]
roles = {e["role"]: e for e in p["sources"]}
assert set(roles) == {"projections", "geometry"}, roles
assert roles["projections"]["sha256"] == sums[d + "/scan.raw"] and roles["geometry"]["sha256"] == sums[d + "/scan.xml"]
assert p["command"].startswith("ivol -q recon ") and "--size 8 --voxel 2" in p["command"], p["command"]
PY
expect_exit against-recon 0 "source digests match" -- "$IVOL" verify --against "$work/scan.raw" "$work/r.ivol"

# A folder of more than 10 000 slices: one entry (count, bytes, the SHA-256
# of its "<sha256>  <name>" lines in natural order), checked by --against.
$py - "$work" <<'PY'
import sys, os, numpy as np, tifffile
d = sys.argv[1] + "/many"
os.mkdir(d)
for z in range(10001):
    tifffile.imwrite(f"{d}/s{z}.tif", np.array([[z % 65536]], np.uint16))
PY
check convert-many "$IVOL" -q convert "$work/many" "$work/many.ivol"
"$IVOL" info --json "$work/many.ivol" > "$work/many.json"
check provenance-many $py - "$work" <<'PY'
import sys, json, os, hashlib
d = sys.argv[1]
[e] = json.load(open(d + "/many.json"))["metadata"]["provenance"]["sources"]
names = [f"s{z}.tif" for z in range(10001)]
lines = "".join(hashlib.sha256(open(f"{d}/many/{n}", "rb").read()).hexdigest() + "  " + n + "\n" for n in names)
assert e["files"] == 10001 and e["bytes"] == sum(os.path.getsize(f"{d}/many/{n}") for n in names), e
assert e["manifest_sha256"] == hashlib.sha256(lines.encode()).hexdigest() and e["path"] == d + "/many", e
PY
expect_exit against-many 0 "10001 voxels equal" -- "$IVOL" verify --against "$work/many" "$work/many.ivol"
printf '\x07' | dd of="$work/many/s5000.tif" bs=1 seek=$(($(stat -c %s "$work/many/s5000.tif") - 1)) conv=notrunc status=none
expect_exit against-many-changed 2 "differ from the recorded" -- "$IVOL" verify --against "$work/many" "$work/many.ivol"

# verify --json: statuses, classes, size and sha256 of the whole file.
cp "$work/v.ivol" "$work/damaged.ivol"
size=$(stat -c %s "$work/damaged.ivol")
printf '\x5a' | dd of="$work/damaged.ivol" bs=1 seek=$((size / 3)) conv=notrunc status=none
printf 'not a volume\n' > "$work/notes.txt"
"$IVOL" verify --json "$work/v.ivol" "$work/damaged.ivol" "$work/missing.ivol" "$work/notes.txt" > "$work/verify.json"
echo $? > "$work/verify.exit"
sha256sum "$work/v.ivol" "$work/damaged.ivol" "$work/notes.txt" > "$work/sums2.txt"
check verify-json $py - "$work" <<'PY'
import sys, json, os, hashlib
d = sys.argv[1]
assert open(d + "/verify.exit").read().strip() == "2"
sums = dict(reversed(l.rstrip("\n").split("  ", 1)) for l in open(d + "/sums2.txt"))
r = {e["path"]: e for e in json.load(open(d + "/verify.json"))}
ok, bad, missing, notes = (r[d + n] for n in ("/v.ivol", "/damaged.ivol", "/missing.ivol", "/notes.txt"))
assert ok["status"] == "ok" and ok["error_class"] is None and ok["problems"] == [], ok
assert ok["sha256"] == sums[d + "/v.ivol"] == hashlib.sha256(open(d + "/v.ivol", "rb").read()).hexdigest()
assert ok["bytes"] == os.path.getsize(d + "/v.ivol")
assert bad["status"] == "damaged" and bad["problems"] and bad["sha256"] == sums[d + "/damaged.ivol"], bad
assert all(p["error_class"] and p["message"] for p in bad["problems"])
assert missing["status"] == "missing" and "sha256" not in missing, missing
assert notes["status"] == "not-ivol" and notes["error_class"] == "not-ivol", notes
assert notes["sha256"] == sums[d + "/notes.txt"]
PY
expect_exit verify-text-missing 2 "MISSING"            -- "$IVOL" verify "$work/missing.ivol"
expect_exit verify-text-not-ivol 2 "NOT AN IVOL FILE"  -- "$IVOL" verify "$work/notes.txt"

# --against: the intact source matches; a changed one is caught by its digest
# and by the first voxel that differs.
expect_exit against-raw       0 "equal, source digests match" -- "$IVOL" verify --against "$raw" "$work/v.ivol"
expect_exit against-tiff      0 "equal, source digests match" -- "$IVOL" verify --against "$work/slices" "$work/t.ivol"
cp "$raw" "$work/changed.raw"
printf '\x01\x02' | dd of="$work/changed.raw" bs=1 seek=$(((3 * 20 * 24 + 2 * 24 + 5) * 2)) conv=notrunc status=none
expect_exit against-changed-digest 2 "sha256"             -- "$IVOL" verify --against "$work/changed.raw" "$work/v.ivol"
expect_exit against-changed-voxel  2 "(5,2,3): source 513" -- "$IVOL" verify --against "$work/changed.raw" "$work/v.ivol"
cp -r "$work/slices" "$work/slices2"
rm "$work/slices2/s7.tif"
expect_exit against-missing-slice 2 "s7.tif: recorded, missing" -- "$IVOL" verify --against "$work/slices2" "$work/t.ivol"
expect_exit against-json 2 '"differing_voxels": 1' -- "$IVOL" verify --json --against "$work/changed.raw" "$work/v.ivol"

# The BagIt manifest: sha256sum -c reads it; not written when a file is damaged.
(cd "$work" && "$IVOL" -q verify --manifest manifest-sha256.txt v.ivol t.ivol)
check manifest-sha256sum bash -c "cd '$work' && sha256sum -c manifest-sha256.txt"
expect_exit manifest-damaged 2 "not written" -- "$IVOL" verify --manifest "$work/m2.txt" "$work/v.ivol" "$work/damaged.ivol"
check manifest-damaged-absent test ! -e "$work/m2.txt"

# Standard streams: raw samples out through "-" equal the raw file written by
# name; raw samples in through "-" give the same volume back, a keep rule's
# overlapping slabs included.
"$IVOL" -q convert "$work/v.ivol" "$work/back.raw"
"$IVOL" convert "$work/v.ivol" - > "$work/stdout.raw" 2> "$work/stdout.log"
check stdout-equals-file cmp "$work/stdout.raw" "$raw"
check stdout-summary-on-stderr grep -q "v.ivol -> -" "$work/stdout.log"
"$IVOL" -q extract "$work/v.ivol" --box 2,3,4,10,12,14 -o - > "$work/box.raw"
check stdout-extract $py -c "
import numpy as np
v = np.fromfile('$raw', np.uint16).reshape(16, 20, 24)
assert (np.fromfile('$work/box.raw', np.uint16).reshape(10, 9, 8) == v[4:14, 3:12, 2:10]).all()"
# 64x64x128 u16 with --memory 1: slabs of a few slices, so the keep rule's
# margin makes each slab re-read slices of the one before.
$py -c "
import numpy as np
v = np.random.default_rng(2).integers(0, 1000, size=(128, 64, 64)).astype(np.uint16)
v[30:100, 20:44, 10:50] += 30000
v.tofile('$work/big.raw')"
big=(--dims 64,64,128 --type u16 --memory 1)
"$IVOL" -q convert "$work/big.raw" "$work/big-file.ivol" "${big[@]}" --keep threshold=15000,margin=3
check stdin-convert bash -c "cat '$work/big.raw' | '$IVOL' -v convert - '$work/big-in.ivol' ${big[*]} --keep threshold=15000,margin=3 2>&1 | grep -E 'slabs of ([1-9]|[1-5][0-9]) slices'"
"$IVOL" -q convert "$work/big-file.ivol" "$work/big-file.raw"
"$IVOL" -q convert "$work/big-in.ivol" "$work/big-in.raw"
check stdin-same-values cmp "$work/big-in.raw" "$work/big-file.raw"
check stdin-digest $py -c "
import json, subprocess, hashlib
m = json.loads(subprocess.run(['$IVOL', 'info', '--json', '$work/big-in.ivol'], capture_output=True, check=True).stdout)
[src] = m['metadata']['provenance']['sources']
data = open('$work/big.raw', 'rb').read()
assert src['path'] == '-' and src['bytes'] == len(data) and src['sha256'] == hashlib.sha256(data).hexdigest(), src"
check stdin-lossless-same bash -c "cat '$raw' | '$IVOL' -q convert - '$work/in.ivol' --dims 24,20,16 --type u16 && '$IVOL' convert '$work/in.ivol' - | cmp - '$raw'"
expect_exit stdin-short 2 "standard input: ended" -- bash -c "head -c 1000 '$raw' | '$IVOL' convert - '$work/short.ivol' --dims 24,20,16 --type u16"
expect_exit stdin-long  2 "more bytes than" -- bash -c "cat '$raw' '$raw' | '$IVOL' convert - '$work/long.ivol' --dims 24,20,16 --type u16"
expect_exit stdin-otsu  2 "give a file" -- bash -c "cat '$work/big.raw' | '$IVOL' convert - '$work/otsu.ivol' ${big[*]} --keep threshold=otsu"
check stdin-failures-leave-nothing bash -c "! ls -A '$work' | grep -E 'short|long|otsu'"

finish
