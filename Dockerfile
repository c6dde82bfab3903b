# Multi-stage build of the sylva binary; runs as a non-root user with the
# configurations baked in.
FROM rust:1.95-slim-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY src ./src
COPY shaders ./shaders
COPY benches ./benches
RUN cargo build --release --locked --bin sylva

FROM debian:bookworm-slim
RUN useradd --system --uid 10001 --home /var/lib/sylva sylva && mkdir -p /var/lib/sylva && chown sylva /var/lib/sylva
COPY --from=build /src/target/release/sylva /usr/local/bin/sylva
COPY config /etc/sylva
USER sylva
WORKDIR /var/lib/sylva
ENTRYPOINT ["sylva"]
CMD ["info", "--config", "/etc/sylva/default.toml"]
