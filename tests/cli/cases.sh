# Sourced by the CLI case scripts: the counters, `check NAME COMMAND...`
# (the command must succeed; its output is shown when it does not) and
# `finish` (the summary line, and the status ctest reads). The command runs
# in the calling shell, so a check may call the script's own functions.
passed=0
failed=0
# The script's own temporary folder (it removes it on exit) holds the log.
cases_log="${work:?cases.sh: set work to the temporary folder of the script first}/.case-log"
check() {
  if "${@:2}" >"$cases_log" 2>&1; then
    echo "ok   $1"
    passed=$((passed + 1))
  else
    echo "FAIL $1"
    sed 's/^/    /' "$cases_log" | head -20
    failed=$((failed + 1))
  fi
}
finish() {
  echo "$passed passed, $failed failed"
  [ "$failed" -eq 0 ]
}
