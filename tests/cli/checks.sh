# Shared by the CLI test scripts (sourced): counters, ok/fail, expect_fail, and the closing
# line CTest's log readers understand ("N passed, N failed").
passed=0; failed=0
ok()   { passed=$((passed + 1)); echo "ok: $1"; }
fail() { failed=$((failed + 1)); echo "FAIL: $1"; }

# expect_fail NAME REGEX CMD... : exit code must be non-zero and stderr must match REGEX
expect_fail() {
  local name="$1" re="$2"; shift 2
  local err; err=$("$@" 2>&1 >/dev/null); local rc=$?
  if [ $rc -ne 0 ] && grep -Eq -- "$re" <<<"$err"; then ok "$name"; else fail "$name (rc=$rc, stderr: $err)"; fi
}

# finish: print the closing line and exit non-zero when anything failed
finish() {
  echo "$passed passed, $failed failed"
  [ "$failed" -eq 0 ]
}
