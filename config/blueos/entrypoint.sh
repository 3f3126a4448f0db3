#!/bin/sh
# The extension's start: the vehicle's config in /etc/lightpose (a folder
# of the vehicle, kept across updates of the extension), made from the
# shipped example the first time so that the page opens at once (on the
# simulated tank until the config names the boards and a calibration).
set -eu
cfg=/etc/lightpose/lightposed.toml
if [ ! -f "$cfg" ]; then
    mkdir -p /etc/lightpose
    cp /usr/share/lightpose/blueos.toml "$cfg"
    echo "lightpose: wrote $cfg from the shipped example; edit it for your boards and calibration" >&2
fi
exec /usr/bin/lightposed --config "$cfg" "$@"
