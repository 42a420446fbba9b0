#!/usr/bin/env bash
# Validate the extension and build one installable zip per platform into dist/, with the
# blender_ext.py that ships inside the bpy wheel. Run tools/setup.sh first.
set -euo pipefail
cd "$(dirname "$0")/.."
.venv/bin/python tools/fetch_wheels.py
SCRIPTS=$(.venv/bin/python -c 'import bpy; print(bpy.utils.system_resource("SCRIPTS"))' | tail -n 1)
BLENDER_EXT="$SCRIPTS/addons_core/bl_pkg/cli/blender_ext.py"
mkdir -p dist
.venv/bin/python "$BLENDER_EXT" validate .
.venv/bin/python "$BLENDER_EXT" build --split-platforms --output-dir dist
ls -l dist/*.zip
