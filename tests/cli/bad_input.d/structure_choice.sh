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
bad structure-octree-for-memory 0 "note: an octree, because a layer of bricks (15 MiB) exceeds the memory budget (--memory), a slab of the octree writer does not; --memory 15 writes a bricked grid" \
    -- "$IVOL" convert "$work/wide.raw" "$work/wide.ivol" --dims 256,256,32 --type u16 --memory 8 -f
# Options that cannot hold together are a bad command line: exit 1 (README).
# A keep rule into a bricked grid: one background value outside the kept
# region, no longer refused (tests/test_bricked_keep.cpp checks the voxels).
# Its output goes outside $out.
bad bricked-with-keep 0 "(ivol bricked uint16" \
    -- "$IVOL" convert "$work/u16.raw" "$work/keep-bricked.ivol" --dims 8,8,8 --type u16 --structure bricked --keep threshold=3000,margin=1 -f
# `info` says what such a file does not hold, not only its metadata.
bad info-bricked-keep 0 "fidelity       not every value kept: full resolution above 3000.0 and within 1 voxels of it, one background value" \
    -- "$IVOL" info "$work/keep-bricked.ivol"
# float32 values are a bricked grid of byte-plane bricks (codec 2), no longer
# refused. Its output goes outside $out.
bad bricked-float32 0 "(ivol bricked float32" \
    -- "$IVOL" convert "$work/u16.raw" "$work/f32-bricked.ivol" --dims 8,8,8 --type u16 --structure bricked --encoding float32 -f
bad bricked-format-1.2 1 "--structure: bricked: format 1.2 (a bricked grid needs format 1.3)" \
    -- "$IVOL" convert "$work/u16.raw" "$out/x.ivol" --dims 8,8,8 --type u16 --structure bricked --format-version 1.2
bad bricked-codec-zstd 1 "--structure: bricked: --codec zstd (codec 1 only, for format 1.0/1.1 readers)" \
    -- "$IVOL" convert "$work/u16.raw" "$out/x.ivol" --dims 8,8,8 --type u16 --structure bricked --codec zstd
# --brick where no bricked grid can be written: refused, not ignored.
bad brick-with-octree 1 "--brick: bricks belong to a bricked grid, and --structure octree asks for an octree" \
    -- "$IVOL" convert "$work/u16.raw" "$out/x.ivol" --dims 8,8,8 --type u16 --structure octree --brick 16
bad brick-with-format-1.2 1 "--brick: bricks belong to a bricked grid, which format 1.2 (--format-version) lacks" \
    -- "$IVOL" convert "$work/u16.raw" "$out/x.ivol" --dims 8,8,8 --type u16 --format-version 1.2 --brick 16
bad structure-unknown      1 "--structure" \
    -- "$IVOL" convert "$work/u16.raw" "$out/x.ivol" --dims 8,8,8 --type u16 --structure kdtree

# A bricked grid holds what --memory gives it: the encoding threads' bricks
# and a layer's encoded blocks are counted, and the writer runs as many
# encoding threads as the budget holds. --brick 128 held about twice its
# --memory before (the threads' bricks were not counted). Peak resident
# memory above ivol's own (a 2x2x2 conversion), not in the sanitizer build.
brickmem="$work/brickmem"
mkdir -p "$brickmem"
/usr/bin/python3 -c "
import numpy as np
z, y, x = np.mgrid[0:128, 0:256, 0:256].astype(np.float32)
(np.sin(x / 9) + np.cos(y / 7) * np.sin(z / 11)).astype(np.float32).tofile('$brickmem/s.raw')"
head -c 32 "$brickmem/s.raw" > "$brickmem/tiny.raw"
brickmem_need=$("$IVOL" convert "$brickmem/s.raw" "$brickmem/probe.ivol" --dims 256,256,128 --type f32 --brick 128 --memory 8 2>&1 |
  grep -o -- "--memory [0-9]* writes a bricked grid" | grep -o "[0-9]*")
# Both checks below: ivol, the folder, the least --memory, and the peak
# resident memory of a conversion (MiB).
peak_py="
import os, subprocess, sys
ivol, folder, need = '$IVOL', '$brickmem', int('${brickmem_need:-0}')
sanitized = os.environ.get('IVOL_SANITIZED', '0') == '1'
def peak_mib(args):
    probe = 'import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True); ' \\
            'print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)'
    done = subprocess.run([sys.executable, '-c', probe, ivol, '-q', 'convert'] + args, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit('ivol failed: ' + done.stderr.strip()[-300:])
    return float(done.stdout.split()[-1])
own = peak_mib([folder + '/tiny.raw', folder + '/tiny.ivol', '--dims', '2,2,2', '--type', 'f32', '-f'])"
bands_check bricked-memory-held "$peak_py
big = peak_mib([folder + '/s.raw', folder + '/s.ivol', '--dims', '256,256,128', '--type', 'f32', '--brick', '128',
                '--memory', str(need)])
kind = subprocess.run([ivol, 'info', folder + '/s.ivol'], capture_output=True, text=True).stdout
ok = need > 0 and 'bricked, bricks of 128' in kind and (sanitized or big - own <= need)
print('same' if ok else 'need %d MiB, held %.0f MiB above %.0f; %s' % (need, big - own, own, kind[:200]))"
# The same for 16-bit values, whose bricks codec 3 encodes (the least-squares
# fit, residuals, the entropy coder's tokens): 128³ binary16 bricks held
# 7–23 MiB more than their --memory when counted as float32 bricks are.
bands_check bricked-memory-held-16 "$peak_py
import numpy as np
z, y, x = np.mgrid[0:128, 0:256, 0:256].astype(np.float32)
(np.sin(x / 9) + np.cos(y / 7) * np.sin(z / 11)).astype(np.float16).tofile(folder + '/h.raw')
said = subprocess.run([ivol, 'convert', folder + '/h.raw', folder + '/hp.ivol', '--dims', '256,256,128', '--type', 'f16',
                       '--brick', '128', '--structure', 'bricked', '--memory', '8', '-f'], capture_output=True, text=True)
import re
found = re.search(r'--memory ([0-9]+) allows it', said.stderr)
least = int(found.group(1)) if found else 0
worst = 0.0
for memory in (least, 2 * least):
    held = peak_mib([folder + '/h.raw', folder + '/h.ivol', '--dims', '256,256,128', '--type', 'f16', '--brick', '128',
                     '--structure', 'bricked', '--memory', str(memory), '-f']) - own
    worst = max(worst, held - memory)
ok = least > 0 and (sanitized or worst <= 0)
print('same' if ok else 'least --memory %d; held up to %.0f MiB more than --memory' % (least, worst))"
# With room for a second layer the next one is read while one is encoded
# (bricked_prefetch): within --memory still, and the same values as the
# layer-at-a-time conversion above.
bands_check bricked-memory-prefetch "$peak_py
room = 4 * need
big = peak_mib([folder + '/s.raw', folder + '/wide.ivol', '--dims', '256,256,128', '--type', 'f32', '--brick', '128',
                '--memory', str(room)])
for name in ('s', 'wide'):
    subprocess.run([ivol, '-q', 'convert', folder + '/' + name + '.ivol', folder + '/' + name + '.back.raw', '-f'], check=True)
same = open(folder + '/s.back.raw', 'rb').read() == open(folder + '/wide.back.raw', 'rb').read()
ok = need > 0 and same and (sanitized or big - own <= room)
print('same' if ok else 'memory %d MiB, held %.0f MiB above %.0f; values equal: %s' % (room, big - own, own, same))"
rm -rf "$brickmem"
