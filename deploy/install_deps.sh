#!/usr/bin/env bash
# Installs the Debian 12 packages lfrecon needs that are not installed yet.
# Idempotent and non-interactive: does nothing (and needs no network) when
# everything is present.
set -euo pipefail

PACKAGES=(
  build-essential cmake pkg-config git
  libeigen3-dev
  libopencv-dev libopencv-contrib-dev
  libspdlog-dev libfmt-dev
  libcli11-dev
  libtbb-dev
  nlohmann-json3-dev
  libopenvdb-dev libboost-iostreams-dev libopenexr-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libopen3d-dev
  libzmq3-dev cppzmq-dev protobuf-compiler libprotobuf-dev
  clang-14 libclang-rt-14-dev
  libceres-dev
  jq
  # tests/integration/netns_test: network namespaces and veth pairs (ip netns; skips without root)
  iproute2
  # tests/deploy/k8s_manifests_test.py parses deploy/k8s/ (Debian's python3)
  python3-yaml
  # tests/cli/report_html_test loads report.html in headless Chromium (skips without it)
  chromium
  colmap
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    echo "install_deps: missing packages (${missing[*]}) and not root; run as root" >&2
    exit 1
  fi
fi
echo "install_deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
