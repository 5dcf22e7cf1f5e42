# jointd: multi-stage build of one static-ish binary, run as a non-root user.
#
#   docker build -t jointd .
#   docker run --rm -p 127.0.0.1:8080:8080 -e JOINTD_TOKEN=change-me jointd          # simulated bus
#   docker run --rm --device /dev/ttyUSB0 -p 127.0.0.1:8080:8080 -e JOINTD_TOKEN=change-me \
#       jointd --bus /dev/ttyUSB0@500000 --listen 0.0.0.0:8080                         # real hardware
#
# The FROM images are build args so machines without a registry can substitute
# local bases (scripts/container-check.sh); with Docker the defaults are used.
ARG RUST_IMAGE=rust:1-bookworm
ARG RUNTIME_IMAGE=debian:bookworm-slim

FROM ${RUST_IMAGE} AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked --features ros2 --bin jointd \
 && install -s -m 0755 target/release/jointd /usr/local/bin/jointd

FROM ${RUNTIME_IMAGE}
# curl serves the health check; the jointd user is in dialout to open serial adapters.
RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends curl ca-certificates \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --no-create-home --shell /usr/sbin/nologin --groups dialout jointd
COPY --from=build /usr/local/bin/jointd /usr/local/bin/jointd
USER jointd
EXPOSE 8080
HEALTHCHECK --interval=10s --timeout=3s --start-period=5s --retries=3 \
  CMD curl -fsS http://127.0.0.1:8080/healthz || exit 1
ENTRYPOINT ["/usr/local/bin/jointd"]
# Default: a simulated bus of 16 joints, reachable through the port mapping.
# Binding beyond loopback needs a token (JOINTD_TOKEN or JOINTD_TOKEN_FILE) or
# --insecure. Browsers reaching it as localhost/127.0.0.1 (any port) just work;
# other names or LAN addresses go in JOINTD_ALLOWED_HOSTS (else 421). The
# health check's /healthz is served under any Host.
CMD ["--sim", "16", "--listen", "0.0.0.0:8080"]
