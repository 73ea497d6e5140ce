"""The registry of cores (estimation/cores.py): every method has one, each keeps the protocol."""
import pytest

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation import CORES, SCHEMES, Core, Estimator
from road_force_estimator.estimation.chain.core import ChainCore, settling_time_s
from road_force_estimator.estimation.observer.online import ModelCore


def test_every_method_has_a_core():
    assert set(CORES) == set(SCHEMES) | {'model'}
    assert CORES['model'] is ModelCore
    assert all(CORES[s] is ChainCore for s in SCHEMES)


@pytest.mark.parametrize('method', sorted(CORES))
def test_estimator_uses_the_registered_core(method):
    est = Estimator(VehicleParameters(), ObserverParameters(discretization=method))
    core = est.core
    assert isinstance(core, CORES[method])
    for name in ('reset', 'step', 'finish', 'fill_status', 'settling_time_s'):
        assert callable(getattr(core, name))
    for name in Core.__annotations__:
        assert hasattr(core, name), name
    assert est.update(0, (0.01, 0.0), 0.0, 10.0) is not None
    assert est.update(1_000_000, (0.01, 0.0), 0.0, 10.0) is not None
    assert not core.ready          # both estimates taken
    assert est.status.method == core.method
    assert core.finish() is (method == 'model')


def test_chain_settling_time():
    assert settling_time_s(3000.0, 200.0, 1e-3) == pytest.approx(0.15)
    assert settling_time_s(1e9, 1e9, 1e-2) == pytest.approx(0.2)
