# Sizes past 64 bits and slices past the memory budget (issue 17, items 2
# and 13). A valid file of 2^31 voxels a side has 2^93 voxels: their count
# wrapped to 0 (info said "dense float32 0 B"), and reads of it or of a
# 2^29-a-side grid ended in a bare std::bad_alloc or std::length_error.
# A TIFF page of 16384^2 (a 261 KB deflate bomb) beyond --memory was
# refused; into raw it now goes a band of rows at a time.
huge_here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
huge_leaf="$huge_here/../../fuzz/regressions/ivol/one-leaf-2e31.ivol"
huge_grid="$huge_here/../../fuzz/regressions/ivol/hostile-rectilinear_2p29.ivol"
huge_cap=(prlimit --as=2147483648)
[ "${IVOL_SANITIZED:-0}" = 1 ] && huge_cap=()

# 2^93 voxels x 4 bytes = 2^95 bytes = 32768 YiB.
bad huge-info-2e31      0 "dense float32 32768.0 YiB" -- timeout 60 "$IVOL" info "$huge_leaf"
bad huge-info-json-2e31 0 '"dense_float32_bytes": 3.961408125713217e+28' -- timeout 60 "$IVOL" info --json "$huge_leaf"
bad huge-slice-2e31     2 "(limit-exceeded)" -- timeout 60 "${huge_cap[@]}" "$IVOL" slice "$huge_leaf" --axis z --index 0 -o "$out/s.png"
bad huge-slice-2e31-size 2 "a slice of 1x2147483648x2147483648 voxels at level 0 needs" -- timeout 60 "${huge_cap[@]}" "$IVOL" slice "$huge_leaf" --axis x --index 0 -o "$out/s.png"
bad huge-slice-2p29     2 "a slice of 536870912x536870912x1 voxels" -- timeout 60 "${huge_cap[@]}" "$IVOL" slice "$huge_grid" --axis z --index 0 -o "$out/s.png"
bad huge-convert-2p29   2 "one slice as float32 and f32 needs" -- timeout 60 "${huge_cap[@]}" "$IVOL" convert "$huge_grid" "$out/c.raw"
bad huge-convert-2e31   2 "one slice as float32 and f32 needs" -- timeout 60 "${huge_cap[@]}" "$IVOL" convert "$huge_leaf" "$out/c.raw"

# The deflate bomb (one page of 256 MiB) into raw under --memory 128 in 2 GiB
# of address space: bands of 4096 rows (64 MiB), and the output is the
# page's 2^28 zeros. (It was refused: one slice beyond --memory.)
/usr/bin/python3 -c "import numpy as np, tifffile; tifffile.imwrite('$work/huge-bomb.tif', np.zeros((16384, 16384), np.uint8), compression='zlib', rowsperstrip=16384)"
log=$(timeout 120 "${huge_cap[@]}" "$IVOL" convert "$work/huge-bomb.tif" "$out/bomb.raw" --memory 128 2>&1)
got=$?
if [ "$got" -eq 0 ] && [ "$(stat -c %s "$out/bomb.raw")" = 268435456 ] && cmp -s -n 268435456 "$out/bomb.raw" /dev/zero &&
   grep -qF "in bands of rows" <<<"$log"; then
  echo "ok   huge-tiff-bomb-to-raw-in-bands"
  passed=$((passed + 1))
else
  echo "FAIL huge-tiff-bomb-to-raw-in-bands: exit $got"; echo "$log" | sed 's/^/    /' | head -5
  failed=$((failed + 1))
fi
rm -rf "${out:?}"/* "${out:?}"/.[!.]* 2>/dev/null
# Into .ivol the writer needs whole slices (8 at once): still a limit, named.
bad huge-tiff-bomb-to-ivol 2 "needs" -- timeout 60 "${huge_cap[@]}" "$IVOL" convert "$work/huge-bomb.tif" "$out/b.ivol" --memory 256

# Out of .ivol, --memory bounds the slice exported (it was a fixed 2 GiB):
# a 1024^2 slice as float32 and f32 is 8 MiB, more than --memory 4 allows.
/usr/bin/python3 -c "import numpy as np; np.arange(1024 * 1024 * 2, dtype=np.float32).tofile('$work/huge-wide.raw')"
"$IVOL" -q convert "$work/huge-wide.raw" "$work/huge-wide.ivol" --dims 1024,1024,2
bad huge-export-memory   2 "needs 8 MiB, more than the 4 MiB" -- timeout 60 "$IVOL" convert "$work/huge-wide.ivol" "$out/w.raw" --memory 4
bad huge-export-memory-ok 0 "" -- sh -c "timeout 60 '$IVOL' -q convert '$work/huge-wide.ivol' '$work/huge-wide-back.raw' --memory 16 && cmp '$work/huge-wide.raw' '$work/huge-wide-back.raw'"

# An OpenVDB file whose blosc block claims 1 TiB (20 KB; found by fuzz_vdb):
# libopenvdb's allocation fails; a limit naming the grid and the file.
cp "$huge_here/../../fuzz/regressions/vdb/vdb-blosc-1tib-allocation" "$work/huge-blosc.vdb"
# ASan's operator new aborts on a 1 TiB request instead of throwing: the
# normal build checks this case.
if [ "${IVOL_SANITIZED:-0}" != 1 ]; then
  bad huge-vdb-blosc-1tib 2 "libopenvdb could not allocate what the grid's data claim" -- timeout 60 "${huge_cap[@]}" "$IVOL" convert "$work/huge-blosc.vdb" "$out/x.ivol"
else
  echo "skip huge-vdb-blosc-1tib (AddressSanitizer's operator new aborts instead of throwing std::bad_alloc)"
fi
