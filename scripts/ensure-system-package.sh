#!/usr/bin/env bash
# ensure-system-package.sh COMMAND PACKAGE: installs Debian's PACKAGE with apt when COMMAND is missing,
# or says what to do where that is not possible.
set -euo pipefail
command=$1
package=$2
command -v "$command" >/dev/null 2>&1 && exit 0

if command -v apt-get >/dev/null 2>&1; then
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then
        if command -v sudo >/dev/null 2>&1; then
            sudo="sudo"
        else
            echo "Pitlane needs '$command'. Install it as root with: apt-get install $package" >&2
            exit 1
        fi
    fi
    echo "Installing $package with apt (Pitlane needs '$command')..."
    export DEBIAN_FRONTEND=noninteractive
    $sudo apt-get update -qq
    $sudo apt-get install -y -qq "$package" >/dev/null
    command -v "$command" >/dev/null 2>&1 && exit 0
    echo "apt installed $package, but '$command' is still not on PATH." >&2
    exit 1
fi

echo "Pitlane needs '$command', and this machine has no apt-get to install it." >&2
echo "Install '$package' with your system's package manager (Homebrew: brew install $package)," >&2
echo "make sure '$command' is on PATH, then run make again." >&2
exit 1
