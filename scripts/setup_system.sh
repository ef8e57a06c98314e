#!/usr/bin/env bash
# Installs the system packages Parallax needs on Debian 12 (bookworm):
# Mesa lavapipe with ray tracing (bookworm-backports), the Vulkan headers/loader and validation layers,
# glslang, a C++ toolchain and Python's venv, and Debian's Blender 3.4 (the legacy add-on's
# oldest supported Blender, and the GUI for viewport tests). Idempotent: quick when done.
set -euo pipefail

need_pkgs=(build-essential cmake python3-venv python3-dev libvulkan-dev libvulkan1 glslang-tools vulkan-tools)
# Khronos validation (1.3.239, matching bookworm's headers and loader): the render tests run
# under it (PARALLAX_VALIDATION=1, tests/render/conftest.py).
need_pkgs+=(vulkan-validationlayers)
blender_pkgs=(blender python3-numpy xvfb x11-apps xdotool)  # GUI tests: Xvfb, xwd, xdotool
need_pkgs+=(libllvm19)  # Mitsuba 3's llvm_ad_rgb variant (bench/mitsuba_peer.py); drjit aborts on LLVM 15
sudo_cmd=""
if [ "$(id -u)" != 0 ]; then sudo_cmd="sudo"; fi

lavapipe_has_rt() {
  local v
  v=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true)
  [ -n "$v" ] && dpkg --compare-versions "$v" ge 24.1
}

missing=()
for p in "${need_pkgs[@]}" "${blender_pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ] && lavapipe_has_rt; then
  exit 0
fi

# Add bookworm-backports by copying the machine's own Debian entry (no mirror names here).
backports_file=/etc/apt/sources.list.d/parallax-bookworm-backports.sources
if ! grep -rqs "bookworm-backports" /etc/apt/sources.list /etc/apt/sources.list.d/; then
  if [ -f /etc/apt/sources.list.d/debian.sources ]; then
    # deb822: take the first stanza whose Suites has plain "bookworm".
    awk -v RS= -v ORS='\n\n' '/Suites:[^\n]*bookworm( |\n|$)/ && !/security/ { print; exit }' \
      /etc/apt/sources.list.d/debian.sources \
      | sed -E 's/^Suites:.*/Suites: bookworm-backports/' \
      | $sudo_cmd tee "$backports_file" >/dev/null
  elif [ -f /etc/apt/sources.list ]; then
    grep -E '^deb .* bookworm( |$).*main' /etc/apt/sources.list | head -1 \
      | sed -E 's/ bookworm / bookworm-backports /' \
      | $sudo_cmd tee /etc/apt/sources.list.d/parallax-bookworm-backports.list >/dev/null
  fi
  if ! grep -rqs "bookworm-backports" /etc/apt/sources.list /etc/apt/sources.list.d/; then
    echo "setup: could not derive a bookworm-backports source entry from this machine's apt sources" >&2
    exit 1
  fi
fi

export DEBIAN_FRONTEND=noninteractive
$sudo_cmd apt-get update -qq
$sudo_cmd apt-get install -y -qq "${need_pkgs[@]}" >/dev/null
$sudo_cmd apt-get install -y -qq -t bookworm-backports mesa-vulkan-drivers >/dev/null
# Blender after Mesa, preferring backports, so its GL packages follow the Mesa 25 above.
$sudo_cmd apt-get install -y -qq -t bookworm-backports "${blender_pkgs[@]}" >/dev/null
lavapipe_has_rt || { echo "setup: mesa-vulkan-drivers from bookworm-backports did not install" >&2; exit 1; }
