#!/usr/bin/env bash
# A base image for deploy/ where public images cannot be pulled: a minimal Debian root made
# with debootstrap, with Python (and its venv module) and Mosquitto from Debian's packages,
# imported into Docker. It serves as both images of docker-compose.yml:
#   image=$(deploy/debian-base.sh)
#   AIOFINS_PYTHON_IMAGE=$image AIOFINS_MOSQUITTO_IMAGE=$image \
#       docker-compose -f deploy/docker-compose.yml up --build
# Prints the image's name; does nothing more if the image exists (Docker keeps it: reruns
# cost nothing). Needs root, debootstrap and a Docker daemon; about 130 MB.
# The host's CA bundle is copied in, so pip in a build trusts what the host trusts (a
# TLS-inspecting proxy included).
set -euo pipefail

image=${AIOFINS_BASE_IMAGE:-aiofins-debian:bookworm}
suite=${AIOFINS_DEBIAN_SUITE:-bookworm}
mirror=${AIOFINS_DEBIAN_MIRROR:-http://deb.debian.org/debian}
# The downloaded packages are kept here: a root made again (a wiped Docker) downloads nothing.
cache=${AIOFINS_DEBOOTSTRAP_CACHE:-/var/cache/aiofins-debootstrap}

if docker image inspect "$image" >/dev/null 2>&1; then
    echo "$image"
    exit 0
fi
root=$(mktemp -d /var/tmp/aiofins-debian.XXXXXX)
trap 'rm -rf "$root"' EXIT
mkdir -p "$cache"
debootstrap --variant=minbase --include=python3-venv,mosquitto --cache-dir="$cache" \
    "$suite" "$root" "$mirror" >&2
# What a container does not use: package lists, documentation, translations.
rm -rf "$root"/var/lib/apt/lists/* "$root"/var/cache/apt/archives/*.deb "$root"/var/cache/apt/*.bin \
    "$root"/usr/share/doc/* "$root"/usr/share/man/* "$root"/usr/share/info/* \
    "$root"/usr/share/locale/*
ca=/etc/ssl/certs/ca-certificates.crt
if [ -f "$ca" ]; then
    install -D -m 644 "$ca" "$root$ca"
fi
tar -C "$root" -c . | docker import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'ENV LANG=C.UTF-8' \
    --change "ENV PIP_CERT=$ca" \
    --message "debootstrap $suite minbase + python3-venv, mosquitto (aiofins deploy/)" \
    - "$image" >/dev/null
echo "$image"
