#!/usr/bin/env bash
# Runs a command under a cgroup v1 memory cap (issue 23: `systemd-run` does
# not work on the development VM, memory.limit_in_bytes does), as root:
#   bench/recon_under_cgroup.sh CAP_MIB COMMAND [ARGS...]
# The cgroup is made under the shell's own memory cgroup (so the cap is the
# tightest along the path, as `ivol recon`'s default --memory reads it) and
# removed afterwards. Prints /usr/bin/time -v's figures on stderr, then the
# cgroup's peak usage, failures and OOM kills.
set -u
cap_mib=$1
shift
own=$(awk -F: '$2 ~ /(^|,)memory(,|$)/ {print $3}' /proc/self/cgroup)
group=/sys/fs/cgroup/memory${own%/}/ivol-bench-$$
mkdir "$group" || exit 1
trap 'rmdir "$group"' EXIT
echo $((cap_mib << 20)) > "$group/memory.limit_in_bytes"
# A child shell joins the cgroup and runs the command; this one watches.
bash -c 'echo $$ > "$1/cgroup.procs"; shift; exec /usr/bin/time -v "$@"' _ "$group" "$@"
status=$?
echo "cgroup: cap ${cap_mib} MiB, exit $status, peak usage $(cat "$group/memory.max_usage_in_bytes") bytes," \
  "failcnt $(cat "$group/memory.failcnt"), $(grep oom_kill "$group/memory.oom_control" || echo 'oom_kill ?')" >&2
exit $status
