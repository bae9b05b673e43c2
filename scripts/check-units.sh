#!/usr/bin/env bash
# The systemd units' sandbox, checked offline (part of the test command, scripts/test.sh):
# exposure at most 2.0 for herbd and 3.0 for the adapters, by systemd-analyze security
# --offline=true --threshold (tenths); sysusers.d and tmpfiles.d parsed by their tools into a
# scratch root; systemd/install.sh staged into a scratch root (stand-in binaries): the docs the
# installed README links to are there, the ros.env template too, and an existing /etc/herb file
# is kept. Without systemd-analyze (Debian's systemd package) the units' part says skipped,
# except under CI=true, where it fails.
set -euo pipefail
cd "$(dirname "$0")/.."
status=0
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT

# install.sh --dest, twice: into an empty root, then again over an owner's ros.env.
install_fail() { echo "check-units: install.sh: $*" >&2; status=1; }
mkdir -p "$scratch/bin"
for b in herbd herbctl herb-loopback herb-baxter herb-camera; do
  printf '#!/bin/sh\n' >"$scratch/bin/$b" && chmod +x "$scratch/bin/$b"
done
stage=$scratch/stage
if ! said=$(systemd/install.sh --dest "$stage" --bin "$scratch/bin" 2>&1); then
  install_fail "staging failed: $said"
else
  herb=$stage/opt/herb
  # Every relative docs/ link of the installed README, and every relative link of the owner's
  # page docs/real-cell.md, resolves in the installed tree.
  links=$(grep -o '](docs/[^)#]*' "$herb/README.md" | cut -c3- | sort -u || true)
  [ -n "$links" ] || install_fail "no docs/ link found in the installed README"
  for l in $links; do
    [ -f "$herb/$l" ] || install_fail "README.md links $l: not installed under /opt/herb"
  done
  page=$(grep -o ']([^)]*' "$herb/docs/real-cell.md" | cut -c3- | grep -v '://' | sed 's/#.*//' | sort -u || true)
  for l in $page; do
    [ -e "$herb/docs/$l" ] || install_fail "docs/real-cell.md links $l: not installed"
  done
  grep -qs '^#ROS_IP=' "$stage/etc/herb/ros.env" || install_fail "no ros.env template in /etc/herb"
  grep -qs 'KERNEL=="cpu_dma_latency".*GROUP="herb"' "$stage/usr/local/lib/udev/rules.d/60-herb.rules" \
    || install_fail "no udev rule giving group herb /dev/cpu_dma_latency (herbd's [rt] cpu_latency)"
  grep -q 'ros.env' <<<"$said" || install_fail "its last message does not mention /etc/herb/ros.env"
  echo 'ROS_IP=10.0.0.5' >"$stage/etc/herb/ros.env"
  systemd/install.sh --dest "$stage" --bin "$scratch/bin" >/dev/null 2>&1 || install_fail "staging again failed"
  [ "$(cat "$stage/etc/herb/ros.env")" = 'ROS_IP=10.0.0.5' ] || install_fail "overwrote an existing ros.env"
  [ $status = 0 ] && echo "check-units: install.sh stages the docs the README links ($(wc -w <<<"$links") docs/ links resolve), ros.env kept or templated: ok"
fi

if ! command -v systemd-analyze >/dev/null 2>&1; then
  if [ "${CI:-}" = "true" ]; then
    echo "check-units: systemd-analyze not found (CI=true: the unit check must run)" >&2
    exit 1
  fi
  echo "check-units: units skipped (no systemd-analyze; apt-get install systemd)"
  exit $status
fi
check() {
  local unit=$1 threshold=$2 level
  level=$(systemd-analyze security --offline=true "systemd/$unit" 2>&1 | sed -n 's/.*Overall exposure level for [^:]*: \([0-9.]*\).*/\1/p')
  if systemd-analyze security --offline=true --threshold="$threshold" "systemd/$unit" >/dev/null 2>&1; then
    echo "check-units: $unit exposure ${level:-?} (at most $((threshold / 10)).$((threshold % 10))): ok"
  else
    echo "check-units: $unit exposure ${level:-?} is above $((threshold / 10)).$((threshold % 10))" >&2
    status=1
  fi
}
check herbd.service 20
for u in herb-loopback.service herb-baxter.service herb-camera.service; do check "$u" 30; done
root=$scratch/root
mkdir -p "$root/etc" "$root/tmp"
if systemd-sysusers --root="$root" "$PWD/systemd/sysusers.d/herb.conf" >/dev/null 2>&1 \
  && grep -q '^herb:' "$root/etc/passwd" \
  && systemd-tmpfiles --root="$root" --create "$PWD/systemd/tmpfiles.d/herb.conf" \
  && [ "$(stat -c %a "$root/tmp/iceoryx2")" = 2770 ]; then
  echo "check-units: sysusers.d creates user herb, tmpfiles.d creates /tmp/iceoryx2 (2770): ok"
else
  echo "check-units: sysusers.d or tmpfiles.d did not lay out user herb and /tmp/iceoryx2" >&2
  status=1
fi
exit $status
