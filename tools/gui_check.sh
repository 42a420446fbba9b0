#!/usr/bin/env bash
# End-to-end check in a real Blender GUI: Debian's Blender (SUITE=trixie: 4.3; SUITE=sid: 5.2)
# in a debootstrap chroot, under Xvfb. Blender loads this working tree as an extension from a
# local repository, builds the demo scene with the add-on's own code, fills it through the UI
# operators (modal, with progress) and saves screenshots of the viewport and the "Mocap" sidebar
# to docs/screenshots/. Needs root (debootstrap, chroot, mounts). ~3-5 minutes the first time.
set -euo pipefail
cd "$(dirname "$0")/.."
SUITE=${SUITE:-trixie}
ROOTFS=${ROOTFS:-/opt/mocap_gapfill_$SUITE}
OUT=${OUT:-docs/screenshots}
PACKAGES="blender python3-scipy xvfb x11-apps netpbm xdotool"
if [ ! -x "$ROOTFS/usr/bin/apt-get" ]; then
  command -v debootstrap >/dev/null || apt-get install -y -q debootstrap
  debootstrap --variant=minbase "$SUITE" "$ROOTFS" http://deb.debian.org/debian
fi
if ! chroot "$ROOTFS" dpkg -s $PACKAGES >/dev/null 2>&1; then
  # a mirror snapshot may be older than the Release file's validity (seen with sid here)
  chroot "$ROOTFS" apt-get -o Acquire::Check-Valid-Until=false update -q
  chroot "$ROOTFS" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q \
    --no-install-recommends $PACKAGES
fi
# this working tree, as the extension folder of a local repository inside the chroot
rm -rf "$ROOTFS/work" && mkdir -p "$ROOTFS/work/repo/mocap_gapfill" "$ROOTFS/work/out"
git ls-files -co --exclude-standard | while read -r f; do
  [ -f "$f" ] && cp --parents "$f" "$ROOTFS/work/repo/mocap_gapfill"
done
# Debian's Blender runs its own Python (3.13 on trixie) with Debian's numpy/scipy: drop the
# manifest's bundled-wheel list (cp311 wheels would make Blender refuse the extension) there
sed -i '/^wheels = \[/,/^\]/d' "$ROOTFS/work/repo/mocap_gapfill/blender_manifest.toml"
cp tools/gui_session.py "$ROOTFS/work/"
# the real marker take as .npz: Debian's Blender has no ezc3d to read the C3D
.venv/bin/mocap-gapfill convert sample_scenes/01_01.c3d "$ROOTFS/work/out/01_01.npz" --force
# a take with a label swap (LFHD / RWRA, frames 201-260) and a 40 mm spike (LKNE, 301-304)
.venv/bin/python - "$ROOTFS/work/out/06_01_faulty.npz" <<'PY'
import sys
from pathlib import Path
from mocap_gapfill.core.io import read_motion, write_motion
data = Path(__import__("os").environ.get("MOCAP_GAPFILL_DATA", "../shared/data"))
take = read_motion(data / "cmu/c3d/06_01.c3d")
pos = take.positions.copy()
i, j = take.names.index("LFHD"), take.names.index("RWRA")
pos[200:260, [i, j]] = pos[200:260, [j, i]]
pos[300:304, take.names.index("LKNE"), 1] += 0.04
write_motion(take.replace(positions=pos), Path(sys.argv[1]), overwrite=True)
PY
for m in proc sys dev; do mountpoint -q "$ROOTFS/$m" || mount --bind "/$m" "$ROOTFS/$m"; done
trap 'for m in dev sys proc; do umount -l "$ROOTFS/$m" 2>/dev/null || true; done' EXIT
chroot "$ROOTFS" bash -c '
  export HOME=/work/home BLENDER_USER_RESOURCES=/work/home/blender DISPLAY=:99
  mkdir -p $HOME
  Xvfb :99 -screen 0 1600x900x24 >/work/out/xvfb.log 2>&1 &
  XVFB=$!
  sleep 2
  blender -b --factory-startup --python /work/gui_session.py -- build > /work/out/build.log 2>&1 \
    || { cat /work/out/build.log; kill $XVFB; exit 1; }
  timeout 600 blender /work/out/mocap_demo.blend --python /work/gui_session.py \
    > /work/out/blender.log 2>&1
  code=$?
  kill $XVFB
  exit $code' || { tail -40 "$ROOTFS/work/out/blender.log"; exit 1; }
mkdir -p "$OUT"
for f in "$ROOTFS"/work/out/*.png; do cp "$f" "$OUT/${SUITE}_$(basename "$f")"; done
# the chroot's paths as the user's would read: out/ and the Blender user folder
cat "$ROOTFS/work/out/build.log" "$ROOTFS/work/out/blender.log" | grep -E "^(mocap_gapfill|Blender)" \
  | sed -e 's#/work/out/#out/#g' -e 's#/work/home/blender/#<Blender user folder>/#g' \
  | tee "$OUT/${SUITE}_log.txt"
ls -la "$OUT"
