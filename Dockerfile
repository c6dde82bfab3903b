# Multi-stage build of the tile server: the release binary with the server
# feature only, on a slim Debian, running as a non-root user with the
# configurations baked in at /etc/sylva. Tiles are cached in /var/lib/sylva/cache
# (mount a volume there to keep them, or share it between replicas).
FROM rust:1.95-slim-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY .cargo ./.cargo
COPY src ./src
COPY assets ./assets
COPY examples ./examples
RUN cargo build --release --locked --no-default-features --features server --bin sylva

FROM debian:bookworm-slim
RUN useradd --system --uid 10001 --home /var/lib/sylva sylva \
 && mkdir -p /var/lib/sylva/cache && chown -R sylva /var/lib/sylva
COPY --from=build /src/target/release/sylva /usr/local/bin/sylva
COPY config /etc/sylva
USER sylva
WORKDIR /var/lib/sylva
EXPOSE 8080
STOPSIGNAL SIGTERM
ENTRYPOINT ["sylva"]
# The embedded demo region; pass `serve --config /etc/sylva/... ` for another.
# The example configurations name their data as ../shared/data beside the
# repository, which is /shared/data here: mount the data there.
CMD ["serve", "--bind", "0.0.0.0:8080", "--cache-dir", "/var/lib/sylva/cache"]
