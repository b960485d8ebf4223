# `convert --structure bricked` where a bricked grid (format 1.3, every
# voxel) cannot hold the file: refused with exit 2 and
# the reason, nothing written.
/usr/bin/python3 - "$work" <<'PY'
import sys, numpy as np
(np.arange(8 * 8 * 8, dtype=np.uint16) * 7).tofile(sys.argv[1] + "/u16.raw")
(np.arange(256 * 256 * 32, dtype=np.uint32) % 4093).astype(np.uint16).tofile(sys.argv[1] + "/wide.raw")
PY
# auto under a --memory that holds the octree's slabs but not a layer of
# bricks: an octree, said on stderr with the --memory that
# writes the bricked grid (only `info` said it). Its output goes outside $out.
bad structure-octree-for-memory 0 "note: an octree, because a layer of bricks (10 MiB) exceeds the memory budget (--memory), a slab of the octree writer does not; --memory 10 writes a bricked grid" \
    -- "$IVOL" convert "$work/wide.raw" "$work/wide.ivol" --dims 256,256,32 --type u16 --memory 8 -f
bad bricked-with-keep 2 "--structure bricked: a keep rule coarsens regions, which only an octree holds" \
    -- "$IVOL" convert "$work/u16.raw" "$out/x.ivol" --dims 8,8,8 --type u16 --structure bricked --keep threshold=10,margin=1
# float32 values are a bricked grid of byte-plane bricks (codec 2), no longer
# refused. Its output goes outside $out.
bad bricked-float32 0 "(ivol bricked float32" \
    -- "$IVOL" convert "$work/u16.raw" "$work/f32-bricked.ivol" --dims 8,8,8 --type u16 --structure bricked --encoding float32 -f
bad bricked-format-1.2 2 "--structure bricked: format 1.2 (a bricked grid needs format 1.3)" \
    -- "$IVOL" convert "$work/u16.raw" "$out/x.ivol" --dims 8,8,8 --type u16 --structure bricked --format-version 1.2
bad bricked-codec-zstd 2 "--structure bricked: --codec zstd (codec 1 only, for format 1.0/1.1 readers)" \
    -- "$IVOL" convert "$work/u16.raw" "$out/x.ivol" --dims 8,8,8 --type u16 --structure bricked --codec zstd
bad structure-unknown      1 "--structure" \
    -- "$IVOL" convert "$work/u16.raw" "$out/x.ivol" --dims 8,8,8 --type u16 --structure kdtree
