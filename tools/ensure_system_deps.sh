#!/usr/bin/env bash
# Installs the Debian packages drake-skill needs at run time (open3d links
# libusb-1.0; the notebooks render Drake diagrams with graphviz's dot), with
# apt-get when running as root; otherwise says what to run.
# --test: also the test-only ones (`make test`, not `make demo`): chromium and
# chromium-driver, the headless browser of the page tests (tests/browser_support.py).
set -euo pipefail
packages=(libusb-1.0-0 graphviz)
[ "${1:-}" = "--test" ] && packages=(chromium chromium-driver)
missing=()
for pkg in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$(id -u)" -eq 0 ]; then
    echo "Installing Debian packages: ${missing[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
else
    echo "drake-skill needs the Debian packages: ${missing[*]}" >&2
    echo "Run:  sudo apt-get install -y ${missing[*]}   then run make again." >&2
    exit 1
fi
