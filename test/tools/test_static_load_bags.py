"""simulate_bag and estimate_bag with deflections from a mechanical zero (issue 19): the drive
of a truck 40 % heavier than the observer's file, its estimate bag read back with the ``mcap``
library (``/wheel_load/static/left|right``), the segments and the report.

References: the truth parameter file (F_c,i = (M/2 + m_i) g of the loaded truck), the
configured static loads under ``equilibrium``, INTERFACES.md's column order.
"""
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest

from road_force_estimator import interfaces
from road_force_estimator.core.parameters import GRAVITY_MPS2
from road_force_estimator.tools.estimate_bag import main as estimate_main
from road_force_estimator.tools.simulate_bag import main as simulate_main

REPO = Path(__file__).resolve().parents[2]
PARAMS = REPO / 'config' / 'road_force_estimator.yaml'
LOADED_KG = 7000.0    # the nominal 5000 kg + 40 %


def static_messages(bag: Path) -> dict[str, list[tuple[int, float, str]]]:
    """(stamp_ns, force.z, frame) of each static-load message, per topic (mcap_ros2)."""
    (path,) = bag.glob('*.mcap')
    out: dict[str, list] = {topic: [] for topic in interfaces.STATIC_LOAD}
    with path.open('rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(
                topics=list(interfaces.STATIC_LOAD)):
            h = msg.header
            out[channel.topic].append((h.stamp.sec * 10**9 + h.stamp.nanosec,
                                       msg.wrench.force.z, h.frame_id))
    return out


@pytest.fixture(scope='module')
def payload_drive(tmp_path_factory):
    """12 s, class C, 20 m/s, 1 kHz: the loaded truck, deflections from the unloaded spring."""
    base = tmp_path_factory.mktemp('payload')
    truth = base / 'truth.yaml'
    truth.write_text('/**:\n  ros__parameters:\n    vehicle:\n'
                     f'      sprung_mass: {LOADED_KG}\n      roll_inertia: 4200.0\n'
                     '      deflection_reference: zero_load\n')
    drive = base / 'drive'
    assert simulate_main(['--road', 'iso8608:C:seed=7', '--speed', '20', '--rate', '1000',
                          '--duration', '12', '--params-file', str(truth), '--output',
                          str(drive), '--no-progress']) == 0
    return drive


@pytest.mark.parametrize('mode', ['online', 'offline'])
def test_estimate_bag_publishes_the_estimated_static_loads(payload_drive, tmp_path, mode):
    out = tmp_path / 'est'
    assert estimate_main([str(payload_drive), '--params-file', str(PARAMS), '-p',
                          'vehicle.deflection_reference:=zero_load', '--output', str(out),
                          '--mode', mode, '--no-figures', '--no-progress']) == 0
    msgs = static_messages(out / 'bag')
    truth = (0.5 * LOADED_KG + 450.0) * GRAVITY_MPS2
    for side, topic in enumerate(interfaces.STATIC_LOAD):
        stamps, loads, frames = (np.array(c) for c in zip(*msgs[topic]))
        assert set(frames.tolist()) == {interfaces.WHEEL_FRAMES[side]}
        assert 115 <= stamps.size <= 121                 # one per 0.1 s of stamps (12 s)
        t = (stamps - stamps[0]) * 1e-9
        assert np.max(np.abs(loads[t >= 10.0] / truth - 1.0)) < 0.02
    lines = (out / 'report' / 'segments.csv').read_text().splitlines()
    head = lines[0].split(',')
    i = head.index('static_load_left_n')
    assert head[i:i + 3] == ['static_load_left_n', 'static_load_right_n',
                             'max_abs_ltr_quasi_static']
    last = dict(zip(head, lines[-1].split(',')))
    assert float(last['static_load_left_n']) == pytest.approx(truth, rel=0.02)
    md = (out / 'report' / 'report.md').read_text()
    assert 'static wheel loads at the end' in md and 'static L (kN)' in md


def test_equilibrium_bag_carries_the_configured_static_loads(payload_drive, tmp_path):
    # the observer told the mechanical-zero drive is at equilibrium: the configured loads
    out = tmp_path / 'est'
    assert estimate_main([str(payload_drive), '--params-file', str(PARAMS), '-p',
                          'vehicle.static_load:=[30000.0, 31000.0]', '--output', str(out),
                          '--no-figures', '--no-progress']) == 0
    msgs = static_messages(out / 'bag')
    for topic, value in zip(interfaces.STATIC_LOAD, (30000.0, 31000.0)):
        assert {load for _, load, _ in msgs[topic]} == {value}
