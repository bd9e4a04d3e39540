"""The compiled kernels' on-disk cache (issue 27, first run): a second process loads what the first compiled, and
an install with no writable cache directory still imports and evaluates (uncached, same values, no warning).

Each case runs in a fresh interpreter with ``-W error`` (so any warning numba or clothlab raises fails it) and its
own ``NUMBA_CACHE_DIR``.  A read-only install is simulated by making numba's writability probe fail everywhere
(the suite runs as root, for whom file modes do not stop a write)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

CODE = r"""
import json, sys, tempfile


def evaluate():
    import numpy as np
    from clothlab.fit import nnls_kernels
    from clothlab.fit.nnls import nnls_sets
    from clothlab.models import jit
    from clothlab.models.irawan import kernels as im
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.models.kang import kernels as kang
    from clothlab.weave.presets import get_preset

    rng = np.random.default_rng(0)
    v = rng.standard_normal((2, 60, 3))
    wi, wo = v / np.linalg.norm(v, axis=2, keepdims=True)
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    c = IrawanModel(get_preset("polyester-lining")).components(wi, wo, normalised=False, warn=False)
    coef, _ = nnls_sets(c["specular_warp"][None, :, None] + np.abs(rng.standard_normal((2, 60, 2))),
                        np.abs(rng.standard_normal((60, 3))) + 0.1)
    used = [im.direction_set, im.filament_from_moments, nnls_kernels.normal_equations_nnls]
    assert kang.peak_tile_average  # imported (decorated) too; compiled only when called
    return {"im": (c["specular_warp"] + c["specular_weft"]).tolist(), "nnls": coef.ravel().tolist(),
            "hits": sum(sum(f.stats.cache_hits.values()) for f in used),
            "misses": sum(sum(f.stats.cache_misses.values()) for f in used),
            "uncached": sorted(jit.uncached_sources())}


if __name__ == "__main__":
    if sys.argv[1] == "read-only":
        def refuse(*args, **kwargs):
            raise PermissionError(13, "read-only file system (simulated)")
        tempfile.TemporaryFile = refuse  # numba's probe of every cache directory
    print(json.dumps(evaluate()))
"""


def _here() -> dict:
    """The same evaluation in this process (its kernels cached wherever the suite's are)."""
    namespace: dict = {"__name__": "evaluation"}
    exec(CODE, namespace)
    return namespace["evaluate"]()


def _run(mode: str, cache_dir: Path) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    done = subprocess.run([sys.executable, "-W", "error", "-c", CODE, mode], env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Warning" not in done.stderr, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _values(result: dict) -> dict:
    return {k: np.array(v) for k, v in result.items() if k not in ("hits", "misses", "uncached")}


def test_the_second_process_loads_the_compiled_kernels(tmp_path):
    first = _run("writable", tmp_path)
    assert first["uncached"] == [] and first["misses"] > 0  # compiled (and written) by the first process
    assert list(tmp_path.rglob("*.nbi")) and list(tmp_path.rglob("*.nbc"))  # the cache directory was writable
    second = _run("writable", tmp_path)
    assert second["misses"] == 0 and second["hits"] >= first["misses"]  # nothing compiled again
    for key, value in _values(first).items():
        np.testing.assert_array_equal(_values(second)[key], value)


def test_a_read_only_install_still_evaluates_uncached(tmp_path):
    read_only = _run("read-only", tmp_path / "nowhere")
    uncached = {Path(s).parent.name + "/" + Path(s).name for s in read_only["uncached"]}
    assert {"irawan/kernels.py", "kang/kernels.py", "fit/nnls_kernels.py"} <= uncached  # the fallback ran
    assert read_only["hits"] == 0 and not list(tmp_path.rglob("*.nbi"))
    for key, value in _values(_here()).items():
        np.testing.assert_array_equal(_values(read_only)[key], value)
        assert np.count_nonzero(value) > 5
