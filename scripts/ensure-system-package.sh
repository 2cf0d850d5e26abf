#!/usr/bin/env bash
# ensure-system-package.sh PACKAGE CHECK...: runs the command CHECK; when it fails, installs Debian's
# PACKAGE with apt (as root, or through sudo) and checks again, or says what to do where it cannot.
#   scripts/ensure-system-package.sh redis-server command -v redis-server
set -euo pipefail
package=$1
shift
present() { "$@" >/dev/null 2>&1; }
present "$@" && exit 0

if command -v apt-get >/dev/null 2>&1; then
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then
        if command -v sudo >/dev/null 2>&1; then
            sudo="sudo"
        else
            echo "Pitlane needs Debian's $package. Install it as root: apt-get install $package" >&2
            exit 1
        fi
    fi
    echo "Installing $package with apt (Pitlane needs it)..."
    export DEBIAN_FRONTEND=noninteractive
    $sudo apt-get update -qq
    $sudo apt-get install -y -qq "$package" >/dev/null
    present "$@" && exit 0
    echo "apt installed $package, but this still fails: $*" >&2
    exit 1
fi

echo "Pitlane needs $package, and this machine has no apt-get to install it." >&2
echo "Install $package with your system's package manager (Homebrew: brew install $package)," >&2
echo "then run make again. (The check that failed: $*)" >&2
exit 1
