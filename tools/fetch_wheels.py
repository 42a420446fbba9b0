"""Download the wheels that blender_manifest.toml lists into ./wheels (they are not committed).

Usage: python tools/fetch_wheels.py [--python PYTHON]
Each wheel file name is split into its distribution, version, Python tag and first platform tag,
and fetched with ``pip download --no-deps --only-binary=:all:`` for exactly that platform (a
pure-Python wheel, platform ``any``, as it is).
"""

import argparse
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", default=sys.executable, help="python whose pip downloads")
    args = parser.parse_args()
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    target = ROOT / "wheels"
    target.mkdir(exist_ok=True)
    for entry in manifest.get("wheels", []):
        path = ROOT / entry
        if path.is_file():
            continue
        name, version, python_tag, _abi, platform = path.name[:-4].split("-")
        cmd = [args.python, "-m", "pip", "download", "--quiet", "--no-deps",
               "--only-binary=:all:", "-d", str(target), f"{name}=={version}"]
        if platform != "any":
            cmd += ["--implementation", "cp", "--python-version",
                    python_tag[2] + "." + python_tag[3:], "--platform", platform.split(".")[0]]
        subprocess.run(cmd, check=True)
        if not path.is_file():
            sys.exit(f"pip did not produce {path.name}")
        print(f"fetched {path.name}")


if __name__ == "__main__":
    main()
