#!/usr/bin/env bash
# A base image for deploy/ where public images cannot be pulled: a minimal Debian root with
# Python (and its venv module) and Mosquitto from Debian's packages, imported into Docker. It
# serves as both images of docker-compose.yml:
#   image=$(deploy/debian-base.sh)
#   AIOFINS_PYTHON_IMAGE=$image AIOFINS_MOSQUITTO_IMAGE=$image \
#       docker-compose -f deploy/docker-compose.yml up --build
# Prints the image's name; does nothing more if the image exists (Docker keeps it: reruns
# cost nothing). Needs root, a Debian host's apt-get and dpkg-deb, and a Docker daemon; about
# 100 MB.
#
# How: apt-get, with a state of its own (this host's packages untouched), resolves python3-venv
# and mosquitto with their dependencies from an empty system and downloads them; each package's
# files are unpacked into the root (dpkg-deb), merged /usr as Debian 12 has it. No package
# manager runs inside, no maintainer script: a container needs the files, the users of
# base-passwd and the linker's cache, made here. (debootstrap did the same in 2-3 minutes on a
# busy 2-core machine: minbase's 124 packages, each unpacked twice and configured by dpkg;
# this takes about 30 s.) So apt and dpkg do not work in the image: it is a base for
# deploy/Dockerfile, not a Debian to install more into.
# The host's CA bundle is copied in, so pip in a build trusts what the host trusts (a
# TLS-inspecting proxy included).
set -euo pipefail

image=${AIOFINS_BASE_IMAGE:-aiofins-debian:bookworm}
suite=${AIOFINS_DEBIAN_SUITE:-bookworm}
mirror=${AIOFINS_DEBIAN_MIRROR:-http://deb.debian.org/debian}
# The downloaded packages are kept here: a root made again (a wiped Docker) downloads nothing.
cache=${AIOFINS_DEB_CACHE:-/var/cache/aiofins-debian}
packages=(python3-venv mosquitto base-files base-passwd dash coreutils findutils libc-bin)

if docker image inspect "$image" >/dev/null 2>&1; then
    echo "$image"
    exit 0
fi
work=$(mktemp -d /var/tmp/aiofins-debian.XXXXXX)
trap 'rm -rf "$work"' EXIT
root=$work/root
apt=$work/apt
mkdir -p "$cache/partial" "$root/usr" "$apt/lists/partial" "$apt/state" "$apt/preferences.d"
: >"$apt/status" # an empty system: every dependency is resolved and fetched
echo "deb $mirror $suite main" >"$apt/sources.list"
apt_options=(
    -o "Dir::Etc::SourceList=$apt/sources.list" -o Dir::Etc::SourceParts=/dev/null
    -o Dir::Etc::Preferences=/dev/null -o "Dir::Etc::PreferencesParts=$apt/preferences.d"
    -o "Dir::State=$apt/state" -o "Dir::State::Lists=$apt/lists"
    -o "Dir::State::status=$apt/status" -o "Dir::Cache=$apt" -o "Dir::Cache::archives=$cache"
    -o APT::Install-Recommends=false -o Acquire::Languages=none -o Debug::NoLocking=1
    -o APT::Sandbox::User=root
)
apt-get "${apt_options[@]}" -qq update >&2
apt-get "${apt_options[@]}" -qq -y --download-only install "${packages[@]}" >&2
for dir in bin sbin lib lib64; do # merged /usr
    mkdir -p "$root/usr/$dir"
    ln -s "usr/$dir" "$root/$dir"
done
apt-get "${apt_options[@]}" -s install "${packages[@]}" | awk '/^Inst / {print $2, $3}' |
    while read -r name version; do
        version=${version#[(]}
        file=$(printf '%s/%s_%s_*.deb' "$cache" "$name" "${version//:/%3a}")
        # shellcheck disable=SC2086 # the glob (the architecture) is meant
        dpkg-deb --fsys-tarfile $file | tar -x --keep-directory-symlink -C "$root"
    done
cp "$root/usr/share/base-passwd/passwd.master" "$root/etc/passwd"
cp "$root/usr/share/base-passwd/group.master" "$root/etc/group"
chroot "$root" /sbin/ldconfig
# What a container does not use: documentation, manual pages, translations.
rm -rf "$root"/usr/share/doc/* "$root"/usr/share/man/* "$root"/usr/share/info/* \
    "$root"/usr/share/locale/*
ca=/etc/ssl/certs/ca-certificates.crt
if [ -f "$ca" ]; then
    install -D -m 644 "$ca" "$root$ca"
fi
tar -C "$root" -c . | docker import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'ENV LANG=C.UTF-8' \
    --change "ENV PIP_CERT=$ca" \
    --message "Debian $suite: python3-venv, mosquitto and their dependencies (aiofins deploy/)" \
    - "$image" >/dev/null
echo "$image"
