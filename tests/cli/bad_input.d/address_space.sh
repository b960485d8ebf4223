# Under an address-space cap, a failed allocation or a thread that cannot
# start ends the command with limit-exceeded and nothing left behind, never
# an abort: an allocation in a reader's decoding thread escaped it
# (std::terminate, exit 134, the temporary output left), and so did a
# thread that could not start (std::system_error). Work split over threads
# now runs on fewer when one cannot start (libformat/src/thread_parts.hpp).
# (Below about 150 MB the process cannot start at all: liblog4cplus, which
# libopenvdb loads, starts threads as it loads.)
asp="$work/address-space"
mkdir -p "$asp"
# A smooth float32 volume (bricks of byte planes that compress: decoding
# allocates in the reader's threads).
/usr/bin/python3 -c "
import numpy as np
z, y, x = np.mgrid[0:256, 0:256, 0:256].astype(np.float32)
(np.sin(x / 9) + np.cos(y / 7) * np.sin(z / 11)).astype(np.float32).tofile('$asp/n.raw')"
"$IVOL" -q convert "$asp/n.raw" "$asp/n.ivol" --dims 256,256,256 --type f32
asp_cap=(prlimit --as=200000000)  # 200 MB: main aborted here 3 times in 3
[ "${IVOL_SANITIZED:-0}" = 1 ] && asp_cap=()
if [ ${#asp_cap[@]} -gt 0 ]; then
  bad address-space-extract 2 "(limit-exceeded)" -- "${asp_cap[@]}" "$IVOL" extract "$asp/n.ivol" --box 0,0,0,256,256,256 -o "$out/x.raw"
  # extract has no --memory: the message does not offer one.
  if "${asp_cap[@]}" "$IVOL" extract "$asp/n.ivol" --box 0,0,0,256,256,256 -o "$out/x.raw" 2>&1 | grep -q -- "--memory"; then
    echo "FAIL address-space-extract-no-memory-option: the message names --memory, which extract lacks"
    failed=$((failed + 1))
  else
    echo "ok   address-space-extract-no-memory-option"
    passed=$((passed + 1))
  fi
  rm -rf "${out:?}"/* "${out:?}"/.[!.]* 2>/dev/null
fi
rm -rf "$asp"
