# Mistyped option values: every one is a bad command line (exit 1), named
# in the message, found before any work, leaving nothing behind. Each value
# here was once taken in part ("0.05mm" as 0.05, "10,5" as 10..11) or
# reported as bad data (exit 2).
raw=(convert "$work/v.raw" "$out/x.ivol" --dims 16,16,16)
bad opt-voxel-size-unit    1 "--voxel-size: '0.05mm'" -- "$IVOL" "${raw[@]}" --voxel-size 0.05mm
bad opt-voxel-size-zero    1 "--voxel-size"           -- "$IVOL" "${raw[@]}" --voxel-size 0
bad opt-voxel-size-two     1 "--voxel-size"           -- "$IVOL" "${raw[@]}" --voxel-size 1,2
bad opt-origin-text        1 "--origin"               -- "$IVOL" "${raw[@]}" --origin 1,2,x
bad opt-keep-margin-neg    1 "--keep"                 -- "$IVOL" "${raw[@]}" --keep threshold=1,margin=-1
bad opt-keep-unknown       1 "--keep"                 -- "$IVOL" "${raw[@]}" --keep threshold=1,margins=2
bad opt-keep-no-threshold  1 "--keep"                 -- "$IVOL" "${raw[@]}" --keep margin=2
bad opt-dims-negative      1 "--dims"                 -- "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16,-16
bad opt-dims-two           1 "--dims"                 -- "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16
bad opt-dims-float         1 "--dims"                 -- "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16,16.5
bad opt-type-word          1 "--type"                 -- "$IVOL" "${raw[@]}" --type u12
bad opt-encoding-word      1 "--encoding"             -- "$IVOL" "${raw[@]}" --encoding float64
bad opt-endian-word        1 "--endian"               -- "$IVOL" "${raw[@]}" --endian middle
bad opt-header-negative    1 "--header-bytes"         -- "$IVOL" "${raw[@]}" --header-bytes -4
bad opt-to-word            1 "--to"                   -- "$IVOL" convert "$work/v.ivol" "$out/x.raw" --to jpeg
bad opt-out-type-word      1 "--out-type"             -- "$IVOL" convert "$work/v.ivol" "$out/x.raw" --out-type u7
bad opt-level-negative     1 "--level"                -- "$IVOL" convert "$work/v.ivol" "$out/x.raw" --level -1
bad opt-memory-negative    1 "--memory"               -- "$IVOL" "${raw[@]}" --memory -1
bad opt-window-reversed    1 "--window"               -- "$IVOL" slice "$work/v.ivol" --index 0 --window 10,5 -o "$out/x.png"
bad opt-window-one         1 "--window"               -- "$IVOL" slice "$work/v.ivol" --index 0 --window 10 -o "$out/x.png"
bad opt-slice-level        1 "--level"                -- "$IVOL" slice "$work/v.ivol" --index 0 --level 9 -o "$out/x.png"
bad opt-extract-level      1 "--level: 9 is past the file's coarsest level" -- "$IVOL" extract "$work/v.ivol" --box 0,0,0,1,1,1 --level 9 -o "$out/x.raw"
bad opt-convert-level      1 "--level: 99 is past the file's coarsest level" -- "$IVOL" convert "$work/v.ivol" "$out/x.raw" --level 99
bad opt-box-reversed       1 "--box"                  -- "$IVOL" extract "$work/v.ivol" --box 8,0,0,4,4,4 -o "$out/x.raw"
bad opt-box-five           1 "--box"                  -- "$IVOL" extract "$work/v.ivol" --box 0,0,0,4,4 -o "$out/x.raw"
bad opt-box-negative       1 "--box"                  -- "$IVOL" extract "$work/v.ivol" --box -1,0,0,4,4,4 -o "$out/x.raw"
bad opt-extract-type       1 "--type"                 -- "$IVOL" extract "$work/v.ivol" --box 0,0,0,4,4,4 --type int -o "$out/x.raw"
bad opt-recon-size-text    1 "--size"                 -- "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 16x16 --voxel 1.5 -o "$out/x.ivol"
bad opt-recon-voxel-unit   1 "--voxel"                -- "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 16 --voxel 1.5mm -o "$out/x.ivol"
bad opt-recon-origin       1 "--origin"               -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --origin 0,0 -o "$out/x.ivol"
bad opt-recon-detector     1 "--detector"             -- "$IVOL" recon "$work/p.raw" --geometry "$work/p.xml" --pitch 1.5 --detector 32 --views 20 "${grid[@]}" -o "$out/x.ivol"
bad opt-recon-pitch-zero   1 "--pitch"                -- "$IVOL" recon "$work/p.raw" --geometry "$work/p.xml" --pitch 0 --detector 32,32 --views 20 "${grid[@]}" -o "$out/x.ivol"
bad opt-recon-offset       1 "--offset"               -- "$IVOL" recon "$work/q.h5" --sid 600 --sdd 1200 --offset 1 --pitch 1.5 "${grid[@]}" -o "$out/x.ivol"
bad opt-recon-memory-neg   1 "--memory"               -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --memory -64 -o "$out/x.ivol"
# 0 once meant the default (the largest budget), and 2^44 MiB or more wrapped
# round 2^64 bytes: a budget of 0 B, or 1 MiB and an octree, exit 0.
bad opt-recon-memory-zero  1 "--memory: '0' MiB is no memory" -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --memory 0 -o "$out/x.ivol"
bad opt-recon-memory-wraps 1 "--memory: '17592186044417' MiB is more bytes than 64 bits hold" -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --memory 17592186044417 -o "$out/x.ivol"
bad opt-recon-device-zero  1 "--device-memory: '0' MiB is no memory" -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --device-memory 0 -o "$out/x.ivol"
bad opt-memory-zero        1 "--memory: '0' MiB is no memory" -- "$IVOL" "${raw[@]}" --memory 0
bad opt-memory-wraps       1 "--memory: '17592186044416' MiB is more bytes than 64 bits hold" -- "$IVOL" "${raw[@]}" --memory 17592186044416
bad opt-recon-keep         1 "--keep"                 -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --keep threshold=otsu,margin=x -o "$out/x.ivol"
bad opt-phantom-pitch      1 "--pitch"                -- "$IVOL" phantom thin-pipe --views 4 --detector 8 --pitch 1,2,3 -o "$out/x.h5"
bad opt-phantom-geometry   1 "--geometry-out"         -- "$IVOL" phantom thin-pipe --views 4 --detector 8 --geometry-out "$out/g.txt" -o "$out/x.h5"
bad opt-recon-arc-zero     1 "--arc"                  -- "$IVOL" recon "$work/q.h5" --sid 600 --sdd 1200 --arc 0 --pitch 1.5 "${grid[@]}" -o "$out/x.ivol"
bad opt-recon-angle-nan    1 "--first-angle"          -- "$IVOL" recon "$work/q.h5" --sid 600 --sdd 1200 --first-angle nan --pitch 1.5 "${grid[@]}" -o "$out/x.ivol"
bad opt-recon-cutoff-nan   1 "--cutoff"               -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --cutoff nan -o "$out/x.ivol"
bad opt-recon-incident     1 "--incident"             -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --incident -1 -o "$out/x.ivol"
bad opt-background-inf     1 "--background"           -- "$IVOL" convert "$work/v.ivol" "$out/x.vdb" --background inf
bad opt-phantom-arc        1 "--arc"                  -- "$IVOL" phantom thin-pipe --views 4 --detector 8 --arc 400 -o "$out/x.h5"
bad opt-recon-device-neg   1 "--device"               -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --device -1 -o "$out/x.ivol"
