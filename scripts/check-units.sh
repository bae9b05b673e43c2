#!/usr/bin/env bash
# The systemd units' sandbox, checked offline (part of the test command, scripts/test.sh):
# exposure at most 2.0 for herbd and 3.0 for the adapters, by systemd-analyze security
# --offline=true --threshold (tenths); sysusers.d and tmpfiles.d parsed by their tools into a
# scratch root. Without systemd-analyze (Debian's systemd package) the check says skipped,
# except under CI=true, where it fails.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v systemd-analyze >/dev/null 2>&1; then
  if [ "${CI:-}" = "true" ]; then
    echo "check-units: systemd-analyze not found (CI=true: the unit check must run)" >&2
    exit 1
  fi
  echo "check-units: skipped (no systemd-analyze; apt-get install systemd)"
  exit 0
fi
status=0
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
root=$(mktemp -d)
trap 'rm -rf "$root"' EXIT
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
