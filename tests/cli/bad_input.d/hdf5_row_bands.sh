# HDF5 input by bands of rows (issue 17, item 13): a slice beyond --memory
# is read by libhdf5's child a hyperslab of rows at a time, as raw, TIFF,
# MetaImage and NRRD inputs are (row_bands.sh), whatever the layout:
# contiguous, chunks that bands end inside (taller than the band's last
# rows, deeper than a slice), gzip and blosc. Compared with h5py's reading of
# the same files. A filtered chunk beyond what the child may allocate is
# refused by its size (libhdf5 inflates a chunk whole); into .ivol the
# writer's own minimum is named.
h5bands="$work/h5bands"
mkdir -p "$h5bands"
if ! /usr/bin/python3 "$(dirname "${BASH_SOURCE[0]}")/make_row_band_h5.py" "$h5bands"; then
  echo "FAIL h5bands-inputs: cannot make the files (h5py with the blosc plugin)"
  failed=$((failed + 1))
else
  # What the checks share: h5py's reading of a dataset, and the samples of
  # an MHA or NRRD file ivol wrote (a header, then the samples, raw or, as
  # its NRRD header says, gzip).
  h5bands_py="
import gzip, numpy as np, h5py, tifffile
def h5(path, z=None):
    with h5py.File(path) as f:
        d = f['/exchange/data']
        return d[...] if z is None else d[z]
def after_header(path, marker, dtype, shape):
    data = open(path, 'rb').read()
    at = data.index(marker) + len(marker)
    samples = gzip.decompress(data[at:]) if b'encoding: gzip' in data[:at] else data[at:]
    return np.frombuffer(samples, dtype).reshape(shape)
"

  # Exactness: 3000x2500x3 u16 under --memory 4: bands of 640 rows.
  for layout in contiguous gzip blosc; do
    bands_ok "h5bands-$layout-to-raw" "${bands_cap[@]}" "$IVOL" convert "$h5bands/$layout.h5" "$h5bands/$layout.raw" --memory 4
  done
  for ext in tif h5 mha nrrd; do
    bands_ok "h5bands-gzip-to-$ext" "${bands_cap[@]}" "$IVOL" convert "$h5bands/gzip.h5" "$h5bands/gzip-out.$ext" --memory 4
  done
  # Whole slices within --memory, from chunks deeper than a slice: libhdf5's
  # chunk cache (preemption weight 1.0) never evicted a chunk read in part
  # and grew to every chunk of a slice, 30 MB, past the child's limit.
  for layout in gzip blosc; do
    bad "h5bands-$layout-slices" 0 "" -- "${bands_cap[@]}" "$IVOL" -q convert "$h5bands/$layout.h5" "$h5bands/$layout-slices.raw" --memory 16
  done
  bands_check h5bands-exact "$h5bands_py
ok = True
for layout, raw in (('contiguous', 'contiguous'), ('gzip', 'gzip'), ('blosc', 'blosc'), ('gzip', 'gzip-slices'), ('blosc', 'blosc-slices')):
    v = h5('$h5bands/' + layout + '.h5')
    ok = ok and v.shape == (3, 2500, 3000) and np.fromfile('$h5bands/' + raw + '.raw', '<u2').tobytes() == v.astype('<u2').tobytes()
v = h5('$h5bands/gzip.h5')
ok = ok and (tifffile.imread('$h5bands/gzip-out.tif') == v).all() and (h5('$h5bands/gzip-out.h5') == v).all()
ok = ok and (after_header('$h5bands/gzip-out.mha', b'ElementDataFile = LOCAL\n', '<u2', v.shape) == v).all()
ok = ok and (after_header('$h5bands/gzip-out.nrrd', b'\n\n', '<u2', v.shape) == v).all()
print('same' if ok else 'differ')"
  rm -f "$h5bands"/{contiguous,gzip,blosc,gzip-slices,blosc-slices}.raw "$h5bands"/gzip-out.*

  # Bounded: 2 slices of 16384^2 u8 (256 MiB each) under --memory 16 in
  # 200 MiB of address space, which one slice would not fit.
  for ext in raw tif h5 mha nrrd; do
    bands_ok "h5bands-big-gzip-to-$ext" "${bands_cap[@]}" "$IVOL" convert "$h5bands/big-gzip.h5" "$h5bands/big-out.$ext" --memory 16
  done
  for layout in blosc contiguous; do
    bands_ok "h5bands-big-$layout-to-raw" "${bands_cap[@]}" "$IVOL" convert "$h5bands/big-$layout.h5" "$h5bands/big-$layout.raw" --memory 16
  done
  bands_check h5bands-big-exact "$h5bands_py
