"""Benchmark of the observer node replayed faster and faster: answered inputs, and the values.

Run from the repository root::

    .venv/bin/python -m bench.probes.observer_replay [--drive-seconds 20] [--rates 1,2,5,10,20]
        [--observer FILE] [--json FILE]

A simulated drive (``--drive-seconds`` at 1 kHz, ISO 8608 class C, 20 m/s, the package's
default parameters) is played with ``bag_player DRIVE --topics /suspension/deflections
/vehicle/twist --rate R`` (its own process) into an ``observer`` (its own process, restarted
for each rate); this process collects every ``/observer/states`` (one per estimate, the
estimate's stamp and its states) and the observer's ``/diagnostics``.

Per rate: ``answered`` (inputs with an estimate) of ``inputs``; ``missed`` (what the observer's
diagnostics count as lost on the way: the publisher's sequence numbers); ``max_diff``, the
largest difference of the published states from ``estimate_bag --mode online``
(:func:`~road_force_estimator.tools.estimate_bag.estimate_online`) on the inputs the observer
took: the drive's samples it answered, and those it held back after a jump (the first sample
after each hole, which the next one confirms); ``max_heave_m``, the largest published body or
wheel heave, beside that of the whole drive estimated offline (a divergence shows as
thousands of times the drive's). The
highest rate at which every input is answered is reported. The machine is shared (other
work may run): figures vary between runs.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[2]
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


def simulate(folder: pathlib.Path, seconds: float) -> None:
    from road_force_estimator.tools.simulate_bag import main
    code = main(['--road', 'iso8608:C:seed=3', '--speed', '20', '--rate', '1000', '--duration',
                 str(seconds), '--output', str(folder), '--no-progress'])
    if code:
        raise SystemExit(f'simulate_bag failed ({code})')


def taken_inputs(stamps: np.ndarray, answered: np.ndarray) -> np.ndarray:
    """The samples the observer took (mask over ``stamps``): those it answered, and before
    each answered sample that follows a hole (a sample not answered just before it, after a
    step of more than ``GAP_PERIODS`` sample steps from the last answered one) the sample
    right before it, held back as a jump and confirmed by it."""
    from road_force_estimator.estimation.acceptance import GAP_PERIODS

    taken = answered.copy()
    idx = np.flatnonzero(answered)
    if idx.size < 2:
        return taken
    step = np.median(np.diff(stamps))
    for a, b in zip(idx[:-1], idx[1:]):
        if b - a > 1 and stamps[b] - stamps[a] > GAP_PERIODS * step:
            taken[b - 1] = True
    return taken


def replay(drive: pathlib.Path, rate: float, context, truth,
           observer_module: str | None = None) -> dict:
    """One replay at ``rate`` (``observer_module``: another version of the node's module
    to run): what came back and how it compares."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from road_force_estimator.ros.messages import reliable_qos, stamp_to_ns
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    states: dict[int, tuple] = {}
    missed = [0]
    up = [False]

    def on_states(m) -> None:
        states[stamp_to_ns(m.header.stamp)] = (*m.position, *m.velocity)

    def on_diagnostics(m) -> None:
        up[0] = True
        for st in m.status:
            if st.name == 'observer: input':
                values = {v.key: v.value for v in st.values}
                missed[0] = max(missed[0], int(values.get('total.missed', '0')))

    node = Node('replay_listener', context=context)
    node.create_subscription(JointState, '/observer/states', on_states, reliable_qos(100000))
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, reliable_qos(100))
    executor = EventsExecutor(context=context)
    executor.add_node(node)
    log = tempfile.TemporaryFile('w+')
    command = [observer_module] if observer_module else ['-m',
                                                         'road_force_estimator.ros.observer']
    observer = subprocess.Popen([sys.executable, *command], cwd=REPO, env=env, stderr=log)
    # the player starts once the observer runs (its first /diagnostics): a player that
    # starts first sees the observer's subscription before the observer sees it (DDS
    # discovery), and its first samples are lost (bag_player's --wait: issue 29)
    deadline = time.monotonic() + 60.0
    while not up[0] and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    t0 = time.monotonic()
    player = subprocess.Popen(
        [sys.executable, '-m', 'road_force_estimator.ros.bag_player', str(drive), '--topics',
         '/suspension/deflections', '/vehicle/twist', '--rate', str(rate), '--wait', '60'],
        cwd=REPO, env=env, stderr=subprocess.PIPE, text=True)
    try:
        while player.poll() is None:
            executor.spin_once(timeout_sec=0.05)
        last, quiet = len(states), time.monotonic()
        while time.monotonic() - quiet < 2.5:      # until nothing more comes (a diagnostic)
            executor.spin_once(timeout_sec=0.05)
            if len(states) != last:
                last, quiet = len(states), time.monotonic()
    finally:
        observer.terminate()
        observer.wait(30)
        executor.shutdown()
        node.destroy_node()
        log.close()
    return compare(states, truth, missed[0], time.monotonic() - t0)


