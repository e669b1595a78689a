#!/usr/bin/env bash
# System packages the tests run as real programs: nginx (the reverse proxy of the deployment
# topology), docker-compose and docker.io (validate docker-compose.yml and run it as containers;
# no image is pulled), chromium (the console's and the video viewer's browser tests drive
# Debian's headless Chromium; no browser is downloaded), janus and coturn (the media services,
# started with the very configuration files compose mounts, and by the video tests), rtklib
# (str2str, a real NTRIP 1 client). Idempotent.
set -euo pipefail
need=()
command -v nginx >/dev/null 2>&1 || [ -x /usr/sbin/nginx ] || need+=(nginx)
[ -f /usr/lib/nginx/modules/ngx_stream_module.so ] || need+=(libnginx-mod-stream)  # NTRIP's TCP
command -v docker-compose >/dev/null 2>&1 || need+=(docker-compose)
# the compose stack as containers (tests/deploy/test_stack.py): Docker's daemon, and debootstrap
# for the Debian base every image is built on (no image registry is reached)
[ -x /usr/sbin/dockerd ] || need+=(docker.io)
command -v debootstrap >/dev/null 2>&1 || need+=(debootstrap)
[ -x /usr/bin/chromium ] || need+=(chromium)
command -v janus >/dev/null 2>&1 || need+=(janus)
command -v turnserver >/dev/null 2>&1 || need+=(coturn)
# the Janus tests build a private network namespace (unshare, ip link ... type veth)
command -v ip >/dev/null 2>&1 || need+=(iproute2)
command -v unshare >/dev/null 2>&1 || need+=(util-linux)
command -v str2str >/dev/null 2>&1 || need+=(rtklib)  # a real NTRIP 1 client (tests/server/test_ntrip_caster.py)
command -v systemd-analyze >/dev/null 2>&1 || need+=(systemd)  # verifies deploy/systemd/ (tests/deploy/test_systemd_units.py)
if [ ${#need[@]} -eq 0 ]; then
    echo "system packages already installed"
    exit 0
fi
export DEBIAN_FRONTEND=noninteractive
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
$SUDO apt-get update
$SUDO apt-get install -y "${need[@]}"
# the packages' own services would hold ports for nothing: the tests start their own
if command -v systemctl >/dev/null 2>&1 && [ -d /run/systemd/system ]; then
    $SUDO systemctl disable --now nginx janus coturn >/dev/null 2>&1 || true
elif command -v service >/dev/null 2>&1; then
    for svc in nginx janus coturn; do $SUDO service "$svc" stop >/dev/null 2>&1 || true; done
fi
echo "installed: ${need[*]}"
