"""tal (y-tal) for the tests: it pins numpy < 2, so it lives in ``.venv-tal`` and runs in a subprocess."""

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TAL_PYTHON = ROOT / ".venv-tal" / "bin" / "python"
needs_tal = pytest.mark.skipif(not TAL_PYTHON.is_file(),
                               reason="tal's virtual environment .venv-tal is absent "
                                      "(create it with scripts/setup_interop.sh)")


def run_tal(code: str, *args) -> str:
    """Run Python code in tal's environment; return its stdout."""
    done = subprocess.run([str(TAL_PYTHON), "-c", code, *map(str, args)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


#: Reads a capture with ``tal.io.read_capture`` (argv: file, where to save H) and prints what tal read as JSON.
TAL_READ = r"""
import json, sys
import numpy as np, tal
data = tal.io.read_capture(sys.argv[1])
np.save(sys.argv[2], data.H)
listed = lambda value: value.tolist() if isinstance(value, np.ndarray) else None   # tal keeps h5py.Empty
print(json.dumps({"H_format": data.H_format.name, "sensor_grid_format": data.sensor_grid_format.name,
                  "laser_grid_format": data.laser_grid_format.name, "delta_t": float(data.delta_t),
                  "t_start": float(data.t_start), "sensor_grid_xyz": listed(data.sensor_grid_xyz),
                  "sensor_grid_normals": listed(data.sensor_grid_normals), "laser_xyz": listed(data.laser_xyz),
                  "sensor_xyz": listed(data.sensor_xyz), "laser_grid_xyz": listed(data.laser_grid_xyz),
                  "accounts": bool(data.t_accounts_first_and_last_bounces), "scene_info": data.scene_info,
                  "confocal": bool(data.is_confocal())}))
"""
