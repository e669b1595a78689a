#!/usr/bin/env bash
# Install InfluxDB 1.x (Debian's `influxdb` package) for the telemetry store tests; idempotent.
# The tests start their own influxd on a free port; the system service is not needed or wanted.
set -euo pipefail
if command -v influxd >/dev/null 2>&1; then
    echo "influxd already installed: $(influxd version 2>/dev/null || true)"
    exit 0
fi
export DEBIAN_FRONTEND=noninteractive
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
$SUDO apt-get update
$SUDO apt-get install -y influxdb
# If the package's postinst started the system service (policy-rc.d may have prevented it), stop it
# and keep it from starting at boot: it would hold 127.0.0.1:8088 and :8086 for nothing.
if command -v systemctl >/dev/null 2>&1 && [ -d /run/systemd/system ]; then
    $SUDO systemctl disable --now influxdb >/dev/null 2>&1 || true
elif command -v service >/dev/null 2>&1; then
    $SUDO service influxdb stop >/dev/null 2>&1 || true
fi
echo "installed: $(influxd version)"
