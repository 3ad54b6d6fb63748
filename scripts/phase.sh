#!/usr/bin/env bash
# Runs one phase of `make test` / `make run` (a command line) and prints how long it took, as
# `phase NAME: N s (ok|failed)`, so a log of `make test` gives each phase's time (docs/testing.md) without a second
# run. The command's exit status is kept.
#
#   scripts/phase.sh NAME COMMAND [ARG...]
set -uo pipefail

name="${1:?usage: phase.sh NAME COMMAND [ARG...]}"
shift
start=$(date +%s)
"$@"
status=$?
end=$(date +%s)
verdict=ok
((status == 0)) || verdict=failed
printf 'phase %s: %d s (%s)\n' "$name" "$((end - start))" "$verdict" >&2
exit "$status"
