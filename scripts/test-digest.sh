#!/usr/bin/env bash
# Runs a test command (`cargo nextest run ...` or `cargo test ...`) with its output passed through, and when it fails,
# ends with a digest: each failed test's name and the first lines of its error, and for a test ended at its ceiling
# (nextest's TIMEOUT) the last thing it said it was waiting for (`waiting up to N s for WHAT on CHANNEL`, printed by
# tests/support/wait.rs). A CI log is often read from its tail; the digest says which tests and why without
# scrolling back. The exit status is kept.
#
#   scripts/test-digest.sh COMMAND [ARG...]
set -uo pipefail

log=$(mktemp)
trap 'rm -f "$log"' EXIT
"$@" 2>&1 | tee "$log"
status=${PIPESTATUS[0]}
if ((status != 0)); then
    echo "failed tests (first lines of each one's error):"
    awk '
        function flush() {
            if (name != "" && kind == "TIMEOUT")
                printf "    ended at the ceiling%s\n", (waiting != "" ? ", " waiting : "");
            name = ""; waiting = ""
        }
        # cargo test: "---- NAME stdout ----" opens a failed test'"'"'s output.
        /^---- .* stdout ----$/ { flush(); name = $2; kind = "FAIL"; left = 2; next }
        /^(failures|successes):$/ && !summary { flush() }
        # nextest: after its Summary line, "FAIL [ 1.0s] (3/9) BINARY TEST" or "TIMEOUT [...]" opens each one.
        /^ *Summary \[/ { summary = 1; next }
        summary && /^ *(FAIL|TIMEOUT|SIGSEGV|SIGABRT|ABORT) \[/ {
            flush(); kind = $1; name = $(NF - 1) " " $NF; left = 2
            printf "  %s %s\n", kind, name; next
        }
        name != "" && /waiting up to/ { sub(/^ +/, ""); waiting = substr($0, 1, 200) }
        name != "" && left > 0 && (/Error: / || /panicked at/ || after) {
            line = $0; sub(/^ +/, "", line)
            if (!summary && left == 2) printf "  %s: ", name; else printf "    ";
            print substr(line, 1, 240);
            after = /panicked at/; left--;
            next
        }
        END { flush() }
    ' "$log" | head -n 60
fi
exit "$status"
