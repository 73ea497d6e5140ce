"""The model observer offline: the forward filter and the Rauch-Tung-Striebel smoother over
each run of a vehicle model's recording (:class:`.smoother.Smoother`; over a drive:
:func:`..offline.smooth`), with a pass that holds only checkpoints (:mod:`.rts_pass`),
blocked linear recursions (:mod:`.lti`) and the gains of a run with stops (:mod:`.run_speed`).
"""
from road_force_estimator.estimation.smoothing.smoother import Smoother

__all__ = ['Smoother']
