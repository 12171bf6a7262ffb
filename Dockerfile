# Build and run mocapstore in a container (used by docker-compose.yml).
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked

FROM debian:bookworm-slim
RUN useradd --system --home /data mocapstore && mkdir -p /data && chown mocapstore /data
COPY --from=build /src/target/release/mocapstore /usr/local/bin/mocapstore
COPY scripts/docker-entrypoint.sh /usr/local/bin/docker-entrypoint.sh
USER mocapstore
WORKDIR /data
EXPOSE 8080
# The first start creates an admin token (secret in /data/admin-token, not in the log):
# `serve` refuses a non-loopback address without one.
ENTRYPOINT ["docker-entrypoint.sh"]
CMD ["serve", "--listen", "0.0.0.0:8080"]
