#!/usr/bin/env bash
# Installs the Debian 12 packages travbench needs. Idempotent and quiet when all are present.
set -euo pipefail
PACKAGES=(build-essential cmake libembree-dev libtinygltf-dev libopenmesh-dev libbenchmark-dev libgtest-dev
          libcli11-dev nlohmann-json3-dev libtbb-dev python3-matplotlib valgrind
          libgmp-dev libcgal-dev libpng-dev libassimp-dev libcsv-dev)
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "setup: installing ${missing[*]}" >&2
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
