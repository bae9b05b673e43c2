#!/usr/bin/env bash
# Lays out HERB on the robot PC (systemd/README.md): binaries, models and the documentation
# (README.md, docs/, systemd/README.md) under /opt/herb, the configuration under /etc/herb
# (existing files are kept; ros.env is a commented template), the units, sysusers.d and
# tmpfiles.d and the udev rule under /usr/local/lib, then creates the user and /tmp/iceoryx2 and reloads systemd.
#
#   cargo build --release --bins && sudo systemd/install.sh
#   systemd/install.sh --dest /tmp/stage     # stage into a folder (packaging, tests): no
#                                            # user, tmpfiles or systemctl step
#
# Options: --dest DIR (a staging root, default /), --bin DIR (the built binaries, default
# target/release), --boxed DIR (the BoxED data to copy: meshes, sessions and catalog, into
# /opt/herb/boxed, where herbd, the loopback and `herbctl pack --session` find them; default:
# none, and objects are primitives).
set -euo pipefail
cd "$(dirname "$0")/.."
DEST=/
BIN=target/release
BOXED=
while [ $# -gt 0 ]; do
  case "$1" in
    --dest) DEST=${2:?--dest needs a folder}; shift 2 ;;
    --bin) BIN=${2:?--bin needs a folder}; shift 2 ;;
    --boxed) BOXED=${2:?--boxed needs a folder}; shift 2 ;;
    -h|--help) sed -n '2,14p' "$0"; exit 0 ;;
    *) echo "install.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
D=${DEST%/}
BINS=(herbd herbctl herb-loopback herb-baxter herb-camera)
for b in "${BINS[@]}"; do
  [ -x "$BIN/$b" ] || { echo "install.sh: $BIN/$b is missing: build it first (cargo build --release --bins)" >&2; exit 1; }
done
install -d "$D/opt/herb/bin" "$D/opt/herb/models" "$D/etc/herb" \
  "$D/usr/local/lib/systemd/system" "$D/usr/local/lib/sysusers.d" "$D/usr/local/lib/tmpfiles.d"
for b in "${BINS[@]}"; do install -m 0755 "$BIN/$b" "$D/opt/herb/bin/$b"; done
install -m 0644 models/sequence.json models/objects.toml "$D/opt/herb/models/"
for m in models/policy-*.onnx; do install -m 0644 "$m" "$D/opt/herb/models/"; done
# The README with what its relative links reach for the owner: docs/ (real-cell.md, adapters.md
# and the rest, the images) and the install layout, systemd/README.md, which real-cell.md links.
install -d "$D/opt/herb/docs/img" "$D/opt/herb/systemd"
install -m 0644 README.md "$D/opt/herb/README.md"
install -m 0644 docs/*.md "$D/opt/herb/docs/"
install -m 0644 docs/img/* "$D/opt/herb/docs/img/"
install -m 0644 systemd/README.md "$D/opt/herb/systemd/README.md"
# ros.env: a commented template (ROS_IP / ROS_HOSTNAME), read by the adapters' units.
for c in herbd.toml baxter.toml camera.toml ros.env; do
  if [ -e "$D/etc/herb/$c" ]; then
    echo "install.sh: keeping the existing /etc/herb/$c (the shipped one is systemd/$c)"
  else
    install -m 0644 "systemd/$c" "$D/etc/herb/$c"
  fi
done
for u in systemd/*.service; do install -m 0644 "$u" "$D/usr/local/lib/systemd/system/"; done
install -m 0644 systemd/sysusers.d/herb.conf "$D/usr/local/lib/sysusers.d/herb.conf"
install -m 0644 systemd/tmpfiles.d/herb.conf "$D/usr/local/lib/tmpfiles.d/herb.conf"
install -d "$D/usr/local/lib/udev/rules.d"
install -m 0644 systemd/udev/60-herb.rules "$D/usr/local/lib/udev/rules.d/60-herb.rules"
if [ -n "$BOXED" ]; then
  install -d "$D/opt/herb/boxed"
  for part in meshes sessions catalog.json; do
    [ -e "$BOXED/$part" ] || { echo "install.sh: $BOXED/$part is missing (is --boxed the BoxED folder?)" >&2; exit 1; }
    cp -r "$BOXED/$part" "$D/opt/herb/boxed/"
  done
fi
real_cell="on a real cell, before enabling herb-baxter and herb-camera:
  /etc/herb/ros.env     set ROS_IP=<this PC's address on the robot's network> (or ROS_HOSTNAME=);
                        both adapters' units read it (EnvironmentFile), and each logs the address
                        it advertises ('reached at ...'); without it the robot must resolve this
                        PC's hostname
  /etc/herb/baxter.toml, /etc/herb/camera.toml
                        [ros] master_uri: the robot's ROS master (not read from ros.env)
  the steps (network, calibrations): /opt/herb/docs/real-cell.md"
if [ "$D" = "" ]; then
  systemd-sysusers /usr/local/lib/sysusers.d/herb.conf
  systemd-tmpfiles --create /usr/local/lib/tmpfiles.d/herb.conf
  # /dev/cpu_dma_latency to group herb now (udev applies the rule at every boot).
  udevadm control --reload 2>/dev/null && udevadm trigger --subsystem-match=misc --sysname-match=cpu_dma_latency 2>/dev/null \
    || echo "install.sh: udev not reloaded; /dev/cpu_dma_latency gets group herb at the next boot"
  systemctl daemon-reload
  echo "installed; next: sudo systemctl enable --now herb-loopback herbd   (or herb-baxter herb-camera herbd on a real cell)"
else
  echo "staged into $DEST"
fi
echo "$real_cell"
