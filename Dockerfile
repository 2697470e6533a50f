# syntax=docker/dockerfile:1
# airroads server image: `docker build -t airroads .` then
#   docker run --rm -p 8080:8080 -e AIRROADS_TOKEN="$(head -c 24 /dev/urandom | base64)" \
#       -v airroads-data:/var/lib/airroads airroads
# The server listens on 0.0.0.0 inside the container, which it only does with a token (16 or more
# characters). Any host port works (`-p 127.0.0.1:18180:8080`): the Host check ignores the port.

# Build stage: the workspace's toolchain (rust-version 1.95) and its locked dependencies. The
# registry and the target directory are BuildKit caches kept between builds, so a rebuild compiles
# only what changed (the binary is copied out of the cache, which no layer holds). Behind a
# TLS-intercepting proxy, give cargo the proxy's CA as a build secret (never stored in the image):
#   docker build --secret id=ca,src=/path/to/proxy-ca.pem -t airroads .
FROM rust:1.95-slim-bookworm AS build
WORKDIR /src
COPY . .
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/usr/local/cargo/git \
    --mount=type=cache,target=/src/target \
    --mount=type=secret,id=ca,required=false \
    if [ -s /run/secrets/ca ]; then export CARGO_HTTP_CAINFO=/run/secrets/ca; fi \
    && cargo build --release --locked -p airroads \
    && strip -o /airroads target/release/airroads

# Runtime stage: the binary alone (the policy model and the demo are embedded in it).
FROM debian:bookworm-slim
RUN useradd --system --create-home --home-dir /var/lib/airroads airroads
COPY --from=build /airroads /usr/local/bin/airroads
USER airroads
VOLUME /var/lib/airroads
EXPOSE 8080
HEALTHCHECK --interval=10s --timeout=3s CMD ["airroads", "health", "--url", "http://127.0.0.1:8080/healthz"]
ENTRYPOINT ["airroads", "serve", "--addr", "0.0.0.0:8080", "--data-dir", "/var/lib/airroads"]
