"""Every input the fuzzer (tools/fuzz.py) found to crash a reader, read again: each must now end
in a successful read or a GapFillError. Inputs are rebuilt from their seed (made from the real
data) and kept edits (tests/fuzz_crashers/); each is read in a child process with a time limit,
so a crash or a hang fails the test instead of the test run."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

import fuzz_inputs

WORKER = r"""
import json, resource, sys
sys.path.insert(0, sys.argv[1])
import fuzz_inputs
from mocap_gapfill.core.errors import GapFillError
fmt, path, partner = json.loads(sys.stdin.read())
try:
    fuzz_inputs.read_as_user(fmt, path, partner)
    print("read")
except GapFillError as exc:
    print("GapFillError: " + str(exc))
# peak memory of this process and of the C3D reader's child process, MB (Linux: kB units)
print(max(resource.getrusage(who).ru_maxrss for who in
          (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)) // 1024)
"""
#: peak memory (MB) a read may reach (the C3D reader's child is capped at its start + 2 GB)
MEMORY_MB = 3000

CASES = fuzz_inputs.crashers()


def test_crashers_are_kept():
    assert CASES, "tests/fuzz_crashers/ is empty"
    assert {record["format"] for _, record in CASES} <= set(fuzz_inputs.FORMATS)


@pytest.mark.parametrize("case", CASES, ids=[p.stem for p, _ in CASES])
def test_a_former_crasher_now_reads_or_fails_cleanly(data_dir, tmp_path, case):
    _, record = case
    fmt = record["format"]
    seed = fuzz_inputs.seeds(fmt, data_dir)[record["seed"]]
    path, partner = fuzz_inputs.input_paths(fmt, tmp_path, data_dir)
    path.write_bytes(fuzz_inputs.decode(seed, record["edits"]))
    proc = subprocess.run([sys.executable, "-c", WORKER, str(Path(fuzz_inputs.__file__).parent)],
                          input=json.dumps([fmt, str(path), partner and str(partner)]),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    outcome, peak_mb = proc.stdout.strip().rsplit("\n", 1)
    assert outcome.startswith(("read", "GapFillError")), outcome
    if sys.platform.startswith("linux"):
        assert int(peak_mb) < MEMORY_MB, f"{peak_mb} MB"
