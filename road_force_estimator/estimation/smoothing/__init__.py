"""The model observer offline: the forward filter and the Rauch-Tung-Striebel smoother over
each run of a recording (:func:`.smoother.smooth`), with a pass that holds only checkpoints
(:mod:`.rts_pass`), blocked linear recursions (:mod:`.lti`) and the gains of a run with stops
(:mod:`.run_speed`).
"""
from road_force_estimator.estimation.smoothing.smoother import smooth

__all__ = ['smooth']
