#!/usr/bin/env bash
# Installs vellum's build and test dependencies from Debian 12 packages (needs root or sudo).
# Does nothing when everything is already installed.
set -euo pipefail
packages=(
  build-essential cmake pkg-config ccache
  libopencv-dev libopencv-contrib-dev libeigen3-dev
  liblcm-dev liblcm-bin liblcm-java
  libv4l-dev libsdl2-dev
  googletest libgtest-dev libgmock-dev libbenchmark-dev
  libcgal-dev libsuitesparse-dev nlohmann-json3-dev libexiv2-dev exiv2 libtiff-dev libssl-dev liblcms2-dev clang-format
  libvips-dev libpng-dev iipimage-server lighttpd libimage-exiftool-perl curl
  default-jdk-headless libjchart2d-java xz-utils iproute2 util-linux nftables
  chromium xvfb xdotool clang libclang-rt-14-dev python3
  slurm-wlm munge
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
echo "install-deps: installing ${missing[*]}"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
