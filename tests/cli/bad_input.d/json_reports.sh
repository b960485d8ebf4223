# Machine-readable reports of damaged files: a problem message that quotes
# bytes which are not UTF-8 is still reported as JSON.
vectors="$(dirname "${BASH_SOURCE[0]}")/../../../format-spec/vectors/invalid"
bad verify-json-bad-utf8   2 '"status": "damaged"'   -- "$IVOL" verify --json "$vectors/metadata_bad_utf8.ivol"

# info --json of a file that cannot be read (cut, or empty) prints one JSON
# object on standard output (status, error class, what salvage would get),
# not the text report; the error still goes to standard error, exit 2.
json_cut="$work/json-cut.ivol"
json_whole="$vectors/../valid/framed_octree_5x6x4_uint16_stored.ivol"
head -c $(($(stat -c %s "$json_whole") / 2)) "$json_whole" > "$json_cut"
: > "$work/json-empty.ivol"
for f in "$json_cut" "$work/json-empty.ivol"; do
  name=info-json-unreadable-$(basename "$f" .ivol)
  said=$("$IVOL" info --json "$f" 2>/dev/null)
  got=$?
  if [ "$got" -eq 2 ] && /usr/bin/python3 -c "
import json, sys
d = json.loads(sys.argv[1])
assert d['status'] == 'unreadable' and d['error_class'] and isinstance(d['salvage'], list)" "$said" 2>/dev/null; then
    echo "ok   $name"
    passed=$((passed + 1))
  else
    echo "FAIL $name: exit $got, standard output not one JSON object: $(head -c 200 <<<"$said")"
    failed=$((failed + 1))
  fi
done
