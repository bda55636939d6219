#!/usr/bin/env bash
# Installs what clevrtex needs on Debian 12 besides Rust: Debian's headless-capable Blender
# (3.4.1) and the rustfmt/clippy components the test command uses. Needs root (or sudo).
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
if ! command -v blender >/dev/null 2>&1; then
  $SUDO apt-get update
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y blender
fi
if command -v rustup >/dev/null 2>&1; then
  rustup component add rustfmt clippy >/dev/null 2>&1 || true
fi
echo "blender: $(blender --version 2>/dev/null | head -n 1)"
