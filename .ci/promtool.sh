#!/usr/bin/env bash
# `promtool check metrics` on a live daemon's /metrics: a
# simulated bus with an enabled, moving joint and a few config reads, so the
# histograms and per-device families are filled. Fails on any problem.
set -euo pipefail
cd "$(dirname "$0")/.."

WAIT_S=60
WORK="$(mktemp -d)"

if ! command -v promtool >/dev/null; then
  if [ "$(id -u)" -eq 0 ]; then SUDO=""; else SUDO="sudo"; fi
  $SUDO apt-get update -qq
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends prometheus >/dev/null
fi
promtool --version | head -n1

cargo build --quiet --features bench,ros2 --bin jointd
# Its TMPDIR (the simulator's pty link, default recordings) goes with $WORK.
TMPDIR="$WORK" target/debug/jointd --sim 4 --listen 127.0.0.1:0 >"$WORK/stdout" 2>"$WORK/stderr" &
PID=$!
cleanup() {
  if kill -0 "$PID" 2>/dev/null; then kill -TERM "$PID" 2>/dev/null || true; wait "$PID" 2>/dev/null || true; fi
  rm -rf "$WORK"
}
trap cleanup EXIT

BASE=""
for _ in $(seq $((WAIT_S * 10))); do
  BASE="$(sed -n 's/^listening on //p' "$WORK/stdout" | head -n1)"
  [ -n "$BASE" ] && break
  kill -0 "$PID" 2>/dev/null || { cat "$WORK/stderr" >&2; echo "jointd exited early" >&2; exit 1; }
  sleep 0.1
done
[ -n "$BASE" ] || { echo "jointd did not report its address" >&2; exit 1; }
API="$BASE/api/v1/buses/sim0"
J='content-type: application/json'

for _ in $(seq $((WAIT_S * 10))); do
  curl -sf "$API/devices/1" >/dev/null && break
  sleep 0.1
done
curl -sf -X POST "$API/devices/1/enable" >/dev/null
# The first enable aligns the encoder (about a second); a target before
# the joint runs is refused with 409.
for _ in $(seq $((WAIT_S * 10))); do
  curl -sf "$API/devices/1" | grep -q '"state":"run"' && break
  sleep 0.1
done
curl -sf -X PUT "$API/devices/1/target" -H "$J" -d '{"position_deg": 20, "speed_dps": 30}' >/dev/null
curl -sf "$API/devices/2/config" >/dev/null
sleep 1

curl -sf "$BASE/metrics" >"$WORK/metrics"
echo "$(grep -c '^# TYPE' "$WORK/metrics") families"
PROBLEMS="$(promtool check metrics <"$WORK/metrics" 2>&1 || true)"
if [ -n "$PROBLEMS" ]; then
  echo "promtool check metrics found problems:" >&2
  echo "$PROBLEMS" >&2
  exit 1
fi
echo "promtool check metrics: 0 problems"
