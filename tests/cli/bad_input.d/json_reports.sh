# Machine-readable reports of damaged files: a problem message that quotes
# bytes which are not UTF-8 is still reported as JSON.
vectors="$(dirname "${BASH_SOURCE[0]}")/../../../format-spec/vectors/invalid"
bad verify-json-bad-utf8   2 '"status": "damaged"'   -- "$IVOL" verify --json "$vectors/metadata_bad_utf8.ivol"
