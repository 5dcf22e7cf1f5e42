#!/usr/bin/env bash
# Property-based API test: schemathesis generates requests from the OpenAPI
# document the daemon serves, against `jointd --sim 16` (the simulator behind
# the real bus engine), and fails on any 5xx or any response that violates
# the document. Then the daemon must shut down cleanly on SIGTERM (exit 0).
#
# Usage: .ci/schemathesis.sh            (SCHEMATHESIS_EXAMPLES=N to change the bound)
set -euo pipefail
cd "$(dirname "$0")/.."

SCHEMATHESIS_VERSION=4.32.5
EXAMPLES="${SCHEMATHESIS_EXAMPLES:-25}"
WAIT_S=60
TOKEN="ci-$RANDOM$RANDOM"
WORK="$(mktemp -d)"

# A venv of its own under target/: Debian's Python refuses installs
# outside one (externally managed). Made again if an earlier attempt left
# it without pip (python3-venv missing then).
VENV="target/schemathesis-venv"
[ -x "$VENV/bin/pip" ] || python3 -m venv --clear "$VENV"
if ! "$VENV/bin/schemathesis" --version 2>/dev/null | grep -q "$SCHEMATHESIS_VERSION"; then
  "$VENV/bin/pip" install --quiet "schemathesis==$SCHEMATHESIS_VERSION"
fi
PATH="$PWD/$VENV/bin:$PATH"

cargo build --quiet --features bench,ros2 --bin jointd
# Its TMPDIR (the simulator's pty link, default recordings) goes with $WORK.
JOINTD_TOKEN="$TOKEN" TMPDIR="$WORK" target/debug/jointd --sim 16 --listen 127.0.0.1:0 \
  >"$WORK/stdout" 2>"$WORK/stderr" &
PID=$!
cleanup() {
  if kill -0 "$PID" 2>/dev/null; then kill -KILL "$PID" 2>/dev/null || true; fi
  rm -rf "$WORK"
}
trap cleanup EXIT

# The first stdout line names the address (port 0 picks a free one).
BASE=""
for _ in $(seq $((WAIT_S * 10))); do
  BASE="$(sed -n 's/^listening on //p' "$WORK/stdout" | head -n1)"
  [ -n "$BASE" ] && break
  kill -0 "$PID" 2>/dev/null || { cat "$WORK/stderr" >&2; echo "jointd exited early" >&2; exit 1; }
  sleep 0.1
done
[ -n "$BASE" ] || { echo "jointd did not report its address" >&2; exit 1; }
AUTH="Authorization: Bearer $TOKEN"

for _ in $(seq $((WAIT_S * 10))); do
  curl -fsS -H "$AUTH" "$BASE/readyz" >/dev/null 2>&1 && break
  sleep 0.1
done
curl -fsS -H "$AUTH" "$BASE/readyz" >/dev/null || { echo "jointd never became ready" >&2; exit 1; }
# The document under test is the served one (it needs the token too).
curl -fsS -H "$AUTH" "$BASE/openapi.json" -o "$WORK/openapi.json"

echo "== schemathesis $SCHEMATHESIS_VERSION against $BASE ($EXAMPLES examples per operation)"
# Run from the scratch directory: schemathesis keeps a cache in ./.schemathesis.
# At the default priority: niced, it would get a few % of a core beside any
# other busy process and take half an hour instead of a minute.
(cd "$WORK" && schemathesis run openapi.json --url "$BASE" -H "$AUTH" \
  --checks not_a_server_error,response_schema_conformance \
  --max-examples "$EXAMPLES" --workers 1 --seed 5 \
  --request-timeout 20 --suppress-health-check all)

echo "== graceful shutdown"
kill -TERM "$PID"
STATUS=0
wait "$PID" || STATUS=$?
if [ "$STATUS" -ne 0 ]; then
  tail -n 20 "$WORK/stderr" >&2
  echo "jointd exited with $STATUS on SIGTERM (expected 0)" >&2
  exit 1
fi
echo "jointd stopped cleanly"
