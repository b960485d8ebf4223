# Slices larger than --memory go a band of rows at a time (issue 17, item
# 13) wherever both ends can work by rows: raw files and standard input,
# TIFF, MetaImage and NRRD in; raw files and standard output, TIFF, HDF5,
# MetaImage and NRRD out. Into .ivol the writer needs whole slices: a
# limit naming the bytes and the --memory that allows it, which then does.
bands="$work/bands"
mkdir -p "$bands"
# Exactness: 3000x2500x3 u16 of a hash pattern (15 MB a slice) under
# --memory 4: bands of 640 rows, the last of each slice 580, so that bands
# end inside HDF5 chunks' and TIFF strips' rows of the next slice's.
/usr/bin/python3 -c "
import numpy as np
v = (np.arange(3 * 2500 * 3000, dtype=np.uint64) * 2654435761 % 65521).astype(np.uint16)
v.tofile('$bands/v.raw')"
pattern="import numpy as np, tifffile, h5py; v = np.fromfile('$bands/v.raw', np.uint16).reshape(3, 2500, 3000)"
raw_in=(--dims 3000,2500,3 --type u16 --memory 4)
for ext in tif h5 nrrd mha raw; do
  bands_ok "bands-raw-to-$ext" "${bands_cap[@]}" "$IVOL" convert "$bands/v.raw" "$bands/a.$ext" "${raw_in[@]}"
done
bands_ok bands-raw-to-stdout sh -c "${bands_cap[*]} '$IVOL' convert '$bands/v.raw' - ${raw_in[*]} > '$bands/stdout.raw'"
bands_ok bands-stdin-to-tif sh -c "${bands_cap[*]} '$IVOL' convert - '$bands/stdin.tif' ${raw_in[*]} < '$bands/v.raw'"
bands_ok bands-tif-to-h5 "${bands_cap[@]}" "$IVOL" convert "$bands/a.tif" "$bands/b.h5" --memory 4
bands_ok bands-nrrd-to-raw "${bands_cap[@]}" "$IVOL" convert "$bands/a.nrrd" "$bands/nrrd.raw" --memory 4
bands_ok bands-mha-to-tif "${bands_cap[@]}" "$IVOL" convert "$bands/a.mha" "$bands/mha.tif" --memory 4
bands_check bands-exact-raw-stdout-nrrd-mha "
import filecmp
same = all(filecmp.cmp('$bands/v.raw', '$bands/' + f, shallow=False) for f in ('a.raw', 'stdout.raw', 'nrrd.raw'))
print('same' if same else 'differ')"
bands_check bands-exact-tif-h5 "$pattern
t = [tifffile.imread('$bands/' + f) for f in ('a.tif', 'stdin.tif', 'mha.tif')]
with h5py.File('$bands/a.h5') as f, h5py.File('$bands/b.h5') as g:
    h = [f['/exchange/data'][...], g['/exchange/data'][...]]
    chunks = f['/exchange/data'].chunks
ok = all(a.shape == v.shape and (a == v).all() for a in t + h) and chunks == (1, 64, 64)
print('same' if ok else 'differ: chunks %s' % (chunks,))"

# Bounded: a 16384^2 u8 slice (256 MiB, a sparse file of zeros) under
# --memory 16 in 200 MiB of address space, which one slice would not fit.
truncate -s $((16384 * 16384 * 2)) "$bands/big.raw"
big_in=(--dims 16384,16384,2 --type u8 --memory 16)
bands_ok bands-big-raw-to-tif "${bands_cap[@]}" "$IVOL" convert "$bands/big.raw" "$bands/big.tif" "${big_in[@]}"
bands_ok bands-big-raw-to-h5 "${bands_cap[@]}" "$IVOL" convert "$bands/big.raw" "$bands/big.h5" "${big_in[@]}"
bands_ok bands-big-stdin-to-stdout sh -c "${bands_cap[*]} '$IVOL' convert - - ${big_in[*]} < '$bands/big.raw' | cmp - '$bands/big.raw'"
bands_check bands-big-exact "
import numpy as np, tifffile, h5py
t = tifffile.TiffFile('$bands/big.tif')
ok = len(t.pages) == 2 and all(p.shape == (16384, 16384) and not p.asarray().any() for p in t.pages)
with h5py.File('$bands/big.h5') as f:
    d = f['/exchange/data']
    ok = ok and d.shape == (2, 16384, 16384) and all(not d[z].any() for z in range(2))
print('same' if ok else 'differ')"
rm -f "$bands"/big.*

# Into .ivol: the writer takes whole slices; the limit names what it needs
# and the --memory that allows it, and that --memory converts exactly.
/usr/bin/python3 -c "
import numpy as np
(np.arange(3 * 700 * 1000, dtype=np.uint64) * 2654435761 % 65521).astype(np.uint16).tofile('$bands/w.raw')"
wide_in=(--dims 1000,700,3 --type u16)
bad bands-ivol-octree-limit 2 "x.ivol: a slab of 3 slices of 1000x700 u16 needs 17 MiB, more than the 4 MiB this conversion may hold: the .ivol writer takes whole slices, 8 or more at a time (--memory 17 allows it)" -- \
  "$IVOL" convert "$bands/w.raw" "$out/x.ivol" "${wide_in[@]}" --memory 4 --structure octree
# (a bricked grid's layer reads its samples a slice at a time when it must)
bad bands-ivol-bricked-limit 2 "x.ivol: a layer of 3 slices of 1000x700 u16 needs 15 MiB, more than the 4 MiB this conversion may hold (--memory 15 allows it)" -- \
  "$IVOL" convert "$bands/w.raw" "$out/x.ivol" "${wide_in[@]}" --memory 4 --structure bricked
bad bands-ivol-class 2 "(limit-exceeded)" -- "$IVOL" convert "$bands/w.raw" "$out/x.ivol" "${wide_in[@]}" --memory 4
for structure in octree:17 bricked:15; do
  bad "bands-ivol-${structure%:*}-allowed" 0 "" -- sh -c "'$IVOL' -q convert '$bands/w.raw' '$bands/w-${structure%:*}.ivol' ${wide_in[*]} --memory ${structure#*:} --structure ${structure%:*} && '$IVOL' -q convert '$bands/w-${structure%:*}.ivol' '$bands/w-${structure%:*}.raw' && cmp '$bands/w.raw' '$bands/w-${structure%:*}.raw'"
done
rm -rf "$bands"
