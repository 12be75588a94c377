"""gnipy.sharding: an XLA batch split across several CPU devices (one chunk per device,
jax.shard_map) gives the one-device batch's results to round-off (the independent formulation: the
same vmapped program on one device)."""

import numpy as np

import gnipy
from gnipy.ensembles import model_systems

_SHARDED_CHILD = r"""
import json, sys
import numpy as np
import gnipy
from gnipy.sharding import member_devices

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False
systems = gnipy.model_systems("rolling-ball", Omega=np.linspace(0.5, 1.5, 7))
seen = []
params = gnipy.simulate(systems, "gni-trapezoid", h=0.01, steps=300, save_every=50, backend="xla",
                        progress=lambda done, total: seen.append(done))
one = systems[0]
q = np.asarray(params.q[:, 0]) + 0.01 * np.arange(7)[:, None]
ics = gnipy.simulate(one, "gni-trapezoid", q, np.asarray(params.v[:, 0]), h=0.01, steps=300, save_every=50,
                     backend="xla", project_v0=True)
print(json.dumps({"devices": len(member_devices()), "params": np.asarray(params.q).tolist(),
                  "params_R": np.asarray(params.R).tolist(), "ics": np.asarray(ics.q).tolist(),
                  "monotone": all(a < b for a, b in zip(seen, seen[1:])), "last": seen[-1],
                  "backend": [params.backend, ics.backend]}))
"""


def test_xla_batch_split_across_cpu_devices_equals_one_device():
    """With JAX_NUM_CPU_DEVICES=2, a batch on XLA runs in one chunk per device (7 members: padded
    to 8, the copies dropped); its members equal the one-device batch to round-off, and progress
    (reported by each chunk) only moves forward."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, JAX_NUM_CPU_DEVICES="2")
    proc = subprocess.run([sys.executable, "-c", _SHARDED_CHILD], capture_output=True, text=True, env=env,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    child = json.loads(proc.stdout.strip().splitlines()[-1])
    assert child["devices"] == 2 and child["backend"] == ["xla", "xla"]
    assert child["monotone"] and child["last"] == 300
    systems = model_systems("rolling-ball", Omega=np.linspace(0.5, 1.5, 7))
    params = gnipy.simulate(systems, "gni-trapezoid", h=0.01, steps=300, save_every=50, backend="xla")
    q = np.asarray(params.q[:, 0]) + 0.01 * np.arange(7)[:, None]
    ics = gnipy.simulate(systems[0], "gni-trapezoid", q, np.asarray(params.v[:, 0]), h=0.01, steps=300,
                         save_every=50, backend="xla", project_v0=True)
    for mine, theirs in ((params.q, child["params"]), (params.R, child["params_R"]), (ics.q, child["ics"])):
        np.testing.assert_allclose(np.asarray(theirs), np.asarray(mine), rtol=0, atol=1e-13)
