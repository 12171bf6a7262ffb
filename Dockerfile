# Build and run mocapstore in a container (used by docker-compose.yml).
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked

FROM debian:bookworm-slim
RUN useradd --system --home /data mocapstore && mkdir -p /data && chown mocapstore /data
COPY --from=build /src/target/release/mocapstore /usr/local/bin/mocapstore
USER mocapstore
WORKDIR /data
EXPOSE 8080
ENTRYPOINT ["mocapstore"]
CMD ["serve", "--listen", "0.0.0.0:8080"]
