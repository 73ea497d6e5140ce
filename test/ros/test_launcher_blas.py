"""The nodes' entry points (ros/launcher.py) run the node with one BLAS thread unless the
environment says otherwise: the variables are set before the node's module (and numpy)
loads. The node module is a stand-in that reports what it found, in a child process."""
import json
import os
import subprocess
import sys

from road_force_estimator.ros.launcher import BLAS_THREAD_VARIABLES

CHILD = """
import json, os, sys, types
stub = types.ModuleType('road_force_estimator.ros.observer')
stub.main = lambda: print(json.dumps({
    'env': {k: os.environ.get(k) for k in %r},
    'numpy_loaded_first': 'numpy' in sys.modules})) or 0
sys.modules['road_force_estimator.ros.observer'] = stub
from road_force_estimator.ros import launcher
sys.exit(launcher.observer())
""" % (BLAS_THREAD_VARIABLES,)


def run(env: dict) -> dict:
    out = subprocess.run([sys.executable, '-c', CHILD], env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_one_blas_thread_unless_the_environment_sets_it():
    base = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    got = run(base)
    assert got['env'] == {k: '1' for k in BLAS_THREAD_VARIABLES}
    assert not got['numpy_loaded_first']
    got = run({**base, 'OPENBLAS_NUM_THREADS': '2'})
    assert got['env']['OPENBLAS_NUM_THREADS'] == '2' and got['env']['OMP_NUM_THREADS'] == '1'
