# Multi-stage build of the jointd binary. The runtime image (non-root user,
# health check, serial device mapping) is completed with the daemon (issue 7).
FROM rust:1-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY src ./src
COPY benches ./benches
RUN cargo build --release --locked --bin jointd

FROM debian:bookworm-slim
RUN useradd --system --no-create-home --groups dialout jointd
COPY --from=build /src/target/release/jointd /usr/local/bin/jointd
USER jointd
ENTRYPOINT ["/usr/local/bin/jointd"]
CMD ["--help"]
