# Lossy conversions without --allow-lossy (README, "Exactness"): each is
# refused with exit 2, a message naming the loss (how many voxels, the values
# that do not fit, the largest error) and the option that accepts it, and
# leaves nothing behind. v.ivol holds the float32 integers 0..4095.
/usr/bin/python3 - "$work" <<'PY'
import sys, numpy as np
d = sys.argv[1]
(np.arange(16 * 16 * 16, dtype=np.float32) * 0.001).tofile(d + "/frac.raw")
(np.arange(16 * 16 * 16, dtype=np.int16) - 100).tofile(d + "/neg.raw")
PY
"$IVOL" -q convert "$work/frac.raw" "$work/frac.ivol" --dims 16,16,16
"$IVOL" -q convert "$work/neg.raw" "$work/neg.ivol" --dims 16,16,16 --type i16   # uint16, value_offset -32768

bad exact-f32-to-u8        2 "3840 of 4096 voxels change (largest error 3840; 3840 values in [256, 4095] do not fit in u8); nothing written. --out-type f32 is exact; --allow-lossy accepts the loss" \
                                                      -- "$IVOL" convert "$work/v.ivol" "$out/x.raw" --out-type u8
bad exact-fractions-to-u16 2 "largest error 0.5"      -- "$IVOL" convert "$work/frac.ivol" "$out/x.tif" --out-type u16
bad exact-negatives-to-u16 2 "100 values in [-100, -1] do not fit in u16" \
                                                      -- "$IVOL" convert "$work/neg.ivol" "$out/x.raw" --out-type u16
bad exact-vdb-half         2 "as f16 is not exact"    -- "$IVOL" convert "$work/frac.ivol" "$out/x.vdb" --out-type f16
bad exact-vdb-integers     1 "OpenVDB grids hold float32 (--out-type f32) or half-float (--out-type f16) values, not u16" \
                                                      -- "$IVOL" convert "$work/neg.ivol" "$out/x.vdb" --out-type u16
bad exact-extract-u8       2 "--type f32 is exact; --allow-lossy accepts the loss" \
                                                      -- "$IVOL" extract "$work/frac.ivol" --box 0,0,0,16,16,16 --type u8 -o "$out/x.h5"
bad exact-import-binary16  2 "f32 samples as binary16 is not exact" \
                                                      -- "$IVOL" convert "$work/frac.raw" "$out/x.ivol" --dims 16,16,16 --encoding binary16

# float64 HDF5: ivol holds at most float32 and HDF5 rounds on the way, out of
# sight: the rounding must be accepted.
/usr/bin/python3 -c "import h5py, numpy as np; h5py.File('$work/f64.h5', 'w')['/exchange/data'] = np.arange(64.0).reshape(4, 4, 4) / 3"
bad exact-hdf5-float64     2 "holds float64 samples, which ivol reads as float32" \
                                                      -- "$IVOL" convert "$work/f64.h5" "$out/x.ivol"

# Standard output cannot be taken back: the refusal comes before the first byte.
bad exact-stdout-u8        2 "as u8 is not exact"     -- "$IVOL" convert "$work/frac.ivol" - --out-type u8
streamed=$("$IVOL" extract "$work/frac.ivol" --box 0,0,0,16,16,16 --type u8 -o - 2>/dev/null | wc -c)
if [ "$streamed" -eq 0 ]; then
  echo "ok   exact-stdout-nothing-streamed"; passed=$((passed + 1))
else
  echo "FAIL exact-stdout-nothing-streamed: $streamed bytes on standard output"; failed=$((failed + 1))
fi
