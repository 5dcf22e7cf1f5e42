#!/usr/bin/env bash
# Builds the Dockerfile and shows the image running the simulator and answering /healthz.
#
# With a Docker engine: plain `docker build` / `docker run`.
# Without one (our CI and dev machines): Debian's debootstrap makes the base
# root filesystems, buildah imports them as local images, and
# `buildah bud --isolation chroot` builds the unchanged Dockerfile with its
# FROM images substituted through build args:
#   RUNTIME_IMAGE = debootstrap'd bookworm minbase   (for debian:bookworm-slim)
#   RUST_IMAGE    = that base + gcc + this machine's stable Rust toolchain (for rust:1-bookworm)
#
# Usage: scripts/container-check.sh [work-dir]   (needs root; installs debootstrap and buildah)
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${1:-/var/tmp/jointd-container}
PORT=${JOINTD_CHECK_PORT:-18080}
IMAGE=localhost/jointd:check
BUILDAH="buildah --storage-driver vfs"
started=$(date +%s)
mkdir -p "$WORK"

wait_healthz() {
  for _ in $(seq 1 100); do
    if curl -fsS "http://127.0.0.1:$PORT/healthz"; then echo; return 0; fi
    sleep 0.3
  done
  echo "no answer from /healthz on port $PORT" >&2
  return 1
}

if docker info >/dev/null 2>&1; then
  docker build -t "$IMAGE" .
  docker run -d --rm --name jointd-check -p "127.0.0.1:$PORT:8080" "$IMAGE" --sim 4 --listen 0.0.0.0:8080 --insecure
  trap 'docker stop jointd-check >/dev/null' EXIT
  wait_healthz
  exit 0
fi

command -v debootstrap >/dev/null && command -v buildah >/dev/null || {
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap buildah
}

# 1. Runtime base: Debian bookworm minbase.
if ! $BUILDAH inspect --type image localhost/jointd-base:bookworm >/dev/null 2>&1; then
  if [ ! -x "$WORK/rootfs/bin/sh" ]; then
    debootstrap --variant=minbase --include=ca-certificates,curl bookworm "$WORK/rootfs" http://deb.debian.org/debian
  fi
  tar -C "$WORK/rootfs" -cf "$WORK/rootfs.tar" .
  ctr=$($BUILDAH from scratch)
  $BUILDAH add "$ctr" "$WORK/rootfs.tar" /
  $BUILDAH commit --rm "$ctr" localhost/jointd-base:bookworm
fi

# 2. Build base: the runtime base plus a C linker and this machine's stable toolchain.
if ! $BUILDAH inspect --type image localhost/jointd-rust:bookworm >/dev/null 2>&1; then
  toolchain=$(rustc --print sysroot)
  ctr=$($BUILDAH from localhost/jointd-base:bookworm)
  $BUILDAH run --isolation chroot "$ctr" -- sh -c \
    'apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq gcc libc6-dev >/dev/null'
  $BUILDAH copy "$ctr" "$toolchain" /usr/local/rust
  # Registries may be reached through a TLS-inspecting proxy whose CA only
  # the host trusts: give the build stage the host's bundle.
  $BUILDAH copy "$ctr" /etc/ssl/certs/ca-certificates.crt /etc/ssl/certs/ca-certificates.crt
  $BUILDAH config --env PATH=/usr/local/rust/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    --env CARGO_HOME=/usr/local/cargo "$ctr"
  $BUILDAH commit --rm "$ctr" localhost/jointd-rust:bookworm
fi

# 3. The Dockerfile itself, FROM images substituted.
# Docker format: the OCI format has no HEALTHCHECK.
$BUILDAH bud --format docker --isolation chroot \
  --build-arg RUST_IMAGE=localhost/jointd-rust:bookworm \
  --build-arg RUNTIME_IMAGE=localhost/jointd-base:bookworm \
  -t "$IMAGE" .
built=$(date +%s)

# 4. Run it: the simulator inside the image, /healthz from outside.
ctr=$($BUILDAH from "$IMAGE")
$BUILDAH run --isolation chroot "$ctr" -- /usr/local/bin/jointd --sim 4 --listen "127.0.0.1:$PORT" &
runner=$!
trap 'kill $runner 2>/dev/null; pkill -f "jointd --sim 4 --listen 127.0.0.1:$PORT" 2>/dev/null; $BUILDAH rm "$ctr" >/dev/null 2>&1 || true' EXIT
wait_healthz
echo "image user: $($BUILDAH inspect --format '{{.OCIv1.Config.User}}' "$IMAGE")"
echo "healthcheck: $($BUILDAH inspect --format '{{.Docker.Config.Healthcheck}}' "$IMAGE" 2>/dev/null || echo n/a)"
echo "build took $((built - started)) s, whole check $(( $(date +%s) - started )) s"
