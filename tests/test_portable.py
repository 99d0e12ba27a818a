"""SENSORIMOTOR_PORTABLE=1 pins every numerical library's code path before it loads."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from sensorimotor import portable

PROBE = """
import json, sensorimotor, numba, torch
print(json.dumps({"aten": torch.backends.cpu.get_cpu_capability(), "numba": numba.config.CPU_NAME,
                  "mkl": __import__("os").environ.get("MKL_CBWR")}))
"""


def _run(code: str, **env: str) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if k not in portable.SETTINGS}
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env={**clean, **env}
    )


def test_the_switch_pins_torch_numba_and_mkl_to_avx2_and_is_off_by_default():
    on = json.loads(_run(PROBE, SENSORIMOTOR_PORTABLE="1").stdout)
    assert on == {"aten": "AVX2", "numba": "haswell", "mkl": "AVX2"}
    off = json.loads(_run(PROBE).stdout)
    assert off["numba"] is None
    assert off["mkl"] is None


def test_the_switch_after_torch_loaded_warns_that_it_comes_too_late():
    proc = _run("import torch, sensorimotor", SENSORIMOTOR_PORTABLE="1")
    assert proc.returncode == 0
    assert "came after torch" in proc.stderr
