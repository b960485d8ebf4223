# Outputs that can't hurt (README, "Outputs"): only a regular file is ever
# replaced, never one of the inputs, never without -f; the name says the
# format written; "-" is standard output for raw samples only, never a
# terminal. Each refusal comes before any work, exits 1, and changes nothing
# in the folder of fixtures ($o) nor leaves anything in $out.
o="$work/outputs"
mkdir -p "$o"
"$IVOL" -q slice "$work/v.ivol" --index 0 -o "$o/s.png"
cp "$work/v.raw" "$o/target.raw"
cp "$work/v.ivol" "$o/b.ivol"
ln -s "$o/target.raw" "$o/link.raw"
ln -s "$o/s.png" "$o/link.png"
ln -s "$o/nowhere.raw" "$o/dangling.raw"
mkdir "$o/dir.raw"
mkfifo "$o/fifo.raw"
ln "$work/v.ivol" "$o/hard.raw"  # a hard link of the input, named as raw output
ln "$work/p.raw" "$o/p.ivol"     # a hard link of recon's input, named as its output
# A device: a null device node of our own where we may make one (root), so
# that a binary that gets this wrong replaces that node, not the system's
# /dev/null (which an older ivol, run as root, did); else /dev/null itself,
# which a user without that right cannot replace either.
device=/dev/null
mknod "$o/null.raw" c 1 3 2>/dev/null && device="$o/null.raw"
# Every name in $o with its type, size and link target, and every file's digest.
outputs_state() {
  find "$o" -mindepth 1 -printf '%P %y %s %l\n' | sort
  find "$o" -type f -exec md5sum {} + | sort
}
# keeps NAME EXIT TEXT -- COMMAND...: as bad, and $o is as it was.
keeps() {
  local before after
  before=$(outputs_state)
  bad "$@"
  after=$(outputs_state)
  if [ "$before" != "$after" ]; then
    echo "FAIL $1: changed $o:"; diff <(echo "$before") <(echo "$after") | head -5 | sed 's/^/    /'
    failed=$((failed + 1))
  fi
}
# Runs a command with its standard output on a pseudo-terminal.
on_terminal=(/usr/bin/python3 -c '
import os, pty, subprocess, sys
master, slave = pty.openpty()
sys.exit(subprocess.run(sys.argv[1:], stdout=slave).returncode)')

keeps out-symlink          1 "is a symbolic link"  -- "$IVOL" convert "$work/v.ivol" "$o/link.raw" -f
keeps out-dangling-symlink 1 "is a symbolic link"  -- "$IVOL" extract "$work/v.ivol" --box 0,0,0,4,4,4 -o "$o/dangling.raw" -f
keeps out-directory-force  1 "is a directory"      -- "$IVOL" convert "$work/v.ivol" "$o/dir.raw" -f
keeps out-fifo             1 "is a FIFO"           -- timeout 20 "$IVOL" convert "$work/v.ivol" "$o/fifo.raw" -f
keeps out-device           1 "is a device"         -- "$IVOL" extract "$work/v.ivol" --box 0,0,0,4,4,4 -o "$device" --to raw -f
keeps out-same-file        1 "is the input"        -- "$IVOL" convert "$o/target.raw" "$o/target.raw" --dims 16,16,16 -f
keeps out-hard-link        1 "is the input"        -- "$IVOL" extract "$work/v.ivol" --box 0,0,0,4,4,4 -o "$o/hard.raw" -f
keeps out-archive-as-raw   1 "named as ivol"       -- "$IVOL" convert "$o/b.ivol" "$o/b.ivol" --to raw -f
keeps extract-onto-archive 1 "named as ivol"       -- "$IVOL" extract "$o/b.ivol" --box 0,0,0,4,4,4 -o "$o/b.ivol" --to raw -f
keeps out-exists           1 "exists (use --force" -- "$IVOL" convert "$work/v.ivol" "$o/target.raw"
keeps slice-exists         1 "exists (use --force" -- "$IVOL" slice "$work/v.ivol" --index 0 -o "$o/s.png"
keeps slice-symlink        1 "is a symbolic link"  -- "$IVOL" slice "$work/v.ivol" --index 0 -o "$o/link.png" -f
bad   slice-jpg            1 "not a .png name"     -- "$IVOL" slice "$work/v.ivol" --index 0 -o "$out/s.jpg"
bad   convert-tif-as-h5    1 "named as tiff"       -- "$IVOL" convert "$work/v.ivol" "$out/x.tif" --to hdf5
bad   stdout-not-raw       1 "raw output only"     -- "$IVOL" convert "$work/v.ivol" - --to tiff
bad   stdout-terminal      1 "terminal"            -- "${on_terminal[@]}" "$IVOL" convert "$work/v.ivol" -
bad   out-no-folder        2 "does not exist"      -- "$IVOL" convert "$work/v.ivol" "$out/nowhere/x.raw"
bad   recon-not-ivol-name  1 "not an .ivol name"   -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" -o "$out/x.raw"
keeps recon-onto-input     1 "is the input"        -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" -o "$o/p.ivol" -f