def state_rows(est, rows: np.ndarray) -> np.ndarray:
    """The ``/observer/states`` positions of an estimate's rows (the node's order)."""
    return np.column_stack([
        est.q_m[rows], est.roll_rad[rows], est.body_heave_m[rows], est.wheel_heave_m[rows],
        est.dq[rows], est.droll[rows], est.body_heave_rate[rows], est.wheel_heave_rate[rows]])


def compare(states: dict, truth, missed: int, wall_s: float) -> dict:
    """The observer's states against estimate_bag online on the inputs it took."""
    from road_force_estimator.tools.estimate_bag import estimate_online

    drive, speed, vehicle, observer = truth
    stamps = np.asarray(drive.stamps_ns)
    answered = np.isin(stamps, np.fromiter(states, dtype=np.int64, count=len(states)))
    taken = taken_inputs(stamps, answered)
    est = estimate_online(stamps[taken], drive.q_m[taken], drive.roll_rad[taken],
                          speed[taken], vehicle, observer)
    rows = np.flatnonzero(est.valid)
    ref = dict(zip(est.stamp_ns[rows].tolist(), range(rows.size)))
    common = [s for s in states if s in ref]
    want = state_rows(est, rows)[[ref[s] for s in common]] if common else np.zeros((0, 12))
    got = np.array([states[s] for s in common]).reshape(-1, want.shape[1])
    full = estimate_online(stamps, drive.q_m, drive.roll_rad, speed, vehicle, observer)
    heave = np.abs(state_rows(full, np.arange(stamps.size))[:, 3:6]).max()
    return {'inputs': int(stamps.size), 'answered': int(answered.sum()),
            'taken': int(taken.sum()), 'estimated_offline': int(rows.size),
            'not_in_offline': len(states) - len(common), 'missed': missed,
            'max_diff': float(np.max(np.abs(got - want))) if common else float('nan'),
            'max_heave_m': float(np.abs(got[:, 3:6]).max()) if common else 0.0,
            'max_heave_full_drive_m': float(heave), 'wall_s': round(wall_s, 2)}


def main(argv=None) -> int:
    import rclpy
    from rclpy.context import Context

    from road_force_estimator import bagio
    from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
    from road_force_estimator.tools.estimate_bag import drive_speed
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--drive-seconds', type=float, default=20.0)
    p.add_argument('--rates', default='1,2,5,10,20')
    p.add_argument('--observer', metavar='FILE',
                   help="another version of the node's module to run (from git history)")
    p.add_argument('--json', metavar='FILE')
    args = p.parse_args(argv)
    rates = [float(r) for r in args.rates.split(',')]
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp) / 'drive'
        simulate(folder, args.drive_seconds)
        drive = bagio.read_drive_bag(folder)
        speed, _ = drive_speed(drive)
        truth = (drive, speed, VehicleParameters(), ObserverParameters())
        context = Context()
        rclpy.init(context=context)
        try:
            for rate in rates:
                results[rate] = replay(folder, rate, context, truth, args.observer)
                print(json.dumps({'rate': rate, **results[rate]}), flush=True)
        finally:
            rclpy.try_shutdown(context=context)
    best = 0.0
    for rate in sorted(results):
        if results[rate]['answered'] != results[rate]['inputs']:
            break
        best = rate
    summary = {'per_rate': results, 'highest_rate_every_input_answered': best}
    print(json.dumps({'highest_rate_every_input_answered': best}))
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(summary, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