shape = (2, 16384, 16384)
ok = True
for name in ('big-out.raw', 'big-blosc.raw', 'big-contiguous.raw'):
    m = np.memmap('$h5bands/' + name, np.uint8, 'r', shape=shape)
    ok = ok and all((m[z] == h5('$h5bands/big-gzip.h5', z)).all() for z in range(2))
t = tifffile.TiffFile('$h5bands/big-out.tif')
ok = ok and len(t.pages) == 2 and all((t.pages[z].asarray() == h5('$h5bands/big-gzip.h5', z)).all() for z in range(2))
ok = ok and all((h5('$h5bands/big-out.h5', z) == h5('$h5bands/big-gzip.h5', z)).all() for z in range(2))
for name, marker in (('big-out.mha', b'ElementDataFile = LOCAL\n'), ('big-out.nrrd', b'\n\n')):
    m = after_header('$h5bands/' + name, marker, np.uint8, shape)
    ok = ok and all((m[z] == h5('$h5bands/big-gzip.h5', z)).all() for z in range(2))
ok = ok and h5('$h5bands/big-gzip.h5', 0)[1000:1100].any() and h5('$h5bands/big-gzip.h5', 1)[-37:].any()
print('same' if ok else 'differ')"
  rm -f "$h5bands"/big-out.* "$h5bands"/big-{blosc,contiguous}.raw

  # A slice in one gzip chunk: libhdf5 inflates it whole, 256 MiB, beside
  # the stored chunk; refused by its size, and the --memory named converts.
  bad h5bands-one-chunk-limit 2 "big-one-chunk.h5: dataset /exchange/data: a chunk of 1x16384x16384 (z, y, x) is 256 MiB inflated, and libhdf5 inflates a chunk whole beside the stored one: more than the 16 MiB its process may allocate (--memory 512 allows it)" -- \
    "${bands_cap[@]}" "$IVOL" convert "$h5bands/big-one-chunk.h5" "$out/x.raw" --memory 16
  bad h5bands-one-chunk-class 2 "(limit-exceeded)" -- "$IVOL" convert "$h5bands/big-one-chunk.h5" "$out/x.raw" --memory 16
  bad h5bands-one-chunk-allowed 0 "" -- sh -c "'$IVOL' -q convert '$h5bands/big-one-chunk.h5' '$h5bands/one.raw' --memory 512 && \
    /usr/bin/python3 -c \"$h5bands_py
import sys; sys.exit(0 if (np.memmap('$h5bands/one.raw', np.uint8, 'r', shape=(1, 16384, 16384)) == h5('$h5bands/big-one-chunk.h5')).all() else 1)\""
  rm -f "$h5bands/one.raw"

  # Full disks under the outputs that bands feed: every write is checked,
  # nothing is left, and -f keeps the good file it would have replaced. A
  # tmpfs of our own, unmounted after.
  h5bands_full="$h5bands/full"
  mkdir -p "$h5bands_full"
  if mount -t tmpfs -o size=256k tmpfs "$h5bands_full" 2>/dev/null; then
    h5bands_saved_out=$out
    out=$h5bands_full
    for ext in raw tif h5 mha nrrd; do
      bad "h5bands-full-disk-$ext" 2 "No space left" -- \
        "${bands_cap[@]}" "$IVOL" convert "$h5bands/gzip.h5" "$h5bands_full/x.$ext" --memory 4
    done
    printf 'a good file' >"$h5bands_full/good.raw"
    log=$("${bands_cap[@]}" "$IVOL" convert "$h5bands/gzip.h5" "$h5bands_full/good.raw" --memory 4 -f 2>&1)
    got=$?
    if [ "$got" -eq 2 ] && [ "$(cat "$h5bands_full/good.raw")" = "a good file" ] && [ "$(ls -A "$h5bands_full")" = good.raw ]; then
      echo "ok   h5bands-full-disk-force"
      passed=$((passed + 1))
    else
      echo "FAIL h5bands-full-disk-force: exit $got (expected 2), $(ls -A "$h5bands_full" | tr '\n' ' ')left"
      echo "$log" | sed 's/^/    /' | head -5
      failed=$((failed + 1))
    fi
    rm -f "$h5bands_full"/* "$h5bands_full"/.[!.]* 2>/dev/null
    out=$h5bands_saved_out
    umount "$h5bands_full"
  else
    echo "skipped h5bands full-disk cases: cannot mount a tmpfs here (needs root or CAP_SYS_ADMIN)"
  fi

  # Into .ivol the writer takes whole slices, 8 at a time: refused by name.
  bad h5bands-big-to-ivol 2 "more than the 16 MiB this conversion may hold: the .ivol writer takes whole slices" -- \
    "${bands_cap[@]}" "$IVOL" convert "$h5bands/big-gzip.h5" "$out/x.ivol" --memory 16
fi
rm -rf "$h5bands"
