"""estimate_bag's model fit per axle (issue 32, estimation/axle_fit.py): simulate_bag drives of
the tractor and semi-trailer, one clean and one whose plant has trailer_2's springs 20 %
stiffer than the parameter file the estimate is given (``-p`` on simulate_bag alone: the truth
is the plant's configuration); offline, the estimate bag's ``/diagnostics`` (read by the mcap
library) and the report name trailer_2 on the faulty drive and nothing on the clean one;
online there is no verdict (15 s: shorter than the online window of 800 m); estimate_fleet
carries each drive's verdict."""
import csv
import json
from pathlib import Path
import subprocess
import sys

import pytest

from road_force_estimator.tools.estimate_bag import main as estimate_bag

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
BIN = Path(sys.executable).parent
AXLES = ('front', 'drive', 'trailer_1', 'trailer_2', 'trailer_3')
STIFF = 'vehicle.axle.trailer_2.suspension_stiffness:=[540000.0, 540000.0]'   # file: 450000


def statuses(bag: Path) -> list:
    """The whole vehicle's statuses of ``/diagnostics``, decoded by the mcap library."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    out = []
    for path in sorted(bag.glob('*.mcap')):
        with open(path, 'rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _, _, _, msg in reader.iter_decoded_messages(topics=['/diagnostics']):
                out += [s for s in msg.status if s.name == 'estimate_bag: whole vehicle']
    return out


@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    """(drive, mode) -> estimate_bag's output folder: 15 s of class C at 20 m/s."""
    folder = tmp_path_factory.mktemp('axle_fit')
    out = {}
    for drive, extra in (('clean', []), ('stiff', ['-p', STIFF])):
        bag = folder / drive
        sim = subprocess.run([str(BIN / 'simulate_bag'), '--params-file', str(CONFIG),
                              '--road', 'iso8608:C:seed=5', '--speed', '20', '--duration', '15',
                              '--gnss-rate', '0', '--no-progress', '--output', str(bag),
                              *extra], capture_output=True, text=True, timeout=600)
        assert sim.returncode == 0, sim.stderr
        for mode in ('offline', 'online'):
            if mode == 'online' and drive == 'clean':
                continue
            out[drive, mode] = folder / f'est_{drive}_{mode}'
            assert estimate_bag([str(bag), '--params-file', str(CONFIG), '--output',
                                 str(out[drive, mode]), '--mode', mode, '--no-figures',
                                 '--no-progress']) == 0
    return out


@pytest.mark.parametrize('drive, named', [('clean', ''), ('stiff', 'trailer_2')])
def test_offline_names_the_axle_the_plant_was_given(runs, drive, named):
    folder = runs[drive, 'offline']
    found = statuses(folder / 'bag')
    assert found
    for status in found[-3:]:            # every status carries the drive's verdict
        values = {kv.key: kv.value for kv in status.values}
        assert values['model_fit'] == ('mismatch' if named else 'ok')
        assert values['model_fit_culprits'] == named
        assert status.level == (1 if named else 0)
        misfit = {a: float(values[f'model_fit_misfit_{a}']) for a in AXLES}
        worst = max(misfit, key=misfit.get)
        assert not named or (worst == named and misfit[named] > 0.015)
        assert named or max(misfit.values()) < 0.015
    report = json.loads((folder / 'report' / 'report.json').read_text())
    fit = report['whole_vehicle_estimate']['model_fit']
    assert fit['culprits'] == ([named] if named else [])
    text = (folder / 'report' / 'report.md').read_text()
    assert 'Model fit per axle' in text and (named in text if named else 'every axle fits' in text)


def test_online_has_no_verdict(runs):
    for status in statuses(runs['stiff', 'online'] / 'bag'):
        assert 'model_fit' not in {kv.key for kv in status.values}
    report = json.loads((runs['stiff', 'online'] / 'report' / 'report.json').read_text())
    assert 'model_fit' not in report['whole_vehicle_estimate']


@pytest.mark.slow   # a Dask cluster: `pytest -m 'not slow'` skips it; scripts/test runs it
def test_estimate_fleet_carries_each_drives_model_fit(runs, tmp_path):
    """estimate_fleet over the clean and the stiff drive (offline, one worker): the fleet
    table's ``model_fit_mismatch`` and ``model_fit_misfit_<axle>`` on every row of each drive
    (CSV and Parquet) are the verdict of that drive's report (``drives/<id>/report``, bit for
    bit), which is estimate_bag's run on its own (to 1e-9: the BLAS threads of a Dask worker
    and of this process sum in another order), the stiff drive's naming trailer_2 (the
    plant's fault), and ``summary.md`` names the culprits."""
    import shutil

    import pyarrow.parquet as pq

    inputs = tmp_path / 'in'
    for drive in ('clean', 'stiff'):
        shutil.copytree(runs[drive, 'offline'].parent / drive, inputs / drive)
    out = tmp_path / 'fleet'
    fleet = subprocess.run([str(BIN / 'estimate_fleet'), str(inputs), '--params-file',
                            str(CONFIG), '--output', str(out), '--workers', '1', '--mode',
                            'offline', '--no-figures', '--no-progress'],
                           capture_output=True, text=True, timeout=900)
    assert fleet.returncode == 0, fleet.stderr
    with (out / 'segments.csv').open(newline='') as f:
        rows = list(csv.DictReader(f))
    parquet = pq.read_table(out / 'segments.parquet').to_pydict()
    for drive, named in (('clean', ''), ('stiff', 'trailer_2')):
        own = json.loads((runs[drive, 'offline'] / 'report' / 'report.json').read_text())
        alone = own['whole_vehicle_estimate']['model_fit']
        kept = json.loads((out / 'drives' / drive / 'report' / 'report.json').read_text())
        fit = kept['whole_vehicle_estimate']['model_fit']
        assert fit['culprits'] == alone['culprits'] == ([named] if named else [])
        for a in AXLES:
            assert fit['misfit'][a] == pytest.approx(alone['misfit'][a], abs=1e-9), a
        mine = [r for r in rows if r['drive'] == drive]
        at = [j for j, d in enumerate(parquet['drive']) if d == drive]
        assert mine and len(at) == len(mine)
        for r in mine:
            assert float(r['model_fit_mismatch']) == (1.0 if named else 0.0)
            for a in AXLES:
                assert float(r[f'model_fit_misfit_{a}']) == fit['misfit'][a], a
        for a in AXLES:
            assert [parquet[f'model_fit_misfit_{a}'][j] for j in at] == \
                [fit['misfit'][a]] * len(at)
        assert (max(fit['misfit'], key=fit['misfit'].get) == named) if named else \
            max(fit['misfit'].values()) < 0.015
    summary = (out / 'summary.md').read_text()
    assert '## Model fit per axle (the whole vehicle)' in summary
    assert '| clean | ok | none |' in summary and '| stiff | mismatch | trailer_2 |' in summary
