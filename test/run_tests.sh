#!/bin/sh
# Runs every test program from the repository root with the build folder as
# its only argument, then prints the totals as "N passed, N failed".
build=$1; shift
passed=0; failed=0
for t in "$@"; do
    out=$("$t" "$build" 2>&1); code=$?
    printf '%s\n' "$out"
    p=$(printf '%s\n' "$out" | grep -c '^PASS ')
    f=$(printf '%s\n' "$out" | grep -c '^FAIL ')
    if [ "$code" -ne 0 ] && [ "$f" -eq 0 ]; then
        echo "FAIL $t exited with status $code"
        f=1
    fi
    passed=$((passed + p)); failed=$((failed + f))
done
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
